"""Reading a ROS 1 bag record by record, without its index: the bags ``rosbags`` refuses.

``rosbags`` reads a bag through its index (the connection, chunk-info and index-data records
at ``index_pos``).  Bags that ROS's own ``rosbag`` plays have come without a usable one:

* format 2.0 bags written by the 2010 C++ recorder (ROS C Turtle, e.g. the scan_tools demo
  bags): each index-data record's length field says 20 bytes an entry where the entries are
  12 (ROS's reader goes by the entry count; ``rosbags`` asserts on the length);
* format 2.0 bags whose recording was killed (``index_pos`` 0, a ``.bag.active`` file, a cut
  last chunk);
* format 1.2 bags (``#ROSRECORD V1.2``, ROS before 1.1): no chunks, a definition record before
  each topic's first message.

:class:`WalkedBag` walks the records from the start of the file instead and offers what
:class:`~fgloc.io.bags.BagSource` uses of a ``rosbags`` reader (``connections``,
``start_time``, ``end_time``, ``messages``).  Messages come in record-time order, ties in file
order.  :attr:`WalkedBag.broke` says where a cut or damaged file stopped being readable.
"""

from __future__ import annotations

import bz2
import mmap
import struct
from collections.abc import Collection, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fgloc.errors import LogError

V2_MAGIC = b"#ROSBAG V2.0\n"
V12_MAGIC = b"#ROSRECORD V1.2\n"
#: the first line of every ROS 1 bag format; the versions this module walks are the two above
ROS1_MAGICS = (b"#ROSBAG V", b"#ROSRECORD V")

OP_MSG_DEF = 0x01      # format 1.2: a topic's message definition
OP_MSG_DATA = 0x02
OP_BAG_HEADER = 0x03
OP_INDEX_DATA = 0x04
OP_CHUNK = 0x05
OP_CHUNK_INFO = 0x06
OP_CONNECTION = 0x07
INDEX_ENTRY_V1 = 12    # time (8) + offset in the chunk (4): what every format 2.0 reader reads
MAX_HEADER = 1 << 24   # a record header longer than this is damage, not a header
CHUNK_CACHE = 4        # decompressed chunks kept while reading messages in time order


class BagFormatError(ValueError):
    """A record that does not parse."""


def _fields(header: bytes) -> dict[str, bytes]:
    out: dict[str, bytes] = {}
    i = 0
    while i < len(header):
        if i + 4 > len(header):
            raise BagFormatError("header field length past the header's end")
        (n,) = struct.unpack_from("<I", header, i)
        i += 4
        item = header[i:i + n]
        if len(item) != n or b"=" not in item:
            raise BagFormatError("malformed header field")
        i += n
        k, v = item.split(b"=", 1)
        out[k.decode("latin-1")] = v
    return out


def _uint(f: dict[str, bytes], key: str) -> int:
    v = f.get(key)
    if v is None or len(v) not in (1, 4, 8):
        raise BagFormatError(f"header field {key!r} missing or malformed")
    return int.from_bytes(v, "little")


def _time_ns(sec_nsec: bytes) -> int:
    if len(sec_nsec) != 8:
        raise BagFormatError("malformed time field")
    sec, nsec = struct.unpack("<II", sec_nsec)
    return sec * 1_000_000_000 + nsec


def _record(buf: bytes | memoryview, pos: int) -> tuple[dict[str, bytes], int, int] | None:
    """``(header fields, data start, data end)`` of the record at ``pos``; None when the record
    does not fit in ``buf`` (a cut file); :class:`BagFormatError` when it does not parse."""
    if pos + 4 > len(buf):
        return None
    (hlen,) = struct.unpack_from("<I", buf, pos)
    if hlen > MAX_HEADER:
        raise BagFormatError(f"record header of {hlen} bytes")
    if pos + 8 + hlen > len(buf):
        return None
    f = _fields(bytes(buf[pos + 4:pos + 4 + hlen]))
    if "op" not in f or len(f["op"]) != 1:
        raise BagFormatError("record without an op field")
    (dlen,) = struct.unpack_from("<I", buf, pos + 4 + hlen)
    start = pos + 8 + hlen
    if start + dlen > len(buf):
        return None
    return f, start, start + dlen


