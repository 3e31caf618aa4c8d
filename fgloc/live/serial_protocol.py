"""The STM32 -> host binary serial protocol: frame encoder and incremental parser.

Byte tables and rationale: ``docs/serial-protocol.md``.  In short, every frame is::

    sync 0xA5 0x5A | len u8 | type u8 | seq u16 | t_us u32 | payload[len] | crc16 u16

little-endian, CRC-16/CCITT-FALSE over ``len .. payload``.  The sensor payload
(``type 0x01``) carries ``n_wheels`` (2 or 4) cumulative signed int32 encoder
counts, the compass yaw (int16, 0.1 deg), the gyro z rate (int16, 0.01 deg/s) and
a flags byte saying which fields are fresh.

This module is pure: no I/O, no printing.  :class:`FrameParser` is fed arbitrary
byte chunks and returns decoded :class:`SensorFrame` objects; every discarded byte
and every rejected frame is counted in :class:`ParserStats`.
"""

from __future__ import annotations

import struct
from dataclasses import asdict, dataclass, field

SYNC = b"\xa5\x5a"
HEADER_LEN = 10  # sync(2) len(1) type(1) seq(2) t_us(4)
CRC_LEN = 2
MAX_PAYLOAD = 64  # longest payload any defined type uses, with headroom

TYPE_SENSOR = 0x01

FLAG_COUNTS = 0x01  # encoder counts sampled for this frame
FLAG_HEADING = 0x02  # compass heading is a fresh reading
FLAG_GYRO = 0x04  # gyro rate is valid
FLAG_COMPASS_FAULT = 0x08  # compass reports an error (heading not trusted)

INT16_ABSENT = 0x7FFF  # heading / gyro field value meaning "not present"
HEADING_MIN_DDEG = -1800  # heading range: -1800..1799 (signed yaw) or 0..3599 (a 0-360 deg bearing)
HEADING_MAX_DDEG = 3599

SEQ_MOD = 1 << 16
T_MOD = 1 << 32
COUNT_MOD = 1 << 32


def crc16_ccitt(data: bytes | bytearray | memoryview, crc: int = 0xFFFF) -> int:
    """CRC-16/CCITT-FALSE: poly 0x1021, init 0xFFFF, no reflection, no final xor."""
    for b in bytes(data):
        crc ^= b << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
    return crc


def _make_table() -> list[int]:
    return [crc16_ccitt(bytes([i]), 0) for i in range(256)]


_CRC_TABLE = _make_table()


def crc16(data: bytes | bytearray | memoryview) -> int:
    """Table-driven CRC-16/CCITT-FALSE (same result as :func:`crc16_ccitt`)."""
    crc = 0xFFFF
    tab = _CRC_TABLE
    for b in bytes(data):
        crc = ((crc << 8) & 0xFFFF) ^ tab[((crc >> 8) ^ b) & 0xFF]
    return crc


@dataclass
class SensorFrame:
    """One decoded sensor frame (type 0x01), raw MCU units.

    ``counts`` are cumulative signed encoder counts (int32, wrapping), ordered
    ``[left, right]`` (diff drive) or ``[front_left, front_right, rear_left, rear_right]``
    (mecanum).  ``heading_ddeg`` is yaw in 0.1 deg, counter-clockwise positive, or None;
    ``gyro_cdps`` the z rate in 0.01 deg/s, or None.
    """

    seq: int
    t_us: int
    counts: tuple[int, ...]
    heading_ddeg: int | None
    gyro_cdps: int | None
    flags: int
    # filled in by the parser:
    t_us_unwrapped: int = 0
    dropped_before: int = 0  # frames missing between the previous frame and this one
    reset: bool = False  # first frame, or the MCU restarted (sequence jumped back)

    @property
    def has_counts(self) -> bool:
        return bool(self.flags & FLAG_COUNTS)

    @property
    def has_heading(self) -> bool:
        return bool(self.flags & FLAG_HEADING) and self.heading_ddeg is not None and not (
            self.flags & FLAG_COMPASS_FAULT
        )


