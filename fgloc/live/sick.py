"""SICK laser scanners over TCP: CoLa-A (ASCII) and CoLa-B (binary) framing, LMDscandata.

CoLa-A telegrams are ``STX (0x02) <ASCII tokens separated by spaces> ETX (0x03)``.
The scan telegram (``sSN LMDscandata`` when streamed after ``sEN LMDscandata 1``,
``sRA LMDscandata`` as the answer to a single ``sRN LMDscandata``) is::

    sSN LMDscandata <version> <device> <serial> <status1> <status2>
        <telegram_counter> <scan_counter> <time_since_startup_us> <time_of_transmission_us>
        <inputs1> <inputs2> <outputs1> <outputs2> <layer angle> <scan_freq_1/100Hz> <meas_freq_100Hz>
        <n_encoders> [<enc_pos> <enc_speed>]*n
        <n_16bit_channels> [<name> <scale f32> <offset f32> <start_angle i32 1/10000deg>
                            <step u16 1/10000deg> <n_values> <v>*n]*n
        <n_8bit_channels> [same block layout]*n
        <position 0|1 ...> <name 0|1 ...> <comment 0|1 ...> <time 0|1 ...> <events 0|1 ...>

Numbers are hexadecimal without leading zeros; the scale factor and offset are the
IEEE-754 float32 bit pattern in hex (``3F800000`` = 1.0).  Distances (DIST1) are mm
after scaling; 0 means no echo -> ``+inf`` (REP 117).  CoLa-B carries the same fields at
fixed widths, big-endian, framed as ``02 02 02 02 <u32 length> <payload> <XOR checksum>``
(:class:`ColaBFramer`, :func:`parse_lmdscandata_binary`).

Angles: device angles grow counter-clockwise seen from above (the LMS1xx, TiM5xx/7xx, LMS5xx
and MRS1000 drivers map a beam to ``start + k * step - 90 deg`` without reversing the
order); on those families device 0 deg is the scanner's right side, so REP 103 (x forward)
is device - 90 deg.  The TiM240, LRS4xxx and NAV2xx count from straight ahead (offset 0);
NAV3xx, LRS36xx and OEM15xx count clockwise and are not read.  The client asks
``sRN DeviceIdent`` and picks the family's offset unless one is configured.

Real-device variants handled here: a scale factor of 2.0 (LMS5xx: DIST1 in 2 mm units),
RSSI channels (16 or 8 bit) and further echoes (DIST2..) beside DIST1, a name block (TiM:
``1 7 <name>``), a multi-layer scanner's layer-angle field (MRS1000: ``FE0C FF06 0 FA``,
one telegram per layer; only ``layer_field`` is used, the others are counted), a
measurement frequency sent in Hz instead of 100 Hz (a firmware inconsistency sick_scan_xd
also corrects; told apart by the mirror's beam rate), ``sFA`` error answers (counted by
SOPAS error name and reported), a scanner left in standby (reported; started on request
with ``start_measurement``) and either CoLa dialect (found in the stream, or tried after an
unanswered start).

Parsing is pure (:func:`parse_lmdscandata`, :func:`parse_lmdscandata_binary`, the framers);
:class:`SickClient` is the threaded TCP client with reconnect and back-off.
"""

from __future__ import annotations

import logging
import math
import re
import socket
import struct
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from fgloc.live.clock import ClockSync
from fgloc.live.worker import SensorThread
from fgloc.types import LaserScan

log = logging.getLogger(__name__)

STX = 0x02
ETX = 0x03
COLA_B_HEADER = b"\x02\x02\x02\x02"
# the start of a CoLa-A answer or scan: STX, a SOPAS command type, a space (never in a CoLa-B stream: there
# STX is followed by STX or by the length's zero bytes, and a binary value would have to spell this out)
_COLA_A_TELEGRAM = re.compile(rb"\x02s(?:SN|RA|EA|FA|AN|WA) [A-Za-z]")
# 5 echoes + 5 16-bit remission channels (LMDscandatacfg 1F 00 1 1, as sick_scan_xd's README shows an
# MRS6124 set) of 1141 beams (LMS5xx, 0.1667 deg) are ~57 KB of CoLa-A: room for that and more
MAX_TELEGRAM = 256 * 1024
MAX_CHANNELS = 32  # per kind (16-bit, 8-bit); DIST1-5, RSSI1-5, ANGL (azimuth correction), VANG (MRS6000)


class TelegramError(ValueError):
    """A malformed telegram; ``reason`` is a short counter key."""

    def __init__(self, reason: str, detail: str = "") -> None:
        super().__init__(f"{reason}: {detail}" if detail else reason)
        self.reason = reason


# ----------------------------------------------------------------------------- framing


@dataclass
class FramerStats:
    bytes_in: int = 0
    telegrams: int = 0
    garbage_bytes: int = 0  # bytes outside STX..ETX
    truncated: int = 0  # STX seen again before ETX, or telegram too long
    cola_b_headers: int = 0  # 02 02 02 02: a CoLa-B (binary) telegram start, which this framer cannot read

    def as_dict(self) -> dict[str, int]:
        return asdict(self)


@dataclass
class ColaFramer:
    """Incremental STX/ETX de-framer: ``feed(chunk) -> list[bytes]`` (payloads, no STX/ETX)."""

    max_len: int = MAX_TELEGRAM
    stats: FramerStats = field(default_factory=FramerStats)
    _buf: bytearray = field(default_factory=bytearray)
    _in: bool = False
    _tail: bytes = b""  # the last 3 bytes fed, to find a CoLa-B header split across chunks

    def reset(self) -> None:
        """Forget a partial telegram (e.g. after a reconnect); counted as truncated."""
        if self._in:
            self.stats.truncated += 1
        self._buf.clear()
        self._in = False

    def feed(self, chunk: bytes | bytearray) -> list[bytes]:
        self.stats.bytes_in += len(chunk)
        out: list[bytes] = []
        data = bytes(chunk)
        if 2 in data:
            self.stats.cola_b_headers += (self._tail + data).count(COLA_B_HEADER)
        self._tail = (self._tail + data)[-3:]
        pos = 0
        n = len(data)
        while pos < n:
            if not self._in:
                j = data.find(b"\x02", pos)
                if j < 0:
                    self.stats.garbage_bytes += n - pos
                    break
                self.stats.garbage_bytes += j - pos
                self._in = True
                self._buf.clear()
                pos = j + 1
                continue
            e = data.find(b"\x03", pos)
            s = data.find(b"\x02", pos)
            if s >= 0 and (e < 0 or s < e):
                # a new STX inside a telegram: the previous one was cut short
                self.stats.truncated += 1
                self.stats.garbage_bytes += len(self._buf) + 1 + (s - pos)
                self._buf.clear()
                pos = s + 1
                continue
            if e < 0:
                self._buf += data[pos:]
                pos = n
                if len(self._buf) > self.max_len:
                    self.stats.truncated += 1
                    self.stats.garbage_bytes += len(self._buf) + 1
                    self._buf.clear()
                    self._in = False
                break
            self._buf += data[pos:e]
            pos = e + 1
            self._in = False
            self.stats.telegrams += 1
            out.append(bytes(self._buf))
            self._buf.clear()
        return out


