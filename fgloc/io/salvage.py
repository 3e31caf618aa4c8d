"""Reading what can be read of an MCAP without a usable summary: cut, unindexed or damaged files.

:class:`Walker` goes through the records in file order.  A chunk that fails its checks
(decompression, CRC, record structure) is skipped and counted; a record header that makes no
sense (an opcode that does not exist, a length past the end of the file) is either damage —
when a complete chunk follows later, found by scanning forward for one that passes every
check — or the point where a cut file ends (``broke`` then says where and why; the readable
records of a cut chunk are still returned).
"""

from __future__ import annotations

import mmap
import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from fgloc.io.mcap_format import (
    MCAP_MAGIC,
    OP_CHANNEL,
    OP_CHUNK,
    OP_DATA_END,
    OP_FOOTER,
    OP_MESSAGE,
    OP_SCHEMA,
    McapFormatError,
    Parsed,
    chunk_records,
    parse_chunk_body,
    parse_records,
)

RESYNC_LIMIT = 1 << 30  # bytes searched forward for the next chunk after a damaged record


@dataclass
class Break:
    offset: int
    size: int
    messages: int
    last_time_ns: int | None
    reason: str

    def describe(self) -> str:
        t = "" if self.last_time_ns is None else f", the last at t={self.last_time_ns * 1e-9:.3f} s"
        where = f"file ends at byte {self.size}" if self.offset < self.size else f"at byte {self.offset}"
        return f"{where}: {self.reason} starting at byte {self.offset}; {self.messages} complete messages read{t}"


@dataclass
class Block:
    """The records of one chunk, or one record outside chunks, at ``offset`` in the file;
    ``start_ns`` is the chunk's first log time (messages are in time order across blocks
    once every block with an earlier start has been read)."""

    offset: int
    start_ns: int
    parsed: Parsed