def encode_sensor_frame(
    seq: int,
    t_us: int,
    counts: tuple[int, ...] | list[int],
    heading_ddeg: int | None,
    gyro_cdps: int | None = None,
    flags: int | None = None,
) -> bytes:
    """Encode a type-0x01 frame.  ``seq`` / ``t_us`` / counts wrap to their field widths.

    ``flags`` defaults to counts + heading (if given) + gyro (if given).
    """
    n = len(counts)
    if n not in (2, 4):
        raise ValueError(f"n_wheels must be 2 or 4, got {n}")
    if flags is None:
        flags = FLAG_COUNTS | (FLAG_HEADING if heading_ddeg is not None else 0)
        flags |= FLAG_GYRO if gyro_cdps is not None else 0
    h = INT16_ABSENT if heading_ddeg is None else int(heading_ddeg)
    g = INT16_ABSENT if gyro_cdps is None else max(-32767, min(32766, int(gyro_cdps)))
    wrapped = [((int(c) + (1 << 31)) % COUNT_MOD) - (1 << 31) for c in counts]
    payload = struct.pack(f"<B{n}ihhB", n, *wrapped, h, g, flags & 0xFF)
    body = struct.pack("<BBHI", len(payload), TYPE_SENSOR, seq % SEQ_MOD, t_us % T_MOD) + payload
    return SYNC + body + struct.pack("<H", crc16(body))


def sensor_payload_len(n_wheels: int) -> int:
    return 1 + 4 * n_wheels + 2 + 2 + 1


@dataclass
class ParserStats:
    """Counters of everything the parser saw (all monotonically increasing)."""

    bytes_in: int = 0
    frames_ok: int = 0
    frame_bytes_ok: int = 0
    crc_errors: int = 0
    length_errors: int = 0  # len byte out of range or inconsistent with the payload
    truncated: int = 0  # a frame cut short: a complete valid frame began before its end
    unknown_type: int = 0  # CRC-valid frame of a type this parser does not know
    resyncs: int = 0  # times bytes were discarded to find the next sync
    garbage_bytes: int = 0  # bytes discarded (noise, bad frames' bytes)
    dropped: int = 0  # frames missing according to sequence gaps
    seq_resets: int = 0  # sequence jumped backwards (MCU reboot) -> not counted as drops
    seq_wraps: int = 0
    time_wraps: int = 0
    time_backwards: int = 0  # the MCU clock stepped back (not a u32 wrap): unwrapped time steps back too
    bad_heading: int = 0  # a fresh heading outside -1800..3599: heading dropped, the rest of the frame kept

    def as_dict(self) -> dict[str, int]:
        return asdict(self)