def frame(payload: str | bytes) -> bytes:
    """Wrap an ASCII command in STX/ETX."""
    b = payload.encode("ascii") if isinstance(payload, str) else payload
    return b"\x02" + b + b"\x03"


def cola_b_checksum(payload: bytes | bytearray) -> int:
    """A CoLa-B telegram's checksum: the XOR of its payload's bytes."""
    ck = 0
    for b in payload:
        ck ^= b
    return ck


def frame_b(payload: bytes) -> bytes:
    """A CoLa-B telegram: ``02 02 02 02``, the payload length (u32, big-endian), the payload, and
    :func:`cola_b_checksum`."""
    return COLA_B_HEADER + struct.pack(">I", len(payload)) + payload + bytes([cola_b_checksum(payload)])


@dataclass
class ColaBFramer:
    """Incremental CoLa-B de-framer: ``feed(chunk) -> list[bytes]`` (payloads whose checksum holds).

    Bytes before a header are garbage; a header with a length above ``max_len`` or a payload whose
    XOR checksum fails discards only the header's first byte, and the search goes on after it.
    """

    max_len: int = MAX_TELEGRAM
    stats: FramerStats = field(default_factory=FramerStats)
    bad_checksum: int = 0
    _buf: bytearray = field(default_factory=bytearray)

    def reset(self) -> None:
        if self._buf:
            self.stats.truncated += 1
            self.stats.garbage_bytes += len(self._buf)
        self._buf.clear()

    def feed(self, chunk: bytes | bytearray) -> list[bytes]:
        self.stats.bytes_in += len(chunk)
        self._buf += chunk
        buf = self._buf
        out: list[bytes] = []
        while True:
            i = buf.find(COLA_B_HEADER)
            if i < 0:
                keep = 0  # up to 3 trailing 02 bytes: a header split across reads
                while keep < min(3, len(buf)) and buf[len(buf) - 1 - keep] == 2:
                    keep += 1
                self.stats.garbage_bytes += len(buf) - keep
                del buf[: len(buf) - keep]
                break
            if i > 0:
                self.stats.garbage_bytes += i
                del buf[:i]
            if len(buf) < 8:
                break
            (n,) = struct.unpack_from(">I", buf, 4)
            if n > self.max_len:
                self.stats.truncated += 1
                self.stats.garbage_bytes += 1
                del buf[:1]
                continue
            if len(buf) < 9 + n:
                break
            payload = bytes(buf[8 : 8 + n])
            if cola_b_checksum(payload) != buf[8 + n]:
                self.bad_checksum += 1
                self.stats.garbage_bytes += 1
                del buf[:1]
                continue
            del buf[: 9 + n]
            self.stats.cola_b_headers += 1
            self.stats.telegrams += 1
            out.append(payload)
        return out


# ----------------------------------------------------------------------------- telegram


@dataclass
class ScanTelegram:
    """The fields of an LMDscandata telegram this project uses (device units decoded)."""

    command: str  # "sSN" or "sRA"
    version: int
    device: int
    serial: int
    status: tuple[int, int]
    telegram_counter: int
    scan_counter: int
    time_since_startup_us: int
    time_of_transmission_us: int
    scan_freq_hz: float
    meas_freq_hz: float
    channel: str
    scale: float
    offset: float
    start_angle_deg: float
    step_deg: float
    values: np.ndarray  # raw uint16 values of the distance channel
    layer_field: int = 0  # the signed layer-angle field (0 on single-layer scanners; MRS1000: 1/100 deg)
    meas_freq_in_hz: bool = False  # the measurement frequency field was in Hz, not 100 Hz (corrected)