def _plausible(f: dict[str, bytes]) -> bool:
    """A message record's header (``conn`` and ``time``) or a connection record's (``conn``)."""
    op = f["op"][0]
    timed = op == OP_CONNECTION or (op == OP_MSG_DATA and len(f.get("time", b"")) == 8)
    return len(f.get("conn", b"")) == 4 and timed


def _resync(body: bytes, start: int) -> int | None:
    """The first offset from ``start`` where a message or connection record parses and fits."""
    i = start
    while True:
        found = [j for j in (body.find(b"op=\x02", i), body.find(b"op=\x07", i)) if j >= 0]
        if not found:
            return None
        j = min(found)
        for s in range(max(start, j - 64), j):
            try:
                rec = _record(body, s)
            except BagFormatError:
                continue
            if rec is not None and rec[0]["op"][0] in (OP_MSG_DATA, OP_CONNECTION) and _plausible(rec[0]):
                return s
        i = j + 1


def _normalize_topic(name: str) -> str:
    return ("/" if name.startswith("/") else "") + "/".join(x for x in name.split("/") if x)


def _decompress(kind: bytes, data: bytes) -> bytes:
    if kind == b"none":
        return data
    if kind == b"bz2":
        return bz2.decompress(data)
    if kind == b"lz4":
        from lz4.frame import decompress  # type: ignore[import-untyped]

        return bytes(decompress(data))
    raise BagFormatError(f"chunk compression {kind.decode('latin-1')!r}")


@dataclass
class _Entry:
    time_ns: int
    conn: int
    chunk: int      # file offset of the chunk holding the message; -1: the file itself (format 1.2)
    start: int      # data start and end in the chunk's bytes (or the file)
    end: int


