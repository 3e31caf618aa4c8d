"""fgloc as a node of the ROS 2 graph: the ``ros_discovery_info`` topic.

DDS discovery shows a participant's readers and writers; which ROS 2 *node* owns them is told
by each participant on the DDS topic ``ros_discovery_info`` (no ``rt/`` prefix), type
``rmw_dds_common/msg/ParticipantEntitiesInfo``: the participant's GID and, per node, its
namespace, name and its readers' and writers' GIDs.  ``ros2 node list`` and ``ros2 node info``
read it (rmw_dds_common's GraphCache).  rmw_cyclonedds_cpp writes it reliable, transient local,
keep last 1, one sample per participant, again whenever an entity is added or removed.

A GID is the entity's DDS GUID (12 bytes of prefix, 4 of entity id, in network order) as
rmw_cyclonedds_cpp copies ``dds_guid_t`` into ``rmw_gid_t`` (``convert_guid_to_gid``), zero-padded
to the message's Gid size: 16 bytes from ROS 2 Iron on (``rmw_dds_common/msg/Gid``:
``char[16] data``), 24 before (Humble, and the zenoh bridge's ``ROS_DISTRO`` rule likewise).

The bytes are written here (XCDR1 little endian, as every ROS 2 message), and read back for the
tests and for telling a peer of another generation apart.
"""

from __future__ import annotations

import functools
import os
import struct
import uuid
from dataclasses import dataclass, field
from typing import Any

TOPIC = "ros_discovery_info"  # as rmw_cyclonedds_cpp creates it (avoid_ros_namespace_conventions)
TYPE = "rmw_dds_common/msg/ParticipantEntitiesInfo"
DDS_TYPE = "rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_"
GID_SIZE = 16  # ROS 2 Iron and later
GID_SIZE_BEFORE_IRON = 24  # ROS 2 Humble and older
DISTROS_BEFORE_IRON = ("ardent", "bouncy", "crystal", "dashing", "eloquent", "foxy", "galactic", "humble")
DEFAULT_DISTRO = "jazzy"
NAME_MAX = 256  # node_namespace / node_name: string<=256
CDR_LE = b"\x00\x01\x00\x00"


def distro_name(value: str | None) -> str:
    """``value``, else ``$ROS_DISTRO``, else :data:`DEFAULT_DISTRO` (lower case)."""
    name = (value or os.environ.get("ROS_DISTRO", "") or DEFAULT_DISTRO).strip().lower()
    return name or DEFAULT_DISTRO


def before_iron(distro: str) -> bool:
    """Whether ROS 2 ``distro`` uses 24-byte GIDs and sends no type hashes (Humble and older)."""
    return distro_name(distro) in DISTROS_BEFORE_IRON


def gid_size(distro: str) -> int:
    return GID_SIZE_BEFORE_IRON if before_iron(distro) else GID_SIZE


def gid_of(guid: uuid.UUID | bytes) -> bytes:
    """The 16 bytes of a DDS GUID as rmw_cyclonedds_cpp puts them in a GID (network order)."""
    raw = guid.bytes if isinstance(guid, uuid.UUID) else bytes(guid)
    if len(raw) != 16:
        raise ValueError(f"a DDS GUID has 16 bytes, not {len(raw)}")
    return raw


@dataclass
class NodeEntities:
    """One node of a participant: its name and the GIDs of its readers and writers."""

    name: str
    namespace: str = "/"
    readers: list[bytes] = field(default_factory=list)
    writers: list[bytes] = field(default_factory=list)


@dataclass
class ParticipantEntities:
    gid: bytes
    nodes: list[NodeEntities] = field(default_factory=list)