_HEX_TOKEN = re.compile(rb"[0-9A-Fa-f]{1,8}")
_HEX_RUNS = {bits: re.compile(rb"(?:[0-9A-Fa-f]{1,%d} )*[0-9A-Fa-f]{1,%d}" % (bits // 4, bits // 4))
             for bits in (8, 16, 32)}


def _uint(tok: bytes, what: str, bits: int = 32) -> int:
    """A CoLa-A unsigned hex field of at most ``bits`` bits.  Anything else (a sign, ``0x``,
    ``_``, more than 8 digits, a value wider than the field) is ``bad_number``: Python's
    ``int(tok, 16)`` alone accepts all of those and returns integers of any size."""
    if _HEX_TOKEN.fullmatch(tok) is None:
        raise TelegramError("bad_number", f"{what}={tok[:24]!r}")
    v = int(tok, 16)
    if v >> bits:
        raise TelegramError("bad_number", f"{what}={tok[:24]!r} wider than {bits} bits")
    return v


def _i32(v: int) -> int:
    return v - (1 << 32) if v >= (1 << 31) else v


def _i16(v: int) -> int:
    return v - (1 << 16) if v >= (1 << 15) else v


def beam_rate_hz(meas_field: int, scan_freq_hz: float, step_deg: float) -> tuple[float, bool]:
    """The beam (measurement) frequency from the telegram's field, and whether it was in Hz.

    The field is in 100 Hz; some firmware sends Hz (sick_scan_xd divides a field above 10000
    by 100 "due to firmware inconsistency", which would also wrongly divide an LMS4000's
    600 Hz x 4320 beams = 25920).  A rotating mirror fires ``scan frequency x 360 deg / step``
    beams a second (LMS1xx 50 Hz x 720 = 36000 = field 168 hex; TiM571 15 Hz x 1080 = 16200 =
    field A2 hex), so the reading nearer that (by ratio) is taken.  0 stays 0 (no beam timing).
    """
    as_100hz = meas_field * 100.0
    if meas_field == 0 or not scan_freq_hz > 0 or not step_deg > 0:
        return as_100hz, False
    rotation = scan_freq_hz * 360.0 / step_deg
    if abs(math.log(meas_field / rotation)) < abs(math.log(as_100hz / rotation)):
        return float(meas_field), True
    return as_100hz, False


def _check_distance_channel(name: str, n: int, step: int, scale: float) -> None:
    """The distance channel's header, in either dialect: values present, a positive step and scale."""
    if n == 0:
        raise TelegramError("bad_count", f"{name}: no values")
    if step == 0 or not scale > 0:
        raise TelegramError("bad_number", f"{name}: step {step}, scale {scale}: must be > 0")


def _f32(tok: bytes, what: str) -> float:
    v = _uint(tok, what, 32)
    f = struct.unpack(">f", v.to_bytes(4, "big"))[0]
    if not math.isfinite(f):
        raise TelegramError("bad_number", f"{what} not finite")
    return float(f)


def _check_run(tok: list[bytes], bits: int, what: str) -> None:
    """Every token is unsigned hex of at most ``bits`` bits (one regex pass over the joined tokens)."""
    if tok and _HEX_RUNS[bits].fullmatch(b" ".join(tok)) is None:
        raise TelegramError("bad_number", f"{what} not u{bits} hex")


def _u16_values(tok: list[bytes], what: str) -> np.ndarray:
    """``n`` u16 hex tokens -> int64 array."""
    _check_run(tok, 16, what)
    return np.array([int(t, 16) for t in tok], dtype=np.int64)


def parse_lmdscandata(payload: bytes, channel: str = "DIST1") -> ScanTelegram:
    """Parse one LMDscandata telegram (without STX/ETX).

    Raises :class:`TelegramError` (and nothing else) for any malformed input: every
    number is checked to be unsigned hex no wider than its field, counts are bounded
    before they are used as indices, the distance channel needs a positive finite scale,
    a finite offset, a positive angular step and at least one value.
    """
    tok = payload.split()
    if len(tok) < 2 or tok[1] != b"LMDscandata" or tok[0] not in (b"sSN", b"sRA"):
        raise TelegramError("not_scan", repr(payload[:24]))
    if len(tok) < 21:
        raise TelegramError("truncated", f"{len(tok)} tokens")
    i = 2
    version = _uint(tok[i], "version", 16)
    device = _uint(tok[i + 1], "device", 16)
    serial = _uint(tok[i + 2], "serial", 32)
    status = (_uint(tok[i + 3], "status", 8), _uint(tok[i + 4], "status", 8))
    tcount = _uint(tok[i + 5], "telegram_counter", 16)
    scount = _uint(tok[i + 6], "scan_counter", 16)
    t_start = _uint(tok[i + 7], "time_since_startup", 32)
    t_tx = _uint(tok[i + 8], "time_of_transmission", 32)
    # inputs(2) outputs(2) reserved / layer angle(1, signed: MRS1000 FE0C FF06 0 FA)
    for k in range(9, 13):
        _uint(tok[i + k], "io", 16)
    layer = _i16(_uint(tok[i + 13], "layer_angle", 16))
    scan_freq = _uint(tok[i + 14], "scan_freq", 32) / 100.0
    meas_field = _uint(tok[i + 15], "meas_freq", 32)
    i += 16
    n_enc = _uint(tok[i], "n_encoders", 16)
    if n_enc > 8:
        raise TelegramError("bad_count", f"{n_enc} encoders")
    _check_run(tok[i + 1 : i + 1 + 2 * n_enc], 32, "encoder")  # position u32, speed u16
    i += 1 + 2 * n_enc
    if i >= len(tok):
        raise TelegramError("truncated", "after encoders")
    found: ScanTelegram | None = None
    for bits in (16, 8):
        if i >= len(tok):
            raise TelegramError("truncated", "channel count")
        n_ch = _uint(tok[i], "n_channels", 16)
        i += 1
        if n_ch > MAX_CHANNELS:
            raise TelegramError("bad_count", f"{n_ch} channels")
        for _ in range(n_ch):
            if i + 6 > len(tok):
                raise TelegramError("truncated", "channel header")
            name = tok[i].decode("ascii", "replace")
            scale = _f32(tok[i + 1], "scale")
            offset = _f32(tok[i + 2], "offset")
            start = _i32(_uint(tok[i + 3], "start_angle", 32))
            step = _uint(tok[i + 4], "step", 16)
            n = _uint(tok[i + 5], "n_values", 16)
            i += 6
            if n > 10000:
                raise TelegramError("bad_count", f"{n} values")
            if i + n > len(tok):
                raise TelegramError("wrong_count", f"{name}: {n} announced, {len(tok) - i} left")
            if name == channel and found is None and bits == 16:  # an 8-bit channel cannot hold mm
                _check_distance_channel(name, n, step, scale)
                vals = _u16_values(tok[i : i + n], name)
                meas_freq, in_hz = beam_rate_hz(meas_field, scan_freq, step / 10000.0)
                found = ScanTelegram(
                    command=tok[0].decode(),
                    version=version,
                    device=device,
                    serial=serial,
                    status=status,
                    telegram_counter=tcount,
                    scan_counter=scount,
                    time_since_startup_us=t_start,
                    time_of_transmission_us=t_tx,
                    scan_freq_hz=scan_freq,
                    meas_freq_hz=meas_freq,
                    channel=name,
                    scale=scale,
                    offset=offset,
                    start_angle_deg=start / 10000.0,
                    step_deg=step / 10000.0,
                    values=vals,
                    layer_field=layer,
                    meas_freq_in_hz=in_hz,
                )
            else:
                _check_run(tok[i : i + n], bits, name)  # a channel not used is still checked
            i += n
    # position, name, comment, time, events: each "0" (absent) or "1 <fields>".  When all five
    # are absent the telegram must end there: tokens left over mean a count above was too
    # small (the values it did not announce would otherwise be read as these blocks).  After
    # a "1" the block's contents are not parsed (their layout varies by device).
    for block in ("position", "name", "comment", "time", "events"):
        if i >= len(tok):
            raise TelegramError("wrong_count", f"{block} block missing")
        if tok[i] == b"1":
            break
        if tok[i] != b"0":
            raise TelegramError("bad_number", f"{block} flag={tok[i][:16]!r}")
        i += 1
    else:
        if i != len(tok):
            raise TelegramError("wrong_count", f"{len(tok) - i} tokens after the last block")
    if found is None:
        raise TelegramError("no_channel", channel)
    return found


class _BinReader:
    """Big-endian fields of a CoLa-B payload; reading past its end is a :class:`TelegramError`."""

    def __init__(self, data: bytes, pos: int) -> None:
        self.data, self.pos = data, pos

    def take(self, fmt: str, what: str) -> tuple[Any, ...]:
        n = struct.calcsize(">" + fmt)
        if self.pos + n > len(self.data):
            raise TelegramError("truncated", f"{what} at byte {self.pos}")
        v = struct.unpack_from(">" + fmt, self.data, self.pos)
        self.pos += n
        return v


def parse_lmdscandata_binary(payload: bytes, channel: str = "DIST1") -> ScanTelegram:
    """Parse one CoLa-B LMDscandata payload (``sSN LMDscandata `` + binary fields, big-endian).

    The same fields as the CoLa-A telegram at fixed widths (the layout sick_scan_xd's
    ``parseCommonBinaryResultTelegram`` reads): u16 version, device; u32 serial; 2 x u8 status;
    u16 telegram, scan counter; u32 time since start-up, of transmission; 2 x u8 inputs, outputs;
    i16 layer angle; u32 scan frequency (1/100 Hz), measurement frequency (100 Hz); u16 encoders
    [u32 position, u16 speed]; u16 16-bit channels [5-char name, f32 scale, f32 offset, i32 start
    angle, u16 step, u16 count, u16 values]; u16 8-bit channels [same, u8 values].  Raises
    :class:`TelegramError` (and nothing else) for any malformed input.  The position / name /
    comment / time / event blocks after the channels are not read (the frame's checksum vouches
    for its length).
    """
    head = payload[:16]
    if head not in (b"sSN LMDscandata ", b"sRA LMDscandata "):
        raise TelegramError("not_scan", repr(payload[:24]))
    r = _BinReader(payload, 16)
    version, device, serial, st1, st2, tcount, scount, t_start, t_tx = r.take("HHIBBHHII", "header")
    r.take("BBBB", "inputs/outputs")
    (layer,) = r.take("h", "layer angle")
    scan_field, meas_field = r.take("II", "frequencies")
    scan_freq = scan_field / 100.0
    (n_enc,) = r.take("H", "encoders")
    if n_enc > 8:
        raise TelegramError("bad_count", f"{n_enc} encoders")
    r.take("IH" * n_enc, "encoder")
    found: ScanTelegram | None = None
    for width in ("H", "B"):
        (n_ch,) = r.take("H", "channel count")
        if n_ch > MAX_CHANNELS:
            raise TelegramError("bad_count", f"{n_ch} channels")
        for _ in range(n_ch):
            raw_name, scale, offset, start, step, n = r.take("5sffiHH", "channel header")
            name = raw_name.decode("ascii", "replace")
            if not (math.isfinite(scale) and math.isfinite(offset)):
                raise TelegramError("bad_number", f"{name}: scale / offset not finite")
            if r.pos + n * struct.calcsize(width) > len(payload):
                raise TelegramError("wrong_count", f"{name}: {n} values announced, the telegram is shorter")
            vals = np.frombuffer(payload, dtype=">u2" if width == "H" else "u1", count=n, offset=r.pos)
            r.pos += n * struct.calcsize(width)
            if name == channel and found is None and width == "H":
                _check_distance_channel(name, n, step, scale)
                meas_freq, in_hz = beam_rate_hz(meas_field, scan_freq, step / 10000.0)
                found = ScanTelegram(
                    command=payload[:3].decode(), version=version, device=device, serial=serial, status=(st1, st2),
                    telegram_counter=tcount, scan_counter=scount, time_since_startup_us=t_start,
                    time_of_transmission_us=t_tx, scan_freq_hz=scan_freq, meas_freq_hz=meas_freq, channel=name,
                    scale=float(scale), offset=float(offset), start_angle_deg=start / 10000.0,
                    step_deg=step / 10000.0, values=vals.astype(np.int64), layer_field=int(layer),
                    meas_freq_in_hz=in_hz,
                )
    if found is None:
        raise TelegramError("no_channel", channel)
    return found


def telegram_to_scan(
    t: ScanTelegram,
    stamp: float,
    range_min: float = 0.05,
    range_max: float = 50.0,
    angle_offset_deg: float = -90.0,
    frame_id: str = "laser",
    time_increment_from: str = "measurement_frequency",
) -> LaserScan:
    """LMDscandata -> REP 117 LaserScan: 0 -> +inf, beyond range_max -> +inf.

    ``time_increment`` (time between beams, used to de-skew motion): with
    ``"measurement_frequency"`` it is ``1 / measurement frequency`` (0 when the field is 0,
    i.e. the device gives no beam timing); with ``"rotation"`` it is
    ``scan_time * step / 360 deg`` (the mirror's rotation).
    """
    mm = t.values.astype(np.float64) * t.scale + t.offset
    r = (mm / 1000.0).astype(np.float32)
    r[t.values == 0] = np.inf
    r[r > range_max] = np.inf
    inc = math.radians(t.step_deg)
    period = 1.0 / t.scan_freq_hz if t.scan_freq_hz > 0 else 0.0
    if time_increment_from == "rotation":
        dt_beam = period * t.step_deg / 360.0
    else:
        dt_beam = 1.0 / t.meas_freq_hz if t.meas_freq_hz > 0 else 0.0
    return LaserScan(
        stamp=stamp,
        angle_min=math.radians(t.start_angle_deg + angle_offset_deg),
        angle_increment=inc,
        range_min=range_min,
        range_max=range_max,
        ranges=r,
        time_increment=dt_beam,
        scan_time=period,
        frame_id=frame_id,
    )


def _hx(v: int) -> str:
    return format(int(v) & 0xFFFFFFFF, "X")


def encode_lmdscandata(
    scan: LaserScan,
    telegram_counter: int,
    scan_counter: int,
    time_since_startup_us: int,
    time_of_transmission_us: int,
    angle_offset_deg: float = -90.0,
    command: str = "sSN",
    serial: int = 0x1234567,
    *,
    scale: float | None = None,
    rssi_bits: int | None = None,
    name: str | None = None,
    layer_field: int = 0,
    meas_freq_in_hz: bool = False,
) -> bytes:
    """Encode a LaserScan as an LMDscandata payload (no STX/ETX): DIST1 in mm, scale 1 or 2.

    Real-device shapes (for the emulator and tests): ``scale=2.0`` (LMS5xx: 2 mm units),
    ``rssi_bits=16`` (TiM5xx/TiM571: RSSI1 as a second 16-bit channel) or ``8`` (TiM55x,
    LMS1xx: an 8-bit channel), ``name`` (a name block ``1 <len> <name>``, as TiMs send),
    ``layer_field`` (MRS1000's signed layer angle, 1/100 deg) and ``meas_freq_in_hz``
    (the measurement frequency in Hz, as some firmware sends it).
    """
    r = np.asarray(scan.ranges, dtype=np.float64)
    finite = np.isfinite(r) & (r > 0)
    if scale is None:
        scale = 1.0 if not finite.any() or np.max(r[finite]) * 1000.0 <= 65535 else 2.0
    vals = np.zeros(len(r), dtype=np.int64)
    vals[finite] = np.clip(np.round(r[finite] * 1000.0 / scale), 1, 65535).astype(np.int64)
    start = int(round((math.degrees(scan.angle_min) - angle_offset_deg) * 10000.0))
    step = int(round(math.degrees(scan.angle_increment) * 10000.0))
    freq = int(round(100.0 / scan.scan_time)) if scan.scan_time > 0 else 2500
    # measurement frequency in 100 Hz: 1 / time_increment (0 = no beam timing, instantaneous scan)
    mfreq = int(round(0.01 / scan.time_increment)) if scan.time_increment > 0 else 0
    if meas_freq_in_hz:
        mfreq = int(round(1.0 / scan.time_increment)) if scan.time_increment > 0 else 0
    scale_hex = struct.unpack(">I", struct.pack(">f", scale))[0]
    n16 = 2 if rssi_bits == 16 else 1
    head = [
        command, "LMDscandata", "1", "1", _hx(serial), "0", "0",
        _hx(telegram_counter & 0xFFFF), _hx(scan_counter & 0xFFFF),
        _hx(time_since_startup_us), _hx(time_of_transmission_us),
        "0", "0", "0", "0", format(layer_field & 0xFFFF, "X"), _hx(freq), _hx(mfreq),
        "0",  # encoders
        str(n16), "DIST1", format(scale_hex, "X"), "0", _hx(start), _hx(step), _hx(len(vals)),
    ]
    body = [format(int(v), "X") for v in vals]
    # a remission made up from the range (the device's is the echo strength): no echo -> 0
    rssi = np.where(vals > 0, 200 - np.minimum(vals // 200, 150), 0)
    rssi_block = ["RSSI1", "3F800000", "0", _hx(start), _hx(step), _hx(len(vals))] + [format(int(v), "X")
                                                                                   for v in rssi]
    if rssi_bits == 16:
        body += rssi_block
    tail = ["1", *rssi_block] if rssi_bits == 8 else ["0"]  # the 8-bit channels
    tail += ["0"]  # position
    tail += ["1", format(len(name), "X"), name] if name is not None else ["0"]
    tail += ["0", "0", "0"]  # comment, time, events
    return " ".join(head + body + tail).encode("ascii")


def lmdscandata_to_binary(payload: bytes) -> bytes:
    """A CoLa-A LMDscandata payload (as :func:`encode_lmdscandata` writes it) in CoLa-B form: the same
    fields at the widths :func:`parse_lmdscandata_binary` reads.  For the emulator and tests."""
    tok = payload.split()
    h = [int(t, 16) for t in tok[2:18]]
    out = tok[0] + b" LMDscandata " + struct.pack(">HHIBBHHIIBBBBhII", h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7],
                                                   h[8], h[9], h[10], h[11], h[12], _i16(h[13]), h[14], h[15])
    i = 18
    n_enc = int(tok[i], 16)
    out += struct.pack(">H", n_enc) + b"".join(struct.pack(">IH", int(tok[i + 1 + 2 * k], 16),
                                                            int(tok[i + 2 + 2 * k], 16)) for k in range(n_enc))
    i += 1 + 2 * n_enc
    for width in ("H", "B"):
        n_ch = int(tok[i], 16)
        out += struct.pack(">H", n_ch)
        i += 1
        for _ in range(n_ch):
            name, scale, offset = tok[i][:5].ljust(5), int(tok[i + 1], 16), int(tok[i + 2], 16)
            start, step, n = _i32(int(tok[i + 3], 16)), int(tok[i + 4], 16), int(tok[i + 5], 16)
            out += name + struct.pack(">IIiHH", scale, offset, start, step, n)
            out += struct.pack(f">{n}{width}", *(int(t, 16) for t in tok[i + 6 : i + 6 + n]))
            i += 6 + n
    return out + b"\x00\x00" * 5  # position, name, comment, time, events: absent


# ----------------------------------------------------------------------------- client


@dataclass
class SickStats:
    connects: int = 0
    disconnects: int = 0
    connect_failures: int = 0
    scans: int = 0
    malformed: int = 0
    malformed_by_reason: dict[str, int] = field(default_factory=dict)
    other_telegrams: int = 0  # acks (sEA), errors (sFA), ...
    device_errors: int = 0  # sFA answers or device status != 0 0
    device_error_codes: dict[str, int] = field(default_factory=dict)  # sFA answers by SOPAS error name
    scan_counter_gaps: int = 0
    other_layer: int = 0  # telegrams of a multi-layer scanner's other layers (MRS1000), skipped
    layers_seen: set[int] = field(default_factory=set)  # the layer fields seen (at most 64 kept)
    unsupported_device: int = 0  # scans of a device whose angles run clockwise (NAV3xx, LRS36xx, OEM15xx)
    implausible_scan_time: int = 0  # transmission minus scan start over two periods (a clock step between)
    meas_freq_in_hz: int = 0  # scans whose measurement frequency field was in Hz (corrected)

    def count_malformed(self, reason: str) -> None:
        self.malformed += 1
        self.malformed_by_reason[reason] = self.malformed_by_reason.get(reason, 0) + 1


# SOPAS error codes of an ``sFA <code>`` answer (hex), from the CoLa telegram listing.
SOPAS_ERRORS = {
    0x1: "METHODIN_ACCESSDENIED", 0x2: "METHODIN_UNKNOWNINDEX", 0x3: "VARIABLE_UNKNOWNINDEX",
    0x4: "LOCALCONDITIONFAILED", 0x5: "INVALID_DATA", 0x6: "UNKNOWN_ERROR", 0x7: "BUFFER_OVERFLOW",
    0x8: "BUFFER_UNDERFLOW", 0x9: "ERROR_UNKNOWN_TYPE", 0xA: "VARIABLE_WRITE_ACCESSDENIED",
    0xB: "UNKNOWN_CMD_FOR_NAMESERVER", 0xC: "UNKNOWN_COLA_COMMAND", 0xD: "METHODIN_SERVER_BUSY",
    0xE: "FLEX_OUT_OF_BOUNDS", 0xF: "EVENTREG_UNKNOWNINDEX", 0x10: "COLA_A_VALUE_OVERFLOW",
    0x11: "COLA_A_INVALID_CHARACTER",
}


# Device families whose angle convention is not the LMS1xx's (device 0 deg = the scanner's right side,
# so REP 103 = device - 90 deg), from sick_scan_xd's per-family table (driver/src/sick_generic_parser.cpp:
# setScanAngleShift / setScanMirroredAndShifted) and its README (the TiM240's frame is ROS's already).
# ``(ident prefix, REP 103 = device + offset deg, or None: clockwise device angles, not supported)``
DEVICE_FAMILIES: tuple[tuple[str, float | None], ...] = (
    ("TIM24", 0.0), ("LRS4", 0.0), ("NAV2", 0.0),
    ("NAV3", None), ("LRS36", None), ("OEM15", None),
)
DEFAULT_ANGLE_OFFSET_DEG = -90.0  # LMS1xx, LMS5xx, TiM5xx/7xx, MRS1000, LMS4000


def device_angle_offset(ident: str) -> tuple[float | None, bool]:
    """``(offset_deg, known)`` for a DeviceIdent name: the offset is None for a family whose angles
    run clockwise (NAV3xx, LRS36xx, OEM15xx); ``known`` is False for a name not in
    :data:`DEVICE_FAMILIES` (the LMS1xx convention, -90 deg, applies)."""
    up = ident.upper()
    for prefix, off in DEVICE_FAMILIES:
        if up.startswith(prefix):
            return off, True
    return DEFAULT_ANGLE_OFFSET_DEG, False


def parse_device_ident(payload: bytes, binary: bool = False) -> tuple[str, str]:
    """``sRA DeviceIdent <len> <name> <len> <version>`` -> ``(name, version)`` (either may be "");
    in CoLa-B the lengths are u16 (``sRA DeviceIdent \\x00\\x08MRS6124R\\x00\\x0a1.1.0.565C``)."""
    if binary:
        out: list[str] = []
        pos = 16
        for _ in range(2):
            if pos + 2 > len(payload):
                break
            n = int.from_bytes(payload[pos : pos + 2], "big")
            out.append(payload[pos + 2 : pos + 2 + n].decode("ascii", "replace"))
            pos += 2 + n
        out += ["", ""]
        return out[0], out[1]
    tok = payload.split()
    name = tok[3].decode("ascii", "replace") if len(tok) > 3 else ""
    version = tok[5].decode("ascii", "replace") if len(tok) > 5 else ""
    return name, version


def sopas_error_name(payload: bytes, binary: bool = False) -> str:
    """``sFA 5`` -> ``"INVALID_DATA"``; an unknown or missing code -> ``"code <token>"``.  In CoLa-B
    the code is a u16 after ``sFA``."""
    if binary:
        rest = payload[3:].lstrip(b" ")
        if len(rest) >= 2:
            v = int.from_bytes(rest[:2], "big")
            return SOPAS_ERRORS.get(v, f"code {v:X}")
        return "code ?"
    tok = payload.split()
    code = tok[1] if len(tok) > 1 else b"?"
    if _HEX_TOKEN.fullmatch(code) is not None:
        name = SOPAS_ERRORS.get(int(code, 16))
        if name is not None:
            return name
    return "code " + code[:8].decode("ascii", "replace")


class SickClient(SensorThread):
    """Threaded SICK client: connect, ``sRN DeviceIdent`` (the family's angle convention),
    optionally start the measurement, ``sEN LMDscandata 1``, stream, reconnect with back-off;
    in CoLa-A, or CoLa-B once the device is found to speak it (``dialect``).

    ``on_scan(scan, arrival_host_time)`` is called from the client thread for each valid
    scan.  Stamps: the scanner's ``time_since_startup`` (scan start) mapped to host time
    through a :class:`ClockSync` fed with ``(time_of_transmission, arrival)`` pairs; with
    ``align_clock=False`` the stamp is ``arrival - scan_time`` (host clock only).
    """

    role = "client"
    thread_name = "sick-client"

    def __init__(
        self,
        host: str,
        port: int,
        on_scan: Callable[[LaserScan, float], None],
        range_min: float = 0.05,
        range_max: float = 50.0,
        angle_offset_deg: float | None = -90.0,
        frame_id: str = "laser",
        time_increment_from: str = "measurement_frequency",
        align_clock: bool = True,
        stall_timeout_s: float = 1.0,
        backoff_min_s: float = 0.1,
        backoff_max_s: float = 2.0,
        on_event: Callable[[str], None] | None = None,
        layer_field: int = 0,
        first_data_timeout_s: float = 5.0,
        start_measurement: bool = False,
    ) -> None:
        super().__init__(on_event, backoff_min_s, backoff_max_s)
        self.start_measurement = start_measurement
        self.layer_field = layer_field
        self.first_data_timeout_s = first_data_timeout_s  # a scanner still spinning up gets this long
        self._stream_acked = False  # sEA LMDscandata 1 seen on this connection
        self.host, self.port = host, port
        self.on_scan = on_scan
        self.range_min, self.range_max = range_min, range_max
        self.angle_offset_deg = angle_offset_deg  # None: by the device family (sRN DeviceIdent)
        self.device_ident: str | None = None
        self._family_offset_deg: float | None = DEFAULT_ANGLE_OFFSET_DEG
        self.frame_id = frame_id
        self.time_increment_from = time_increment_from
        self.align_clock = align_clock
        self.stall_timeout_s = stall_timeout_s
        self.stats = SickStats()
        self.framer = ColaFramer()
        self.framer_b = ColaBFramer()
        self.dialect = "A"  # CoLa-A (ASCII); "B" once the device is found to speak CoLa-B (binary)
        self.clock = ClockSync()
        self._sock: socket.socket | None = None
        self._t_ext_tx = 0
        self._last_tx: int | None = None
        self._last_scan_counter: int | None = None

    # -- lifecycle
    @property
    def label(self) -> str:
        return f"laser {self.host}:{self.port}"

    def before_join(self) -> None:
        sock = self._sock
        if sock is not None:
            try:
                sock.sendall(self._stop_command())
            except OSError:
                pass

    def _start_commands(self) -> bytes:
        """sRN DeviceIdent, (with ``start_measurement``: log in as authorized client with its default
        password, sMN LMCstartmeas, sMN Run,) sEN LMDscandata 1, in the current dialect."""
        if self.dialect == "B":
            cmds = [b"sRN DeviceIdent"]
            if self.start_measurement:
                cmds += [b"sMN SetAccessMode \x03\xf4\x72\x47\x44", b"sMN LMCstartmeas", b"sMN Run"]
            return b"".join(frame_b(c) for c in cmds + [b"sEN LMDscandata \x01"])
        cmds = [b"sRN DeviceIdent"]
        if self.start_measurement:
            cmds += [b"sMN SetAccessMode 03 F4724744", b"sMN LMCstartmeas", b"sMN Run"]
        return b"".join(frame(c) for c in cmds + [b"sEN LMDscandata 1"])

    def _stop_command(self) -> bytes:
        return frame_b(b"sEN LMDscandata \x00") if self.dialect == "B" else frame("sEN LMDscandata 0")

    def _bytes_in(self) -> int:
        return self.framer.stats.bytes_in + self.framer_b.stats.bytes_in

    # -- processing (also used directly by tests)
    def handle_payload(self, payload: bytes, arrival: float, binary: bool = False) -> LaserScan | None:
        """Process one de-framed telegram; returns the scan (and calls on_scan) if valid.

        Never raises: a malformed telegram is counted per reason (``stats.malformed_by_reason``);
        an unexpected exception while decoding one (a parser bug) is counted as
        ``internal_error`` and reported through ``on_event`` (the first few times), and the
        stream goes on with the next telegram.
        """
        try:
            return self._handle(payload, arrival, binary)
        except Exception as e:  # noqa: BLE001 - one bad telegram must never stop the laser
            self.stats.count_malformed("internal_error")
            if self.stats.malformed_by_reason["internal_error"] <= 3:
                self.on_event(f"{self.label}: telegram skipped ({type(e).__name__}: {e})")
            log.debug("telegram %r", payload[:80], exc_info=True)
            return None

    def _handle(self, payload: bytes, arrival: float, binary: bool = False) -> LaserScan | None:
        head = payload[:16]
        if not (head.startswith(b"sSN LMDscandata") or head.startswith(b"sRA LMDscandata")):
            self.stats.other_telegrams += 1
            if head.startswith(b"sRA DeviceIdent"):
                self._device_ident(payload, binary)
            elif payload in (b"sEA LMDscandata \x01", b"sEA LMDscandata 1") or (
                    payload.split() == [b"sEA", b"LMDscandata", b"1"]):
                self._stream_acked = True
            if head.startswith(b"sAN SetAccessMode") and payload[-1:] in (b"0", b"\x00"):
                self.on_event(f"{self.label}: the device refused the login (sMN SetAccessMode 03, default "
                              f"password): it will not start measuring on request")
            if head.startswith(b"sFA"):
                # the device refused a command (e.g. sEN LMDscandata: it will not stream)
                self.stats.device_errors += 1
                name = sopas_error_name(payload, binary)
                codes = self.stats.device_error_codes
                codes[name] = codes.get(name, 0) + 1
                if codes[name] <= 3:
                    self.on_event(f"{self.label}: the device answered sFA ({name}) to a command")
            return None
        try:
            t = parse_lmdscandata_binary(payload) if binary else parse_lmdscandata(payload)
        except TelegramError as e:
            self.stats.count_malformed(e.reason)
            return None
        if t.status != (0, 0):
            self.stats.device_errors += 1
        if t.meas_freq_in_hz:
            self.stats.meas_freq_in_hz += 1
            if self.stats.meas_freq_in_hz == 1:
                self.on_event(f"{self.label}: measurement frequency sent in Hz, not 100 Hz; read as "
                              f"{t.meas_freq_hz:.0f} Hz (the mirror's beam rate)")
        if self._last_scan_counter is not None:
            gap = (t.scan_counter - self._last_scan_counter - 1) & 0xFFFF
            if 0 < gap < 0x8000:
                self.stats.scan_counter_gaps += gap
        self._last_scan_counter = t.scan_counter
        period = 1.0 / t.scan_freq_hz if t.scan_freq_hz > 0 else 0.04
        if self.align_clock:
            if self._last_tx is None:
                self._t_ext_tx = t.time_of_transmission_us
            else:
                # signed: less than half the u32 range forward is time going on (a wrap if the value went
                # down), a step back is the device's clock stepping back (ClockSync re-anchors on it)
                self._t_ext_tx += ((t.time_of_transmission_us - self._last_tx + 0x80000000) & 0xFFFFFFFF) - 0x80000000
            self._last_tx = t.time_of_transmission_us
            # device time of the scan start on the same unwrapped axis; a scan longer than two periods
            # is not one (the clock stepped between the scan's start and its transmission): one period
            took_us = (t.time_of_transmission_us - t.time_since_startup_us) & 0xFFFFFFFF
            if took_us > (2.0 * period + 0.02) * 1e6:
                self.stats.implausible_scan_time += 1
                took_us = int(period * 1e6)
            start_dev = self._t_ext_tx - took_us
            step = self.clock.update(self._t_ext_tx * 1e-6, arrival)
            if step is not None:
                self.on_event(f"{self.label}: laser {step.describe()}")
            stamp = self.clock.to_host(start_dev * 1e-6, arrival)
        else:
            stamp = arrival - period
        if len(self.stats.layers_seen) < 64:
            self.stats.layers_seen.add(t.layer_field)
        if t.layer_field != self.layer_field:
            # a multi-layer scanner (MRS1000): one telegram per layer, each tilted; only one is planar
            self.stats.other_layer += 1
            if self.stats.other_layer in (1, 100) and self.stats.scans == 0:
                seen = " ".join(str(v) for v in sorted(self.stats.layers_seen))
                self.on_event(f"{self.label}: multi-layer telegrams (layer fields seen: {seen}); localizing "
                              f"with laser.layer_field {self.layer_field}, skipping the others")
            return None
        offset = self.angle_offset_deg if self.angle_offset_deg is not None else self._family_offset_deg
        if offset is None or self._family_offset_deg is None:
            # device angles running clockwise: read as counter-clockwise they would be a mirrored scan
            self.stats.unsupported_device += 1
            return None
        scan = telegram_to_scan(t, stamp, self.range_min, self.range_max, offset, self.frame_id,
                                self.time_increment_from)
        self.stats.scans += 1
        self.on_scan(scan, arrival)
        return scan

    def _stall_reason(self, got_scans: bool, bytes0: int, limit_s: float) -> str:
        """Why a connection is given up as stalled, as far as the device let it be known."""
        if got_scans:
            return f"no data for {limit_s:g} s (stalled)"
        if self._bytes_in() == bytes0:
            return (f"no answer to sRN DeviceIdent / sEN LMDscandata 1 (CoLa-{self.dialect}) in {limit_s:g} s "
                    f"(not a SICK port, or a device set to the other CoLa dialect?)")
        if self._stream_acked:
            how = ("it was told sMN LMCstartmeas and Run" if self.start_measurement
                   else "laser.start_measurement: true sends sMN LMCstartmeas")
            return (f"sEN LMDscandata 1 acknowledged but no scan in {limit_s:g} s (is the scanner measuring? "
                    f"{how}; SOPAS ET shows its state)")
        return f"no scan in {limit_s:g} s and sEN LMDscandata 1 not acknowledged (see the answers above)"

    def _device_ident(self, payload: bytes, binary: bool = False) -> None:
        name, version = parse_device_ident(payload, binary)
        off, known = device_angle_offset(name)
        first = self.device_ident != name
        self.device_ident, self._family_offset_deg = name, off
        if not first:
            return
        if off is None:
            self.on_event(f"{self.label}: {name} {version}: its scan angles run clockwise, which fgloc does not "
                          f"read; its scans are counted (unsupported_device) and skipped")
        elif self.angle_offset_deg is None:
            how = "its family's" if known else "the LMS1xx convention,"
            self.on_event(f"{self.label}: {name} {version}: device angle + {off:g} deg = REP 103 ({how} "
                          f"laser.angle_offset_deg)")
        elif known and off != self.angle_offset_deg:
            self.on_event(f"{self.label}: {name} {version}: its family's angle offset is {off:g} deg, "
                          f"laser.angle_offset_deg is {self.angle_offset_deg:g}: check the scan's orientation")

    def counters(self) -> dict[str, Any]:
        """Every laser counter, for the status line and the summary."""
        st = self.stats
        return {
            "scans": st.scans, "malformed": st.malformed, "malformed_by_reason": dict(st.malformed_by_reason),
            "garbage_bytes": self.framer.stats.garbage_bytes, "truncated": self.framer.stats.truncated,
            "connects": st.connects, "disconnects": st.disconnects, "scan_gaps": st.scan_counter_gaps,
            "device_errors": st.device_errors, "device_error_codes": dict(st.device_error_codes),
            "other_layer": st.other_layer, "meas_freq_in_hz": st.meas_freq_in_hz,
            "unsupported_device": st.unsupported_device, "device": self.device_ident,
            "clock_steps": self.clock.n_steps, "clock_outliers": self.clock.outliers,
            "clock_step_sizes_s": [round(st.step_s, 4) for st in self.clock.steps],
            "implausible_scan_time": st.implausible_scan_time,
            "layers_seen": sorted(st.layers_seen),
            "cola_b_headers": self.framer.stats.cola_b_headers, "dialect": self.dialect,
            "cola_b_telegrams": self.framer_b.stats.telegrams, "cola_b_bad_checksum": self.framer_b.bad_checksum,
            "thread_failure": self.failure,
        }

    def serve(self) -> None:
        """The client loop (connect, stream, reconnect) until :meth:`stop`; runs in the thread."""
        backoff = self.backoff_min_s
        while not self.stop_event.is_set():
            try:
                sock = socket.create_connection((self.host, self.port), timeout=1.0)
            except OSError as e:
                self.stats.connect_failures += 1
                backoff = self.retry_later(self.stats.connect_failures, f"connect failed ({e})", backoff)
                continue
            backoff = self.backoff_min_s
            self._sock = sock
            self.stats.connects += 1
            self.connected = True
            self.framer.reset()
            self.framer_b.reset()
            self._last_tx = None
            self._last_scan_counter = None
            self.clock.reset()  # the device may have rebooted: its clock restarts
            self.on_event(f"{self.label}: connected")
            try:
                sock.settimeout(0.1)
                # who it is (the family's angle convention), then stream; answered in this order
                sock.sendall(self._start_commands())
                self._stream_acked = False
                scans0, bytes0 = self.stats.scans, self._bytes_in()
                last_data = time.monotonic()
                while not self.stop_event.is_set():
                    try:
                        chunk = sock.recv(65536)
                    except TimeoutError:
                        # a scanner still spinning up gets longer before it counts as stalled
                        got_scans = self.stats.scans > scans0
                        limit = self.stall_timeout_s if got_scans else max(self.stall_timeout_s,
                                                                           self.first_data_timeout_s)
                        if time.monotonic() - last_data > limit:
                            silent = self._bytes_in() == bytes0
                            reason = self._stall_reason(got_scans, bytes0, limit)
                            if silent:
                                # a device set to the other dialect may ignore these commands: try it
                                self.dialect = "B" if self.dialect == "A" else "A"
                                reason += f"; trying CoLa-{self.dialect} next"
                            raise ConnectionError(reason) from None
                        continue
                    if not chunk:
                        raise ConnectionError("closed by peer")
                    now = time.time()
                    last_data = time.monotonic()
                    started_in_b = self.dialect == "B"
                    if self.dialect == "A":
                        n_b = self.framer.stats.cola_b_headers
                        for payload in self.framer.feed(chunk):
                            self.handle_payload(payload, now)
                        if self.framer.stats.cola_b_headers > n_b:
                            # the device speaks CoLa-B: read this chunk again as such, and from now on
                            self.dialect = "B"
                            self.on_event(f"{self.label}: the device sends CoLa-B (binary) telegrams; reading "
                                          f"CoLa-B")
                            chunk = chunk[chunk.find(b"\x02"):] if b"\x02" in chunk else chunk
                        else:
                            continue
                    for payload in self.framer_b.feed(chunk):
                        self.handle_payload(payload, now, binary=True)
                    m = _COLA_A_TELEGRAM.search(chunk) if started_in_b else None  # (else read as CoLa-A above)
                    if m is not None:
                        # the device answers in CoLa-A (set back to it): read it as such from here on
                        self.dialect = "A"
                        self.framer_b.reset()
                        self.on_event(f"{self.label}: the device sends CoLa-A telegrams; reading CoLa-A")
                        for payload in self.framer.feed(chunk[m.start() :]):
                            self.handle_payload(payload, now)
                try:
                    sock.sendall(self._stop_command())
                except OSError:
                    pass
            except (OSError, ConnectionError) as e:
                self.stats.disconnects += 1
                self.on_event(f"{self.label}: connection lost ({e}); reconnecting")
            finally:
                self.connected = False
                self._sock = None
                try:
                    sock.close()
                except OSError:
                    pass
