"""MCAP records at byte level: chunks, their records, and the summary section.

The reader (:mod:`fgloc.io.mcap_reader`) and the salvage walker (:mod:`fgloc.io.salvage`)
parse chunks here with ``struct`` (the ``mcap`` package's per-record objects cost more than
decoding the message), check each chunk's CRC, and read the summary only when its CRC (if
the writer set one) matches and every chunk index points at a chunk record of its length.
Anything inconsistent raises :class:`McapFormatError` (a damaged chunk) or returns None (an
unusable summary: the caller falls back to a linear scan).
"""

from __future__ import annotations

import queue
import struct
import threading
import zlib
from dataclasses import dataclass, field
from typing import IO, Any

MCAP_MAGIC = b"\x89MCAP0\r\n"
OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK = 0x01, 0x02, 0x03, 0x04, 0x05, 0x06
OP_MESSAGE_INDEX, OP_CHUNK_INDEX, OP_STATISTICS, OP_DATA_END = 0x07, 0x08, 0x0B, 0x0F
FOOTER_LEN = 1 + 8 + 20  # opcode, length, summary_start, summary_offset_start, summary_crc
MAX_DECOMPRESSED = 1 << 31

_REC = struct.Struct("<BQ")
_MSG = struct.Struct("<HIQQ")
_CHUNK_HEAD = struct.Struct("<QQQII")  # start, end, uncompressed size, crc, len(compression)
_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")
_U64x2 = struct.Struct("<QQ")
_U64x4 = struct.Struct("<QQQQ")
_U16_U64 = struct.Struct("<HQ")


class McapFormatError(ValueError):
    """A chunk or record that cannot be read as the format says."""


@dataclass(frozen=True)
class SchemaRec:
    id: int
    name: str
    encoding: str
    data: bytes


@dataclass(frozen=True)
class ChannelRec:
    id: int
    schema_id: int
    topic: str
    message_encoding: str


# (log_time_ns, index in its chunk, channel id, data)
MessageRec = tuple[int, int, int, bytes]


@dataclass
class Parsed:
    """The records of one chunk (or a run of records outside chunks)."""

    schemas: list[SchemaRec] = field(default_factory=list)
    channels: list[ChannelRec] = field(default_factory=list)
    messages: list[MessageRec] = field(default_factory=list)
    end: int = 0  # bytes consumed (a partial buffer stops at the first incomplete record)


def _string(buf: bytes, p: int) -> tuple[str, int]:
    (n,) = _U32.unpack_from(buf, p)
    end = p + 4 + n
    if end > len(buf):
        raise McapFormatError("string overruns its record")
    return buf[p + 4 : end].decode(), end


def parse_schema(body: bytes) -> SchemaRec:
    (sid,) = _U16.unpack_from(body, 0)
    name, p = _string(body, 2)
    enc, p = _string(body, p)
    (n,) = _U32.unpack_from(body, p)
    if p + 4 + n > len(body):
        raise McapFormatError("schema data overruns its record")
    return SchemaRec(sid, name, enc, bytes(body[p + 4 : p + 4 + n]))


def parse_channel(body: bytes) -> ChannelRec:
    cid, sid = struct.unpack_from("<HH", body, 0)
    topic, p = _string(body, 4)
    enc, p = _string(body, p)
    return ChannelRec(cid, sid, topic, enc)


def parse_records(buf: bytes, want: set[int] | None, complete: bool = True) -> Parsed:
    """Schemas, channels and the messages of channels in ``want`` (None = all) in ``buf``.

    ``complete``: a record running past the end is an error (a whole chunk); otherwise
    parsing stops before it (the readable part of a cut chunk)."""
    out = Parsed()
    msgs = out.messages
    pos, n, idx = 0, len(buf), 0
    rec, msg = _REC.unpack_from, _MSG.unpack_from
    while pos + 9 <= n:
        op, length = rec(buf, pos)
        body = pos + 9
        end = body + length
        if end > n:
            if complete:
                raise McapFormatError("record overruns its chunk")
            break
        if op == OP_MESSAGE:
            if length < 22:
                raise McapFormatError("message record too short")
            ch, _seq, log_time, _pub = msg(buf, body)
            if want is None or ch in want:
                msgs.append((log_time, idx, ch, buf[body + 22 : end]))
        elif op == OP_SCHEMA:
            out.schemas.append(parse_schema(buf[body:end]))
        elif op == OP_CHANNEL:
            out.channels.append(parse_channel(buf[body:end]))
        elif op == 0 or (0x10 < op < 0x80):
            raise McapFormatError(f"corrupt record (opcode {op:#x})")
        pos = end
        idx += 1
    if complete and pos != n:
        raise McapFormatError("trailing bytes in chunk")
    out.end = pos
    return out