@dataclass
class FrameParser:
    """Incremental parser: ``feed(chunk) -> list[SensorFrame]``.

    Resynchronization: bytes before a sync pattern are discarded (``garbage_bytes``);
    a candidate frame with a bad length or CRC discards only its first sync byte and
    the search restarts right after it, so a valid frame hidden inside a corrupt one
    is still found.  Invariant: ``bytes_in == frame_bytes_ok + garbage_bytes + pending``.
    """

    max_gap_as_drop: int = SEQ_MOD // 2  # larger forward gaps / backward jumps = MCU reset
    stats: ParserStats = field(default_factory=ParserStats)
    _buf: bytearray = field(default_factory=bytearray)
    _last_seq: int | None = None
    _last_t: int | None = None
    _t_ext: int = 0

    @property
    def pending(self) -> int:
        return len(self._buf)

    def reset_buffer(self) -> None:
        """Discard the bytes still waiting for the rest of a frame (counted as garbage)."""
        self._discard(len(self._buf))

    def _discard(self, n: int) -> None:
        if n <= 0:
            return
        del self._buf[:n]
        self.stats.garbage_bytes += n
        self.stats.resyncs += 1

    def feed(self, chunk: bytes | bytearray | memoryview) -> list[SensorFrame]:
        self.stats.bytes_in += len(chunk)
        self._buf += chunk
        out: list[SensorFrame] = []
        buf = self._buf
        while True:
            i = buf.find(SYNC)
            if i < 0:
                # keep a trailing 0xA5 that may be the first half of a sync
                keep = 1 if buf and buf[-1] == SYNC[0] else 0
                self._discard(len(buf) - keep)
                break
            if i > 0:
                self._discard(i)
            if len(buf) < HEADER_LEN:
                break
            plen = buf[2]
            ftype = buf[3]
            if plen > MAX_PAYLOAD or (ftype == TYPE_SENSOR and not self._sensor_len_ok(plen)):
                self.stats.length_errors += 1
                self._discard(1)
                continue
            total = HEADER_LEN + plen + CRC_LEN
            if len(buf) < total:
                # a frame cut short (bytes lost on the wire) must not hold back a complete
                # frame that follows it until enough later bytes arrive to fail its CRC
                if self._complete_frame_after(buf, total) is None:
                    break
                self.stats.truncated += 1
                self._discard(buf.find(SYNC, 1))  # up to the next candidate, which is checked in turn
                continue
            body = bytes(buf[2 : HEADER_LEN + plen])
            (crc_rx,) = struct.unpack_from("<H", buf, HEADER_LEN + plen)
            if crc16(body) != crc_rx:
                self.stats.crc_errors += 1
                self._discard(1)
                continue
            if ftype != TYPE_SENSOR:
                self.stats.unknown_type += 1
                self._discard(total)
                continue
            frame = self._decode_sensor(buf, plen)
            if frame is None:  # n_wheels inconsistent with len (CRC ok: firmware bug)
                self.stats.length_errors += 1
                self._discard(total)
                continue
            del buf[:total]
            self.stats.frames_ok += 1
            self.stats.frame_bytes_ok += total
            self._track(frame)
            out.append(frame)
        return out

    def _complete_frame_after(self, buf: bytearray, total: int) -> int | None:
        """Position of a later sync, inside the first ``total`` bytes, that starts a complete
        CRC-valid frame; such a frame cannot lie inside a real frame starting at 0 (a frame's
        byte 2 is its length, never a sync byte, and no payload holds a whole frame), so the
        candidate at 0 was cut short."""
        k = buf.find(SYNC, 1)
        while 0 < k < total:
            if len(buf) - k < HEADER_LEN:
                return None
            plen = buf[k + 2]
            end = k + HEADER_LEN + plen + CRC_LEN
            if plen <= MAX_PAYLOAD and end <= len(buf):
                (crc_rx,) = struct.unpack_from("<H", buf, k + HEADER_LEN + plen)
                if crc16(buf[k + 2 : k + HEADER_LEN + plen]) == crc_rx:
                    return k
            k = buf.find(SYNC, k + 1)
        return None

    @staticmethod
    def _sensor_len_ok(plen: int) -> bool:
        return plen in (sensor_payload_len(2), sensor_payload_len(4))

    def _decode_sensor(self, buf: bytearray, plen: int) -> SensorFrame | None:
        seq, t_us = struct.unpack_from("<HI", buf, 4)
        n = buf[HEADER_LEN]
        if n not in (2, 4) or plen != sensor_payload_len(n):
            return None
        vals = struct.unpack_from(f"<{n}ihhB", buf, HEADER_LEN + 1)
        counts = tuple(int(v) for v in vals[:n])
        h, g, flags = vals[n], vals[n + 1], vals[n + 2]
        heading = None if h == INT16_ABSENT else int(h)
        if heading is not None and not HEADING_MIN_DDEG <= heading <= HEADING_MAX_DDEG:
            heading = None
            if flags & FLAG_HEADING:
                self.stats.bad_heading += 1
        return SensorFrame(
            seq=seq,
            t_us=t_us,
            counts=counts,
            heading_ddeg=heading,
            gyro_cdps=None if (g == INT16_ABSENT or not flags & FLAG_GYRO) else int(g),
            flags=int(flags),
        )

    def _track(self, f: SensorFrame) -> None:
        """Sequence-gap drop detection and timestamp unwrapping."""
        if self._last_seq is None:
            f.reset = True
        else:
            gap = (f.seq - self._last_seq - 1) % SEQ_MOD
            if f.seq < self._last_seq and gap < self.max_gap_as_drop:
                self.stats.seq_wraps += 1
            if gap >= self.max_gap_as_drop:
                # backwards jump (or absurd gap): the MCU restarted; restart the clock too
                self.stats.seq_resets += 1
                self._last_t = None
                f.reset = True
            else:
                f.dropped_before = gap
                self.stats.dropped += gap
        self._last_seq = f.seq
        if self._last_t is None:
            self._t_ext = f.t_us
        else:
            # signed modular difference: a step of less than half the u32 range forward is
            # time going on (a wrap if the raw value went down), a step back is the clock
            # stepping back (jitter or a resync on the MCU), not a 71.6 min wrap
            dt = ((f.t_us - self._last_t + T_MOD // 2) % T_MOD) - T_MOD // 2
            if dt < 0:
                self.stats.time_backwards += 1
            elif f.t_us < self._last_t:
                self.stats.time_wraps += 1
            self._t_ext += dt
        self._last_t = f.t_us
        f.t_us_unwrapped = self._t_ext
