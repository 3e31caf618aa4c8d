"""ROS 2 CDR bytes <-> fgloc objects for DDS, with fgloc's one set of codecs.

Decoding: the fixed-layout batch decoders of :mod:`fgloc.io.fastcdr` (one message at a time
here) and, for another layout or type, mcap_ros2's generic decoder on the standard definition
(:func:`fgloc.io.msgdefs.full_text`) followed by :data:`fgloc.io.ros.FROM_ROS`: the same path
a log's message takes.  Encoding: :func:`fgloc.io.mcap_writer.message_encoder` (fastcdr) for
fgloc's messages, mcap_ros2's generic encoder for the few others (a map, the clock, the status).

A message that does not decode raises :class:`Undecodable` (the caller counts it by topic).
"""

from __future__ import annotations

import functools
import math
import struct
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from fgloc.geometry import quaternion_to_yaw
from fgloc.io import fastcdr
from fgloc.io.msgdefs import MSG_TEXT, full_text, short_name
from fgloc.io.ros import (
    FROM_ROS,
    header_stamp,
    quaternion_yaw,
    ros_header,
    stamp_to_sec_nsec,
    tf_flips,
    tf_from_ros,
    yaw_quaternion,
)
from fgloc.io.topics import IMU, LASER_SCAN, ODOMETRY, POSE_COV_STAMPED, TF_MESSAGE, normalize_type
from fgloc.maps import OccupancyMap
from fgloc.types import StaticTransform

OCCUPANCY_GRID = "nav_msgs/msg/OccupancyGrid"
CLOCK = "rosgraph_msgs/msg/Clock"
DIAGNOSTIC_ARRAY = "diagnostic_msgs/msg/DiagnosticArray"


class Undecodable(ValueError):
    """A message whose bytes are not a valid message of its topic's type."""


_FAST: dict[str, Callable[[Sequence[bytes]], list[Any]]] = {
    LASER_SCAN: fastcdr.decode_laser_scans,
    ODOMETRY: fastcdr.decode_odometries,
    IMU: fastcdr.decode_imus,
    TF_MESSAGE: fastcdr.decode_tf_messages,
}


@functools.cache
def _generic_decoder(type_name: str) -> Callable[[bytes], Any]:
    from mcap.records import Schema
    from mcap_ros2.decoder import DecoderFactory

    schema = Schema(id=1, name=type_name, encoding="ros2msg", data=full_text(type_name).encode())
    dec = DecoderFactory().decoder_for("cdr", schema)
    if dec is None:
        raise Undecodable(f"no decoder for {type_name}")
    return dec  # type: ignore[no-any-return]


@functools.cache
def _generic_encoder(type_name: str) -> Callable[[Any], bytes]:
    from mcap_ros2._dynamic import serialize_dynamic

    name = short_name(type_name)
    return serialize_dynamic(name, full_text(type_name))[name]


def known(type_name: str) -> bool:
    """Whether fgloc has the definition of ROS 2 type ``type_name`` (any spelling)."""
    return short_name(normalize_type(type_name)) in MSG_TEXT


def decode_generic(type_name: str, data: bytes) -> Any:
    """mcap_ros2's decoded message object (attribute access) of ``data``."""
    try:
        return _generic_decoder(normalize_type(type_name))(bytes(data))
    except Undecodable:
        raise
    except Exception as e:  # noqa: BLE001 - any failure of the generic codec is a bad message
        raise Undecodable(f"{type(e).__name__}: {e}") from None


def decode(type_name: str, data: bytes, topic: str = "") -> object:
    """The fgloc object of a message (what a log reader gives for it): LaserScan, Odometry, Imu,
    ``list[Transform3D]``, PoseFix; an :class:`OccupancyMap` for a map."""
    t = normalize_type(type_name)
    if len(data) < 4:
        raise Undecodable(f"{len(data)} bytes: shorter than the CDR header")
    fast = _FAST.get(t)
    if fast is not None:
        with np.errstate(over="ignore", invalid="ignore"):
            obj = fast([data])[0]
        if obj is not None:
            return obj[0] if t == TF_MESSAGE else obj
    if t == POSE_COV_STAMPED:
        with np.errstate(over="ignore", invalid="ignore"):
            fix = fastcdr.decode_pose_fixes([data], topic)[0]
        if fix is not None:
            return fix
    if t == OCCUPANCY_GRID:
        fast_map = _decode_map(data)
        return fast_map if fast_map is not None else map_from_grid(decode_generic(t, data))
    conv = FROM_ROS.get(t)
    if conv is None:
        raise Undecodable(f"fgloc does not read {t}")
    msg = decode_generic(t, data)
    try:
        return conv(msg, topic)
    except Exception as e:  # noqa: BLE001
        raise Undecodable(f"{type(e).__name__}: {e}") from None