def decompress(compression: str, data: bytes, size: int, partial: bool = False) -> bytes:
    if compression == "":
        return data
    if compression == "zstd":
        import zstandard

        if partial:
            return zstandard.ZstdDecompressor().decompressobj().decompress(data)  # type: ignore[no-any-return]
        return zstandard.ZstdDecompressor().decompress(  # type: ignore[no-any-return]
            data, max_output_size=min(max(size, 1), MAX_DECOMPRESSED))
    if compression == "lz4":
        import lz4.frame

        if partial:
            return lz4.frame.LZ4FrameDecompressor().decompress(data)  # type: ignore[no-any-return]
        return lz4.frame.decompress(data)  # type: ignore[no-any-return]
    raise McapFormatError(f"unsupported chunk compression '{compression[:20]}'")


@dataclass
class ChunkHead:
    start_ns: int
    end_ns: int
    size: int          # uncompressed
    crc: int
    compression: str
    data: bytes        # compressed records (possibly cut short)
    complete: bool


def parse_chunk_body(body: bytes, complete: bool = True) -> ChunkHead:
    if len(body) < 40:
        raise McapFormatError("chunk header cut short")
    start, end, usize, crc, clen = _CHUNK_HEAD.unpack_from(body, 0)
    if clen > 16 or 32 + clen + 8 > len(body):
        raise McapFormatError("corrupt chunk header")
    comp = body[32 : 32 + clen].decode(errors="replace")
    (dlen,) = _U64.unpack_from(body, 32 + clen)
    p = 40 + clen
    if complete and p + dlen != len(body):
        raise McapFormatError("chunk data length disagrees with the record length")
    return ChunkHead(start, end, usize, crc, comp, body[p : p + dlen], complete and p + dlen <= len(body))


def chunk_records(head: ChunkHead, want: set[int] | None) -> Parsed:
    """Decompress, check the CRC and parse a chunk; :class:`McapFormatError` if damaged."""
    if not head.complete:
        cut = _decompressed(head.compression, head.data, head.size, partial=True)
        return Parsed() if cut is None else parse_records(cut, want, complete=False)
    buf = _decompressed(head.compression, head.data, head.size)
    if head.crc:
        if buf is None or zlib.crc32(buf) != head.crc:
            # the size or the compression name may be what is damaged: the CRC tells a right guess
            for comp in ("zstd", "lz4", ""):
                alt = _decompressed(comp, head.data, head.size, True)
                if alt is not None and zlib.crc32(alt) == head.crc:
                    buf = alt
                    break
            else:
                raise McapFormatError("CRC mismatch" if buf is not None else "cannot decompress")
    elif buf is None:
        raise McapFormatError(f"cannot decompress ({head.compression[:20]})")
    elif len(buf) != head.size:
        raise McapFormatError("decompressed size differs from the chunk header")
    return parse_records(buf, want, complete=True)


def _decompressed(compression: str, data: bytes, size: int, partial: bool = False) -> bytes | None:
    try:
        return decompress(compression, data, size, partial)
    except Exception:  # noqa: BLE001 - zstd/lz4 errors on corrupt data, unknown compression
        return None


# --------------------------------------------------------------------------------------------
# summary
@dataclass
class ChunkRef:
    start_ns: int
    end_ns: int
    offset: int
    length: int
    channels: frozenset[int] | None   # channels with messages in it (None: unknown)


@dataclass
class Summary:
    schemas: dict[int, SchemaRec]
    channels: dict[int, ChannelRec]
    chunks: list[ChunkRef]
    message_count: int
    start_ns: int
    end_ns: int
    channel_counts: dict[int, int]