class Walker:
    """Walk an MCAP's data section in file order (see the module doc)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.broke: Break | None = None
        self.damaged: list[tuple[int, str, bool]] = []  # (offset, reason, data lost) of damaged records
        self.complete = False                      # reached DataEnd / Footer
        self.n_messages = 0
        self.last_time: int | None = None

    def blocks(self) -> Iterator[Block]:
        size = os.path.getsize(self.path)
        with self.path.open("rb") as f:
            if size <= len(MCAP_MAGIC):
                self._break(size, size, "no records")
                return
            with mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as mm:
                yield from self._walk(mm, size)

    def _walk(self, mm: mmap.mmap, size: int) -> Iterator[Block]:
        pos = len(MCAP_MAGIC)
        while True:
            if pos + 9 > size:
                self._break(pos, size, "cut inside a record header" if pos < size else "no end-of-data record")
                return
            op = mm[pos]
            length = int.from_bytes(mm[pos + 1 : pos + 9], "little")
            end = pos + 9 + length
            if (op, length) in ((OP_FOOTER, 20), (OP_DATA_END, 4)) and end <= size:
                self.complete = True
                return
            if op == OP_CHUNK and end <= size:
                try:
                    head = parse_chunk_body(mm[pos + 9 : end])
                    parsed = chunk_records(head, None)
                except McapFormatError as e:
                    found = self._chunk_at(mm, pos, size)  # the framing may be all that is wrong
                    if found is not None:
                        yield self._count(found[0])
                        pos = found[1]
                        continue
                    if length < 40 and self._record_at(mm, end, size):
                        # too short for any chunk, and its length lands on the next record: another
                        # record (a message index, say) whose opcode byte was damaged; nothing lost
                        self.damaged.append((pos, f"corrupt record ({e})", False))
                        pos = end
                        continue
                    self.damaged.append((pos, str(e), True))
                    nxt = self._resync(mm, pos + 1, size)
                    pos = end if nxt is None or nxt >= end else nxt
                    continue
                yield self._count(Block(pos, head.start_ns, parsed))
                pos = end
                continue
            if op in (OP_SCHEMA, OP_CHANNEL, OP_MESSAGE) and end <= size:
                found = self._chunk_at(mm, pos, size)  # a chunk whose opcode byte was damaged?
                if found is not None:
                    yield self._count(found[0])
                    pos = found[1]
                    continue
                try:
                    parsed = parse_records(mm[pos:end], None)
                except (McapFormatError, ValueError, UnicodeDecodeError) as e:
                    self.damaged.append((pos, f"corrupt record ({e})", op == OP_MESSAGE))
                    pos = end
                    continue
                start = parsed.messages[0][0] if parsed.messages else 0
                yield self._count(Block(pos, start, parsed))
                pos = end
                continue
            # another record (index, attachment, metadata, ...: nothing fgloc reads), or one that
            # makes no sense: either may be a chunk whose opcode or length field was damaged (read
            # it through its own inner lengths and CRC), damage before a later chunk, or the cut
            found = self._chunk_at(mm, pos, size)
            if found is not None:
                yield self._count(found[0])
                pos = found[1]
                continue
            sane = op != 0 and not (0x10 < op < 0x80) and op not in (OP_FOOTER, OP_DATA_END) and end <= size
            if sane:
                pos = end
                continue
            nxt = self._resync(mm, pos + 1, size)
            if nxt is None:
                if op == OP_CHUNK:  # the file ends inside this chunk: read what is complete in it
                    try:
                        parsed = chunk_records(parse_chunk_body(mm[pos + 9 : size], complete=False), None)
                        yield self._count(Block(pos, 0, parsed))
                    except McapFormatError:
                        pass
                    self._break(pos, size, "cut inside a chunk")
                    return
                cut = end > size and op != 0 and not (0x10 < op < 0x80)
                self._break(pos, size, "cut inside a record" if cut else f"corrupt record (opcode {op:#x})")
                return
            self.damaged.append((pos, f"corrupt record header (opcode {op:#x})", op == OP_CHUNK))
            pos = nxt

    @staticmethod
    def _record_at(mm: mmap.mmap, pos: int, size: int) -> bool:
        """A plausible record header at ``pos``: a known opcode whose length fits in the file."""
        if pos + 9 > size:
            return pos == size
        op = mm[pos]
        length = int.from_bytes(mm[pos + 1 : pos + 9], "little")
        return 0x01 <= op <= 0x10 and pos + 9 + length <= size

    def _chunk_at(self, mm: mmap.mmap, pos: int, size: int) -> tuple[Block, int] | None:
        """A complete, intact chunk at ``pos`` whatever its opcode and record length say
        (its own header gives the lengths); ``(block, end)`` or None."""
        if pos + 9 + 40 > size:
            return None
        try:
            clen = int.from_bytes(mm[pos + 9 + 28 : pos + 9 + 32], "little")
            if clen > 16 or pos + 9 + 40 + clen > size:
                return None
            dlen = int.from_bytes(mm[pos + 9 + 32 + clen : pos + 9 + 40 + clen], "little")
            end = pos + 9 + 40 + clen + dlen
            if end > size:
                return None
            head = parse_chunk_body(mm[pos + 9 : end])
            if not head.crc:
                return None  # nothing to tell an intact chunk from a damaged one
            return Block(pos, head.start_ns, chunk_records(head, None)), end
        except McapFormatError:
            return None

    def _resync(self, mm: mmap.mmap, start: int, size: int) -> int | None:
        """Offset of the next complete, intact chunk at or after ``start``, or None."""
        q = start
        stop = min(size, start + RESYNC_LIMIT)
        while True:
            q = mm.find(bytes([OP_CHUNK]), q, stop)
            if q < 0 or q + 9 + 40 > size:
                return None
            length = int.from_bytes(mm[q + 1 : q + 9], "little")
            end = q + 9 + length
            if 40 <= length and end <= size:
                try:
                    chunk_records(parse_chunk_body(mm[q + 9 : end]), set())
                    return q
                except McapFormatError:
                    pass
            q += 1

    def _count(self, block: Block) -> Block:
        for m in block.parsed.messages:
            self.n_messages += 1
            self.last_time = m[0] if self.last_time is None else max(self.last_time, m[0])
        return block

    def _break(self, pos: int, size: int, reason: str) -> None:
        self.broke = Break(pos, size, self.n_messages, self.last_time, reason)