@dataclass
class WalkedBag:
    """A ROS 1 bag (format 2.0 or 1.2) read by walking its records (see the module doc)."""

    path: Path
    connections: list[Any] = field(default_factory=list)
    start_time: int = 0
    end_time: int = 0
    version: str = ""
    broke: str | None = None          # where a cut or damaged file stopped being readable
    damaged: dict[int, str] = field(default_factory=dict)  # chunk offset -> what was skipped in it
    bad_index_lengths: int = 0        # index-data records whose length field disagreed with their count
    _entries: list[_Entry] = field(default_factory=list)
    _conns: dict[int, dict[str, Any]] = field(default_factory=dict)
    _chunks: dict[int, tuple[bytes, int, int]] = field(default_factory=dict)  # offset -> (compression, start, end)

    def open(self) -> None:
        try:
            with self.path.open("rb") as fh, mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) as mm:
                self._walk_file(mm)
        except (OSError, ValueError) as e:  # ValueError: mmap of an empty file
            raise LogError(f"{self.path}: cannot read ROS 1 bag ({getattr(e, 'strerror', None) or e})") from None
        self._entries.sort(key=lambda entry: entry.time_ns)  # stable: ties stay in file order
        if self._entries:
            self.start_time = self._entries[0].time_ns
            self.end_time = self._entries[-1].time_ns + 1
        counts: dict[int, int] = {}
        for entry in self._entries:
            counts[entry.conn] = counts.get(entry.conn, 0) + 1
        self.connections = [self._connection(cid, c, counts.get(cid, 0)) for cid, c in self._conns.items()]

    def _walk_file(self, data: Any) -> None:
        line_end = data.find(b"\n", 0, 64)
        magic = bytes(data[:line_end + 1])
        if magic == V2_MAGIC:
            self.version = "2.0"
            self._walk(data, len(magic), v2=True)
        elif magic == V12_MAGIC:
            self.version = "1.2"
            self._walk(data, len(magic), v2=False)
        else:
            shown = magic.strip().decode("latin-1", "replace") or "no first line"
            raise LogError(f"{self.path}: ROS 1 bag format '{shown}' is not read "
                           "(fgloc reads formats 2.0 and 1.2)")

    def close(self) -> None:
        pass

    @property
    def message_count(self) -> int:
        return len(self._entries)

    # -- walking -----------------------------------------------------------------------------
    def _walk(self, data: Any, pos: int, v2: bool) -> None:
        by_topic: dict[str, int] = {}          # format 1.2: topic -> connection id
        while pos < len(data):
            try:
                rec = _record(data, pos)
                if rec is None:
                    if v2:
                        self._cut_chunk(data, pos)
                    self.broke = (f"file ends at byte {len(data)} inside a record starting at byte {pos}; "
                                  f"{len(self._entries)} complete messages read")
                    return
                f, start, end = rec
                op = f["op"][0]
                if op == OP_BAG_HEADER and f.get("encryptor"):
                    raise LogError(f"{self.path}: encrypted ROS 1 bag ({f['encryptor'].decode('latin-1')}); "
                                   "decrypt it first (`rosbag decrypt`)")
                if v2 and op == OP_CHUNK:
                    self._chunk(data, pos, f, start, end)
                elif v2 and op == OP_CONNECTION:
                    self._connection_record(f, bytes(data[start:end]))
                elif v2 and op == OP_INDEX_DATA:
                    end = self._index_data_end(data, f, start, end)
                elif not v2 and op == OP_MSG_DEF:
                    self._v12_definition(f, by_topic)
                elif not v2 and op == OP_MSG_DATA:
                    self._v12_message(f, by_topic, start, end)
            except BagFormatError as e:
                self.broke = f"damaged record at byte {pos} ({e}); {len(self._entries)} messages read before it"
                return
            pos = end

    def _index_data_end(self, data: Any, f: dict[str, bytes], start: int, end: int) -> int:
        """Where an index-data record really ends: by its entry count (as ROS's reader reads it)
        when its length field disagrees and the count lands on the next record."""
        if _uint(f, "ver") != 1:
            return end
        by_count = start + _uint(f, "count") * INDEX_ENTRY_V1
        if by_count == end:
            return end
        try:
            ok = by_count == len(data) or _record(data, by_count) is not None
        except BagFormatError:
            ok = False
        if ok:
            self.bad_index_lengths += 1
            return by_count
        return end

    def _chunk(self, data: Any, pos: int, f: dict[str, bytes], start: int, end: int) -> None:
        """A chunk's records; one that does not decompress is skipped (its length, in the
        record outside it, still says where the next record starts)."""
        kind = f.get("compression", b"none")
        try:
            body = _decompress(kind, bytes(data[start:end]))
        except Exception as e:  # noqa: BLE001 - a chunk that does not decompress is damage
            self.damaged[pos] = f"chunk does not decompress ({e})"
            return
        self._chunks[pos] = (kind, start, end)
        self._chunk_records(body, pos)

    def _cut_chunk(self, data: Any, pos: int) -> None:
        """The complete records of an uncompressed chunk the file ends in."""
        try:
            (hlen,) = struct.unpack_from("<I", data, pos)
            f = _fields(data[pos + 4:pos + 4 + hlen])
            start = pos + 8 + hlen
        except (struct.error, BagFormatError):
            return
        if f.get("op") != bytes([OP_CHUNK]) or f.get("compression", b"none") != b"none" or start > len(data):
            return
        self._chunks[pos] = (b"none", start, len(data))
        self._chunk_records(bytes(data[start:]), pos, cut=True)

    def _chunk_records(self, body: bytes, chunk_pos: int, cut: bool = False) -> None:
        """The connection and message records of a chunk's ``body``.  A record that does not
        parse (or, in a complete chunk, runs past its end) is skipped: the walk goes on at the
        next offset where a message or connection record parses (noted in :attr:`damaged`).
        ``cut``: the file ends in this chunk; a record running past it is where it ends."""
        p = 0
        skipped = 0
        while p < len(body):
            try:
                rec = _record(body, p)
                if rec is None and cut:
                    break
                if rec is None:
                    raise BagFormatError("record runs past the chunk's end")
                f, start, end = rec
                op = f["op"][0]
                if op == OP_CONNECTION:
                    self._connection_record(f, body[start:end])
                elif op == OP_MSG_DATA:
                    entry = _Entry(_time_ns(f.get("time", b"")), _uint(f, "conn"), chunk_pos, start, end)
                    self._entries.append(entry)
                else:
                    raise BagFormatError(f"op {op} inside a chunk")
                p = end
            except BagFormatError as e:
                skipped += 1
                if skipped == 1:
                    self.damaged[chunk_pos] = f"damaged record at byte {p} of the chunk ({e})"
                q = _resync(body, p + 1)
                if q is None:
                    break
                p = q
        if skipped > 1:
            self.damaged[chunk_pos] += f" and {skipped - 1} more"

    def _connection_record(self, f: dict[str, bytes], data: bytes) -> None:
        cid = _uint(f, "conn")
        if cid in self._conns:
            return
        d = _fields(data)
        self._conns[cid] = {
            "topic": f.get("topic", b"").decode("utf-8", "replace"),
            "type": d.get("type", b"").decode("utf-8", "replace"),
            "md5": d.get("md5sum", b"").decode("latin-1"),
            "def": d.get("message_definition", b"").decode("utf-8", "replace"),
            "callerid": d["callerid"].decode("utf-8", "replace") if "callerid" in d else None,
            "latching": d.get("latching", b"").decode("latin-1"),
        }

    def _v12_definition(self, f: dict[str, bytes], by_topic: dict[str, int]) -> None:
        topic = f.get("topic", b"").decode("utf-8", "replace")
        if topic in by_topic:
            return
        by_topic[topic] = len(self._conns)
        self._conns[by_topic[topic]] = {
            "topic": topic, "type": f.get("type", b"").decode("utf-8", "replace"),
            "md5": f.get("md5", b"").decode("latin-1"),
            "def": f.get("def", b"").decode("utf-8", "replace"), "callerid": None, "latching": "",
        }

    def _v12_message(self, f: dict[str, bytes], by_topic: dict[str, int], start: int, end: int) -> None:
        topic = f.get("topic", b"").decode("utf-8", "replace")
        if topic not in by_topic:  # a message before its definition: known by its type only
            self._v12_definition(f, by_topic)
        t = _uint(f, "sec") * 1_000_000_000 + _uint(f, "nsec")
        self._entries.append(_Entry(t, by_topic[topic], -1, start, end))

    def _connection(self, cid: int, c: dict[str, Any], count: int) -> Any:
        from rosbags.interfaces import (
            Connection,
            ConnectionExtRosbag1,
            MessageDefinition,
            MessageDefinitionFormat,
        )
        from rosbags.typesys.msg import normalize_msgtype

        latching = int(c["latching"]) if c["latching"].isdigit() else None
        msgtype = normalize_msgtype(c["type"]) if c["type"] else ""
        return Connection(cid, _normalize_topic(c["topic"]), msgtype,
                          MessageDefinition(MessageDefinitionFormat.MSG, c["def"]), c["md5"], count,
                          ConnectionExtRosbag1(c["callerid"], latching), self)

    # -- messages ----------------------------------------------------------------------------
    def messages(self, connections: Collection[Any] = ()) -> Iterator[tuple[Any, int, bytes]]:
        """``(connection, record time ns, raw message bytes)`` in record-time order."""
        wanted = {c.id for c in connections} if connections else set(self._conns)
        by_id = {c.id: c for c in self.connections}
        cache: dict[int, bytes] = {}  # the chunks read last (chunks whose times overlap alternate)
        with self.path.open("rb") as fh:
            for e in self._entries:
                if e.conn not in wanted:
                    continue
                if e.chunk < 0:
                    fh.seek(e.start)
                    raw = fh.read(e.end - e.start)
                else:
                    body = cache.pop(e.chunk, None)
                    if body is None:
                        kind, start, end = self._chunks[e.chunk]
                        fh.seek(start)
                        body = _decompress(kind, fh.read(end - start))
                        if len(cache) >= CHUNK_CACHE:
                            del cache[next(iter(cache))]
                    cache[e.chunk] = body  # most recently used last
                    raw = body[e.start:e.end]
                yield by_id[e.conn], e.time_ns, raw