def decode_tf(data: bytes) -> tuple[list[StaticTransform], list[bool], list[float]]:
    """A TFMessage's transforms, whether each turns the child's z axis down
    (:func:`fgloc.io.ros.tf_flips`) and each transform's header stamp."""
    m = decode_generic(TF_MESSAGE, data)
    try:
        return tf_from_ros(m, ""), tf_flips(m), [header_stamp(t.header) for t in m.transforms]
    except Exception as e:  # noqa: BLE001
        raise Undecodable(f"{type(e).__name__}: {e}") from None


def encode(msg: object, stamp: float | None = None) -> tuple[str, bytes]:
    """``(ROS 2 type, CDR bytes)`` of an fgloc message (a transform list: a TFMessage)."""
    from fgloc.io.mcap_writer import message_encoder

    enc = message_encoder(msg)
    if enc is None:
        if isinstance(msg, list | tuple) and all(isinstance(x, StaticTransform) for x in msg):
            return TF_MESSAGE, fastcdr.encode_tf(list(msg), float(0.0 if stamp is None else stamp))
        raise TypeError(f"cannot encode {type(msg).__name__} as a ROS 2 message")
    type_name, fn = enc
    return type_name, fn(msg, float(msg.stamp if stamp is None else stamp))  # type: ignore[attr-defined]


def encode_generic(type_name: str, fields: dict) -> bytes:
    """CDR of a message given as a dict of its fields (mcap_ros2's generic encoder)."""
    return _generic_encoder(normalize_type(type_name))(fields)


# ------------------------------------------------------------------------------------ maps
def grid_fields(m: OccupancyMap, stamp: float, frame_id: str = "map") -> dict:
    """A ``nav_msgs/OccupancyGrid`` of a map as map_server publishes it (row 0 at the origin,
    100 occupied, 0 free, -1 unknown; a scale map's values as they are)."""
    sec, nsec = stamp_to_sec_nsec(stamp)
    x, y, yaw = (float(v) for v in m.origin)
    data = np.clip(np.asarray(m.data), -1, 100).astype(np.int8)
    return {
        "header": ros_header(stamp, frame_id),
        "info": {"map_load_time": {"sec": sec, "nanosec": nsec}, "resolution": float(m.resolution),
                 "width": m.width, "height": m.height,
                 "origin": {"position": {"x": x, "y": y, "z": 0.0}, "orientation": yaw_quaternion(yaw)}},
        "data": data.ravel(),
    }


def encode_map(m: OccupancyMap, stamp: float, frame_id: str = "map") -> bytes:
    """The ``nav_msgs/OccupancyGrid`` CDR of a map: the fields before the cells by the generic encoder,
    the ``int8[]`` cells (the last field: a uint32 count, then the bytes) appended as one block."""
    f = grid_fields(m, stamp, frame_id)
    cells = f.pop("data").tobytes()
    head = encode_generic(OCCUPANCY_GRID, {**f, "data": []})
    if head[-4:] != b"\x00\x00\x00\x00":
        raise ValueError("unexpected OccupancyGrid layout")
    return head[:-4] + struct.pack("<I", len(cells)) + cells


def map_from_grid(msg: Any) -> OccupancyMap:
    """An :class:`OccupancyMap` of a decoded ``nav_msgs/OccupancyGrid`` (see :func:`grid_map`)."""
    info, o = msg.info, msg.info.origin
    raw = msg.data
    cells = np.frombuffer(bytes(raw), dtype=np.int8) if isinstance(raw, bytes | bytearray | memoryview) \
        else np.asarray(raw, dtype=np.int16)
    q = o.orientation
    return grid_map(int(info.width), int(info.height), float(info.resolution), o.position.x, o.position.y,
                    quaternion_yaw(q), cells)