def read_summary(f: IO[bytes], size: int) -> Summary | None:
    """The summary section, or None if absent, cut, or inconsistent with the file.

    A summary whose CRC (written by the writer) matches is trusted; without a CRC every chunk
    index must point at a chunk record of its length."""
    if size < 2 * len(MCAP_MAGIC) + FOOTER_LEN:
        return None
    f.seek(size - len(MCAP_MAGIC) - FOOTER_LEN)
    tail = f.read()
    if tail[-len(MCAP_MAGIC):] != MCAP_MAGIC or tail[0] != OP_FOOTER:
        return None
    start, _offsets, crc = struct.unpack_from("<QQI", tail, 9)
    foot = size - len(MCAP_MAGIC) - FOOTER_LEN
    if start == 0 or not len(MCAP_MAGIC) < start <= foot:
        return None
    f.seek(start)
    section = f.read(foot - start)
    if crc and zlib.crc32(tail[: FOOTER_LEN - 4], zlib.crc32(section)) != crc:
        return None
    schemas: dict[int, SchemaRec] = {}
    channels: dict[int, ChannelRec] = {}
    chunks: list[ChunkRef] = []
    stats: tuple[int, int, int, dict[int, int]] | None = None
    pos = 0
    try:
        while pos + 9 <= len(section):
            op, length = _REC.unpack_from(section, pos)
            body = section[pos + 9 : pos + 9 + length]
            if len(body) != length:
                return None
            if op == OP_SCHEMA:
                s = parse_schema(body)
                schemas[s.id] = s
            elif op == OP_CHANNEL:
                c = parse_channel(body)
                channels[c.id] = c
            elif op == OP_CHUNK_INDEX:
                chunks.append(parse_chunk_index(body))
            elif op == OP_STATISTICS:
                stats = parse_statistics(body)
            pos += 9 + length
    except Exception:  # noqa: BLE001 - a summary we cannot parse is no summary
        return None
    if stats is None or not chunks and stats[0]:
        return None
    for ref in chunks:  # every index must point at a chunk record of its length
        if ref.offset + ref.length > start or ref.length < 9 + 40:
            return None
        if crc:  # the summary is intact: a chunk that disagrees with it is a damaged chunk
            continue
        f.seek(ref.offset)
        head = f.read(9)
        op, length = _REC.unpack_from(head, 0)
        if op != OP_CHUNK or 9 + length != ref.length:
            return None
    return Summary(schemas, channels, chunks, *stats)


def _u16_u64_map(body: bytes, p: int) -> tuple[dict[int, int], int]:
    """A ``map<uint16, uint64>`` at ``p`` (its byte length first), read as ``mcap``'s reader reads it:
    entries while the position is short of the map's end; the position after the last one."""
    (n,) = _U32.unpack_from(body, p)
    p += 4
    end = p + n
    out: dict[int, int] = {}
    while p < end:
        k, v = _U16_U64.unpack_from(body, p)
        out[k] = v
        p += 10
    return out, p


def parse_chunk_index(body: bytes) -> ChunkRef:
    """A chunk index record's body (``mcap.records.ChunkIndex.read`` with ``struct``: the ``mcap``
    package's record classes cost 5 ms of every command's start to import)."""
    start, end, offset, length = _U64x4.unpack_from(body, 0)
    offsets, p = _u16_u64_map(body, 32)
    _U64.unpack_from(body, p)  # message index length
    _compression, p = _string(body, p + 8)
    _U64x2.unpack_from(body, p)  # compressed, uncompressed size
    return ChunkRef(start, end, offset, length, frozenset(offsets) if offsets else None)


def parse_statistics(body: bytes) -> tuple[int, int, int, dict[int, int]]:
    """A statistics record's message count, first and last log time and messages per channel."""
    (count,) = _U64.unpack_from(body, 0)
    start, end = struct.unpack_from("<QQ", body, 26)  # after the schema, channel, attachment,
    counts, _ = _u16_u64_map(body, 42)                # metadata and chunk counts
    return count, start, end, counts


def read_chunk(f: IO[bytes], ref: ChunkRef) -> ChunkHead:
    f.seek(ref.offset + 9)
    return parse_chunk_body(f.read(ref.length - 9))


# --------------------------------------------------------------------------------------------
# writing
def _str(s: str) -> bytes:
    b = s.encode()
    return _U32.pack(len(b)) + b