class _Writer:
    def __init__(self) -> None:
        self.b = bytearray()

    def align(self, n: int) -> None:
        self.b += b"\x00" * (-len(self.b) % n)

    def u32(self, v: int) -> None:
        self.align(4)
        self.b += struct.pack("<I", v)

    def string(self, s: str) -> None:
        raw = s.encode()
        if len(raw) > NAME_MAX:
            raise ValueError(f"{s[:40]}...: longer than {NAME_MAX} bytes (string<={NAME_MAX})")
        self.u32(len(raw) + 1)
        self.b += raw + b"\x00"

    def gid(self, g: bytes, size: int) -> None:
        if len(g) > size:
            raise ValueError(f"a GID of {len(g)} bytes does not fit {size}")
        self.b += g + b"\x00" * (size - len(g))


def encode(info: ParticipantEntities, size: int = GID_SIZE) -> bytes:
    """The CDR bytes (encapsulation header included) of ``info`` with ``size``-byte GIDs."""
    w = _Writer()
    w.gid(info.gid, size)
    w.u32(len(info.nodes))
    for n in info.nodes:
        w.string(n.namespace)
        w.string(n.name)
        for seq in (n.readers, n.writers):
            w.u32(len(seq))
            for g in seq:
                w.gid(g, size)
    data = CDR_LE + bytes(w.b)
    return data + b"\x00" * (-len(data) % 4)


class _Reader:
    def __init__(self, data: bytes) -> None:
        self.b = memoryview(data)
        self.at = 0

    def take(self, n: int) -> bytes:
        if self.at + n > len(self.b):
            raise ValueError(f"truncated at byte {self.at + 4} of {len(self.b) + 4}")
        out = bytes(self.b[self.at:self.at + n])
        self.at += n
        return out

    def u32(self) -> int:
        self.at += -self.at % 4
        return int(struct.unpack("<I", self.take(4))[0])

    def string(self) -> str:
        n = self.u32()
        if n == 0 or n > NAME_MAX + 1:
            raise ValueError(f"a string of {n} bytes (string<={NAME_MAX})")
        raw = self.take(n)
        if raw[-1] != 0:
            raise ValueError("a string without its terminating NUL")
        return raw[:-1].decode()


def decode(data: bytes, size: int = GID_SIZE) -> ParticipantEntities:
    """``ParticipantEntitiesInfo`` from its CDR bytes; ValueError when they are not one."""
    if len(data) < 4 or bytes(data[:2]) not in (b"\x00\x01", b"\x00\x00"):
        raise ValueError("not XCDR1 (CDR_LE / CDR_BE) data")
    if bytes(data[:2]) != b"\x00\x01":
        raise ValueError("big-endian CDR is not read here")
    r = _Reader(bytes(data[4:]))
    gid = r.take(size)
    nodes = []
    for _ in range(r.u32()):
        ns, name = r.string(), r.string()
        seqs = []
        for _ in range(2):
            n = r.u32()
            if n * size > len(r.b) - r.at:
                raise ValueError(f"{n} GIDs in {len(r.b) - r.at} bytes")
            seqs.append([r.take(size) for _ in range(n)])
        nodes.append(NodeEntities(name, ns, seqs[0], seqs[1]))
    return ParticipantEntities(gid, nodes)


@functools.cache
def idl_class(size: int = GID_SIZE) -> Any:
    """Cyclone DDS type of the topic (its DDS name as rmw spells it); the bytes are fgloc's."""
    import cyclonedds.idl.types
    from cyclonedds.idl import make_idl_struct

    t: Any = cyclonedds.idl.types
    suffix = "" if size == GID_SIZE else f"_{size}"
    name = t.bounded_str[NAME_MAX]
    gid = make_idl_struct(f"Gid{suffix}", "rmw_dds_common::msg::dds_::Gid_",
                          {"data": t.array[t.uint8, size]})
    gids = t.sequence[gid]
    node = make_idl_struct(f"NodeEntitiesInfo{suffix}", "rmw_dds_common::msg::dds_::NodeEntitiesInfo_",
                           {"node_namespace": name, "node_name": name, "reader_gid_seq": gids, "writer_gid_seq": gids})
    return make_idl_struct(f"ParticipantEntitiesInfo{suffix}", DDS_TYPE,
                           {"gid": gid, "node_entities_info_seq": t.sequence[node]})