def grid_map(w: int, h: int, res: float, x: float, y: float, yaw: float, cells: np.ndarray) -> OccupancyMap:
    """A map of OccupancyGrid cells (row-major from the origin): trinary when every cell is -1, 0 or
    100, as map_server's trinary maps; else its values read as scale."""
    if w <= 0 or h <= 0 or cells.size != w * h:
        raise Undecodable(f"map of {w} x {h} cells with {cells.size} values")
    if not (math.isfinite(res) and res > 0):
        raise Undecodable(f"map resolution {res}")
    # the message's float32 resolution read as the shortest decimal that rounds to it: the map_server
    # YAML's value (0.03, not 0.029999999329447746, which would misplace a far wall by cells)
    res = float(str(np.float32(res)))
    data = cells.astype(np.int16).reshape(h, w)
    trinary = bool(np.all(np.isin(np.unique(data), (-1, 0, 100))))
    return OccupancyMap(data, res, np.array([x, y, yaw]), mode="trinary" if trinary else "scale")


def _decode_map(data: bytes) -> OccupancyMap | None:
    """A little-endian ``nav_msgs/OccupancyGrid`` read with struct and numpy (its cells as one block;
    the generic decoder makes a Python list of them); None when the layout does not apply."""
    buf = memoryview(data)
    if len(buf) < 16 or bytes(buf[:2]) != fastcdr.CDR_LE[:2]:
        return None
    try:
        (n,) = struct.unpack_from("<I", buf, 12)
        p = 16 + n  # after the frame id (its length counts the NUL)
        p += (-(p - 4)) % 4
        _sec, _nsec, res, w, h = struct.unpack_from("<iIfII", buf, p)
        p += 20
        p += (-(p - 4)) % 8
        x, y, _z, qx, qy, qz, qw = struct.unpack_from("<7d", buf, p)
        p += 56
        (count,) = struct.unpack_from("<I", buf, p)
        if p + 4 + count > len(buf):
            return None
        cells = np.frombuffer(buf, dtype=np.int8, count=count, offset=p + 4)
    except (struct.error, ValueError):
        return None
    return grid_map(w, h, res, x, y, float(quaternion_to_yaw(qx, qy, qz, qw)), cells)


def encode_clock(t: float) -> bytes:
    sec, nsec = stamp_to_sec_nsec(t)
    return encode_generic(CLOCK, {"clock": {"sec": sec, "nanosec": nsec}})


def _aligned(pos: int, n: int) -> int:
    """``pos`` moved up to a multiple of ``n`` from the CDR origin (byte 4, after the encapsulation)."""
    return 4 + -(-(pos - 4) // n) * n


def restamp(type_name: str, data: bytes, new_ns: Callable[[int], int]) -> bytes:
    """The same CDR message with each header stamp (nanoseconds) ``t`` replaced by ``new_ns(t)``: a message
    that starts with a ``std_msgs/Header`` (every type fgloc reads but tf), its header; a TFMessage, each
    transform's.  Only the stamp bytes change.  Raises :class:`Undecodable` when the bytes are not that."""
    buf = bytearray(data)
    if bytes(buf[:2]) != b"\x00\x01":
        raise Undecodable("not little-endian CDR")

    def patch(off: int) -> None:
        sec, nsec = struct.unpack_from("<iI", buf, off)
        t = new_ns(sec * 1_000_000_000 + nsec)
        struct.pack_into("<iI", buf, off, t // 1_000_000_000, t % 1_000_000_000)

    try:
        if normalize_type(type_name) != TF_MESSAGE:
            patch(4)
            return bytes(buf)
        (n,) = struct.unpack_from("<I", buf, 4)
        pos = 8
        for _ in range(n):  # geometry_msgs/TransformStamped: header, child_frame_id, 7 float64
            pos = _aligned(pos, 4)
            patch(pos)
            (ln,) = struct.unpack_from("<I", buf, pos + 8)
            pos = _aligned(pos + 12 + ln, 4)
            (ln,) = struct.unpack_from("<I", buf, pos)
            pos = _aligned(pos + 4 + ln, 8) + 56
        if pos > len(buf):
            raise struct.error("truncated")
    except struct.error as e:
        raise Undecodable(f"{type_name}: {e}") from None
    return bytes(buf)