def _record(op: int, body: bytes) -> bytes:
    return _REC.pack(op, len(body)) + body


_MSG_HEAD = struct.Struct("<BQHIQQ")  # opcode, length, channel, sequence, log time, publish time


class StreamWriter:
    """A lean MCAP writer (chunked, CRCs, message indexes, summary with schemas, channels,
    statistics and chunk indexes, summary offsets), written for speed: one ``struct.pack`` and
    two buffer appends per message, where ``mcap.writer.Writer`` builds record objects.  Files
    are read back by ``mcap``'s own reader with CRC validation (tested).

    ``background``: a full chunk is compressed, checksummed and written (with its message indexes)
    by one worker thread, in order, while the caller goes on filling the next one: zstd, the CRC
    and the file write release the GIL, so on a second core they overlap the caller's work (the
    same bytes as written in line; at most two chunks wait).  An error of the worker (a full disk)
    is raised by the next chunk handed over or by :meth:`finish`."""

    def __init__(self, f: IO[bytes], profile: str = "ros2", library: str = "fgloc", chunk_size: int = 1 << 20,
                 compression: str = "zstd", background: bool = True) -> None:
        if compression not in ("zstd", "lz4", ""):
            raise ValueError(f"unsupported compression {compression!r}")
        self._f = f
        self._background = background
        self._queue: queue.Queue[tuple[bytearray, dict[int, list[tuple[int, int]]], int, int] | None] | None = None
        self._worker: threading.Thread | None = None
        self._error: BaseException | None = None
        self._chunk_size = chunk_size
        self._compression = compression
        self._compressor: Any = None
        if compression == "zstd":
            import zstandard

            self._compressor = zstandard.ZstdCompressor()
        self._schemas: list[bytes] = []
        self._channels: list[bytes] = []
        self._n_schemas = 0
        self._n_channels = 0
        self._chunk_indexes: list[bytes] = []
        self._counts: dict[int, int] = {}
        self._n = 0
        self._start: int | None = None
        self._end = 0
        self._buf = bytearray()
        self._index: dict[int, list[tuple[int, int]]] = {}
        self._c_start = self._c_end = 0
        self._c_empty = True
        self._pos = 0
        self._write(MCAP_MAGIC + _record(OP_HEADER, _str(profile) + _str(library)))

    def _write(self, b: bytes) -> None:
        self._f.write(b)
        self._pos += len(b)

    def add_schema(self, name: str, encoding: str, data: bytes) -> int:
        self._n_schemas += 1
        sid = self._n_schemas
        rec = _record(OP_SCHEMA, _U16.pack(sid) + _str(name) + _str(encoding) + _U32.pack(len(data)) + bytes(data))
        self._schemas.append(rec)
        self._buf += rec
        return sid

    def add_channel(self, topic: str, message_encoding: str, schema_id: int) -> int:
        cid = self._n_channels
        self._n_channels += 1
        rec = _record(OP_CHANNEL, struct.pack("<HH", cid, schema_id) + _str(topic) + _str(message_encoding)
                      + _U32.pack(0))
        self._channels.append(rec)
        self._buf += rec
        self._counts[cid] = 0
        return cid

    def add_message(self, channel_id: int, log_time: int, data: bytes, publish_time: int, sequence: int = 0) -> None:
        buf = self._buf
        ix = self._index.get(channel_id)
        if ix is None:
            ix = self._index[channel_id] = []
        ix.append((log_time, len(buf)))
        buf += _MSG_HEAD.pack(OP_MESSAGE, 22 + len(data), channel_id, sequence & 0xFFFFFFFF, log_time, publish_time)
        buf += data
        if self._c_empty:
            self._c_start = self._c_end = log_time
            self._c_empty = False
        elif log_time < self._c_start:
            self._c_start = log_time
        elif log_time > self._c_end:
            self._c_end = log_time
        self._counts[channel_id] += 1
        self._n += 1
        if len(buf) >= self._chunk_size:
            self._flush()

    def _flush(self) -> None:
        if not self._buf:
            return
        raw, index = self._buf, self._index
        start, end = (self._c_start, self._c_end) if not self._c_empty else (0, 0)
        if not self._c_empty:
            self._start = start if self._start is None else min(self._start, start)
            self._end = max(self._end, end)
        self._buf = bytearray()
        self._index = {}
        self._c_empty = True
        if not self._background:
            self._write_chunk(raw, index, start, end)
            return
        self._raise_worker_error()
        if self._queue is None:
            self._queue = queue.Queue(maxsize=2)
            self._worker = threading.Thread(target=self._work, name="fgloc-mcap-chunks", daemon=True)
            self._worker.start()
        self._queue.put((raw, index, start, end))

    def _work(self) -> None:
        """The worker thread: the chunks handed over, in order, until None."""
        assert self._queue is not None
        while (item := self._queue.get()) is not None:
            if self._error is None:
                try:
                    self._write_chunk(*item)
                except BaseException as e:  # noqa: BLE001 - raised in the caller's thread
                    self._error = e

    def _raise_worker_error(self) -> None:
        if self._error is not None:
            e, self._error = self._error, None
            raise e

    def _join_worker(self) -> None:
        if self._queue is not None and self._worker is not None:
            self._queue.put(None)
            self._worker.join()
            self._queue = self._worker = None
        self._raise_worker_error()

    def _write_chunk(self, raw: bytearray, index: dict[int, list[tuple[int, int]]], start: int, end: int) -> None:
        """A chunk record of the messages ``raw``, its message indexes and (kept for the summary) its chunk index."""
        if self._compression == "zstd":
            data = self._compressor.compress(raw)
        elif self._compression == "lz4":
            import lz4.frame

            data = lz4.frame.compress(raw)
        else:
            data = bytes(raw)
        chunk_off = self._pos
        body = (struct.pack("<QQQI", start, end, len(raw), zlib.crc32(raw)) + _str(self._compression)
                + _U64.pack(len(data)))
        self._write(_REC.pack(OP_CHUNK, len(body) + len(data)) + body)
        self._write(data)
        chunk_len = self._pos - chunk_off
        offsets = []
        idx_start = self._pos
        for cid, entries in sorted(index.items()):
            entries.sort(key=lambda e: e[0])
            arr = struct.pack(f"<{2 * len(entries)}Q", *(v for e in entries for v in e))
            offsets.append((cid, self._pos))
            self._write(_record(OP_MESSAGE_INDEX, _U16.pack(cid) + _U32.pack(len(arr)) + arr))
        omap = b"".join(_U16.pack(c) + _U64.pack(o) for c, o in offsets)
        self._chunk_indexes.append(_record(OP_CHUNK_INDEX, struct.pack("<QQQQ", start, end, chunk_off, chunk_len)
                                           + _U32.pack(len(omap)) + omap + _U64.pack(self._pos - idx_start)
                                           + _str(self._compression) + struct.pack("<QQ", len(data), len(raw))))

    def finish(self) -> None:
        self._flush()
        self._join_worker()  # every chunk written before the summary
        self._write(_record(OP_DATA_END, _U32.pack(0)))
        summary_start = self._pos
        groups: list[tuple[int, bytes]] = [(OP_SCHEMA, b"".join(self._schemas)),
                                           (OP_CHANNEL, b"".join(self._channels))]
        cmap = b"".join(_U16.pack(c) + _U64.pack(n) for c, n in sorted(self._counts.items()))
        stats = (_U64.pack(self._n) + _U16.pack(self._n_schemas) + _U32.pack(self._n_channels)
                 + struct.pack("<III", 0, 0, len(self._chunk_indexes))
                 + struct.pack("<QQ", self._start or 0, self._end if self._n else 0) + _U32.pack(len(cmap)) + cmap)
        groups += [(OP_STATISTICS, _record(OP_STATISTICS, stats)), (OP_CHUNK_INDEX, b"".join(self._chunk_indexes))]
        summary = bytearray()
        offsets = bytearray()
        for op, blob in groups:
            if blob:
                offsets += _record(0x0E, struct.pack("<BQQ", op, summary_start + len(summary), len(blob)))
                summary += blob
        offset_start = summary_start + len(summary)
        summary += offsets
        head = struct.pack("<BQQQ", OP_FOOTER, 20, summary_start, offset_start)
        crc = zlib.crc32(head, zlib.crc32(bytes(summary)))
        self._write(bytes(summary) + head + _U32.pack(crc) + MCAP_MAGIC)
