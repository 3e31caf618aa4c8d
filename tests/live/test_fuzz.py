"""Property-based fuzzing of the live parsers (issue 12): the STM32 serial frame parser (with
the frame converter behind it) and the SICK CoLa-A framer + LMDscandata parser (through the
client's ``handle_payload``).  For any stream: no exception escapes, every valid record is
parsed exactly as it was sent, every bad record is counted.

Bounded: the four properties run in a few seconds together (``max_examples`` below);
``derandomize`` makes every run (and CI) see the same examples.  A deeper randomized hunt:
``FGLOC_FUZZ_EXAMPLES=5000 pytest tests/live/test_fuzz.py``.
"""

from __future__ import annotations

import math
import os
import struct

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fgloc.live.serial_link import FrameConverter, RobotParams
from fgloc.live.serial_protocol import (
    FLAG_COUNTS,
    FLAG_GYRO,
    FLAG_HEADING,
    FrameParser,
    encode_sensor_frame,
)
from fgloc.live.sick import ColaFramer, SickClient, TelegramError, frame, parse_lmdscandata

# FGLOC_FUZZ_EXAMPLES=5000 for a long, randomized hunt (the default is the bounded, repeatable CI run)
_DEEP = int(os.environ.get("FGLOC_FUZZ_EXAMPLES", "0"))
FUZZ = settings(max_examples=_DEEP or 80, deadline=None, derandomize=not _DEEP, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])

U16 = st.integers(0, 0xFFFF)
U32 = st.integers(0, 0xFFFFFFFF)
I32 = st.integers(-(2**31), 2**31 - 1)

# ------------------------------------------------------------------------------ serial

HEADING_OK = st.one_of(st.none(), st.integers(-1800, 3599))
HEADING_BAD = st.one_of(st.integers(-32768, -1801), st.integers(3600, 32766))  # 32767 = absent
GYRO = st.one_of(st.none(), st.integers(-32767, 32766))

valid_frame = st.tuples(st.just("ok"), st.sampled_from([2, 4]), U32, st.lists(I32, min_size=4, max_size=4),
                        HEADING_OK, GYRO)
bad_heading_frame = st.tuples(st.just("bad_heading"), st.sampled_from([2, 4]), U32,
                              st.lists(I32, min_size=4, max_size=4), HEADING_BAD, GYRO)
# corrupted: one byte after the sync + len flipped (CRC-16 catches every single-byte error)
corrupt_frame = st.tuples(st.just("corrupt"), st.sampled_from([2, 4]), st.integers(4, 33), st.integers(1, 255))
truncated_frame = st.tuples(st.just("truncated"), st.sampled_from([2, 4]), st.integers(2, 33))
noise = st.tuples(st.just("noise"), st.binary(min_size=1, max_size=40))
serial_record = st.one_of(valid_frame, bad_heading_frame, corrupt_frame, truncated_frame, noise)


def _flags(heading, gyro):
    return FLAG_COUNTS | (FLAG_HEADING if heading is not None else 0) | (FLAG_GYRO if gyro is not None else 0)


def _build_serial(records, exact):
    """Stream bytes + what was sent.  ``exact``: bad frames and noise contain no 0xA5, so no false
    sync can appear inside them and the error counts are exact."""
    stream = bytearray()
    sent = []  # (seq, t_us, counts, heading, gyro) of every valid frame
    n_bad = n_bad_heading = n_lost = 0  # n_lost: bad frames after the first valid one (seen as gaps)
    seq = 0
    prev = ""
    for rec in records:
        kind = rec[0]
        if kind in ("ok", "bad_heading"):
            _, n, t_us, counts, heading, gyro = rec
            counts = counts[:n]
            stream += encode_sensor_frame(seq, t_us, counts, heading, gyro, _flags(heading, gyro))
            sent.append((seq, t_us, tuple(counts), heading if kind == "ok" else None, gyro))
            n_bad_heading += kind == "bad_heading"
        elif kind == "corrupt":
            _, n, pos, xor = rec
            f = bytearray(encode_sensor_frame(seq, 5, [1, 2, 3, 4][:n], 0))
            f[min(pos, len(f) - 1)] ^= xor
            if exact and b"\xa5" in f[1:]:
                f[min(pos, len(f) - 1)] ^= xor ^ 0x01  # another single-byte error, no sync byte
            stream += f
            n_bad += 1
            n_lost += bool(sent)
        elif kind == "truncated":
            _, n, cut = rec
            f = encode_sensor_frame(seq, 5, [1, 2, 3, 4][:n], 0)
            stream += f[: min(cut, len(f) - 3)]  # cut into the payload: the next bytes cannot complete it
            n_bad += 1
            n_lost += bool(sent)
        else:
            if exact and prev == "truncated":
                continue  # noise could complete a cut frame with a matching CRC: a valid frame, not bad
            data = rec[1].replace(b"\xa5", b"\x00") if exact else rec[1]
            stream += data
            prev = kind
            continue
        prev = kind
        seq += 1
    # a final valid frame resolves a truncated frame at the end of the stream
    stream += encode_sensor_frame(seq, 7, [0, 0], None, None, FLAG_COUNTS)
    sent.append((seq, 7, (0, 0), None, None))
    return bytes(stream), sent, n_bad, n_bad_heading, n_lost


def _feed_in_chunks(feed, data, sizes):
    out = []
    pos = k = 0
    while pos < len(data):
        n = sizes[k % len(sizes)]
        out += feed(data[pos : pos + n])
        pos += n
        k += 1
    return out


def _as_tuple(f):
    return (f.seq, f.t_us, f.counts, f.heading_ddeg, f.gyro_cdps)


@FUZZ
@given(st.lists(serial_record, max_size=30), st.lists(st.integers(1, 120), min_size=1, max_size=8))
def test_serial_parser_every_valid_frame_parsed_every_bad_one_counted(records, sizes):
    data, sent, n_bad, n_bad_heading, n_lost = _build_serial(records, exact=True)
    p = FrameParser()
    got = _feed_in_chunks(p.feed, data, sizes)
    s = p.stats
    assert [_as_tuple(f) for f in got] == sent
    assert s.crc_errors + s.length_errors + s.truncated == n_bad
    assert s.dropped == n_lost  # their sequence numbers never arrived intact
    assert s.bad_heading == n_bad_heading
    assert p.pending == 0 and s.bytes_in == len(data) == s.frame_bytes_ok + s.garbage_bytes


@FUZZ
@given(st.lists(serial_record, max_size=30), st.lists(st.integers(1, 120), min_size=1, max_size=8))
def test_serial_any_noise_no_exception_valid_frames_found_twists_plausible(records, sizes):
    """Noise may contain sync bytes (false frame starts): the valid frames are all still found
    (in order, among possibly more), and the converter turns random counts into nothing faster
    than the robot's limits."""
    data, sent, *_ = _build_serial(records, exact=False)
    p = FrameParser()
    got = [_as_tuple(f) for f in _feed_in_chunks(p.feed, data, sizes)]
    it = iter(got)
    assert all(any(g == want for g in it) for want in sent)  # sent is a subsequence of got
    assert p.stats.bytes_in == p.stats.frame_bytes_ok + p.stats.garbage_bytes + p.pending
    robot = RobotParams(drive="diff")
    conv = FrameConverter(robot, align_clock=False)
    msgs = []
    for k, f in enumerate(FrameParser().feed(data)):
        msgs += conv.convert(f, 100.0 + 0.01 * k)
    for kind, m in msgs:
        if kind == "odom":
            assert math.hypot(m.twist[0], m.twist[1]) <= conv.max_speed_mps
            assert abs(m.twist[2]) <= conv.max_yaw_rate_radps
        else:
            assert -math.pi <= m.yaw_rad <= math.pi


# ------------------------------------------------------------------------------ CoLa-A

F32_SCALE = st.floats(min_value=0.0625, max_value=1024.0, width=32)
F32_OFFSET = st.floats(min_value=-1024.0, max_value=1024.0, width=32)


def _hx(v: int) -> bytes:
    return format(v, "X").encode()


def _f32_hex(f: float) -> bytes:
    return _hx(struct.unpack(">I", struct.pack(">f", f))[0])


@st.composite
def telegrams(draw):
    """A valid LMDscandata token list with random fields, and what the parser must return."""
    n = draw(st.integers(1, 40))
    want = {
        "scan_counter": draw(U16), "t_start": draw(U32), "t_tx": draw(U32), "scale": draw(F32_SCALE),
        "offset": draw(F32_OFFSET), "start": draw(I32), "step": draw(st.integers(1, 0xFFFF)),
        "values": draw(st.lists(U16, min_size=n, max_size=n)),
        # the layer-angle token (signed 16 bit): 0 on single-layer scanners, MRS1000 FE0C FF06 0 FA
        "layer": draw(st.one_of(st.just(0), st.integers(-0x8000, 0x7FFF))),
    }
    head = [draw(st.sampled_from([b"sSN", b"sRA"])), b"LMDscandata", _hx(draw(U16)), _hx(draw(U16)),
            _hx(draw(U32)), b"0", b"0", _hx(draw(U16)), _hx(want["scan_counter"]), _hx(want["t_start"]),
            _hx(want["t_tx"])] + [_hx(draw(U16)) for _ in range(4)] + [_hx(want["layer"] & 0xFFFF)] + [
            _hx(draw(U32)), _hx(draw(U32))]
    n_enc = draw(st.integers(0, 2))
    head += [_hx(n_enc)] + [_hx(draw(U32 if k % 2 == 0 else U16)) for k in range(2 * n_enc)]
    dist = [b"DIST1", _f32_hex(want["scale"]), _f32_hex(want["offset"]), _hx(want["start"] & 0xFFFFFFFF),
            _hx(want["step"]), _hx(n)] + [_hx(v) for v in want["values"]]
    others = []
    for name in draw(st.lists(st.sampled_from([b"RSSI1", b"DIST2"]), max_size=2)):
        m = draw(st.integers(0, 10))
        others.append([name, _f32_hex(1.0), b"0", b"0", b"1388", _hx(m)] + [_hx(draw(U16)) for _ in range(m)])
    pos = draw(st.integers(0, len(others)))
    chans16 = others[:pos] + [dist] + others[pos:]
    tok = head + [_hx(len(chans16))] + [t for c in chans16 for t in c]
    if draw(st.booleans()):  # one 8-bit channel
        m = draw(st.integers(0, 10))
        tok += [b"1", b"RSSI1", _f32_hex(1.0), b"0", b"0", b"1388", _hx(m)] + [_hx(draw(st.integers(0, 255)))
                                                                              for _ in range(m)]
    else:
        tok += [b"0"]
    tok += [b"0"] * 5  # position, name, comment, time, events: absent
    names = {i for i, t in enumerate(tok) if t in (b"RSSI1", b"DIST2")}  # any token is a valid name
    return tok, want, names


BAD_TOKEN = st.one_of(
    st.builds(lambda s, h: s + h, st.sampled_from([b"-", b"+"]), st.sampled_from([b"1", b"3F800000", b"FF"])),
    st.integers(9, 24).map(lambda k: b"1" * k),  # wider than any field
    st.sampled_from([b"0x10", b"1_0", b"G", b"12.5", b"-", b"1.0e5", b"NaN", b"inf", b"\xff"]),
)


@st.composite
def bad_telegrams(draw):
    tok, _, names = draw(telegrams())
    kind = draw(st.sampled_from(["token", "truncate", "more_values", "wide_value"]))
    i_n = tok.index(b"DIST1") + 5  # DIST1's value count
    if kind == "token":
        i = draw(st.sampled_from([k for k in range(2, len(tok)) if k not in names]))
        tok[i] = draw(BAD_TOKEN)
    elif kind == "truncate":
        tok = tok[: draw(st.integers(2, len(tok) - 1))]
    elif kind == "more_values":
        tok[i_n] = _hx(int(tok[i_n], 16) + draw(st.integers(1, 50)))
    else:
        i = draw(st.integers(i_n + 1, i_n + int(tok[i_n], 16)))
        tok[i] = _hx(draw(st.integers(0x10000, 0xFFFFFFFF)))
    return tok


GARBAGE = st.binary(max_size=30).map(lambda b: b.replace(b"\x02", b"").replace(b"\x03", b""))


@FUZZ
@given(telegrams())
def test_cola_every_valid_telegram_parses_to_what_was_sent(t):
    tok, want, _ = t
    got = parse_lmdscandata(b" ".join(tok))
    assert got.scan_counter == want["scan_counter"]
    assert got.time_since_startup_us == want["t_start"] and got.time_of_transmission_us == want["t_tx"]
    assert got.scale == want["scale"] and got.offset == want["offset"]
    assert got.start_angle_deg == want["start"] / 10000.0 and got.step_deg == want["step"] / 10000.0
    assert got.values.tolist() == want["values"]
    assert got.layer_field == want["layer"]


@FUZZ
@given(st.lists(st.one_of(telegrams().map(lambda t: ("ok", t[0], t[1])),
                          bad_telegrams().map(lambda t: ("bad", t, None))), max_size=12),
       st.lists(GARBAGE, min_size=1, max_size=5), st.lists(st.integers(1, 400), min_size=1, max_size=8))
def test_cola_stream_every_valid_scan_delivered_every_bad_one_counted(items, garbage, sizes):
    stream = bytearray()
    sent = []
    n_bad = 0
    for k, (kind, tok, want) in enumerate(items):
        stream += garbage[k % len(garbage)] + frame(b" ".join(tok))
        if kind == "ok":
            sent.append(want)  # a telegram of another layer than the client's (0) is counted, not localized
        else:
            n_bad += 1
    scans = []
    client = SickClient("127.0.0.1", 1, on_scan=lambda s, a: scans.append(s), align_clock=False)
    client.framer = ColaFramer()
    _feed_in_chunks(lambda chunk: [client.handle_payload(p, 1.0) for p in client.framer.feed(chunk)],
                    bytes(stream), sizes)
    st_ = client.stats
    other_layer = [w for w in sent if w["layer"] != 0]
    sent = [w for w in sent if w["layer"] == 0]
    assert st_.scans == len(scans) == len(sent) and st_.other_layer == len(other_layer)
    assert st_.malformed == n_bad and "internal_error" not in st_.malformed_by_reason
    for s, want in zip(scans, sent, strict=True):
        v = np.asarray(want["values"], dtype=np.float64)
        r = ((v * want["scale"] + want["offset"]) / 1000.0).astype(np.float32)
        r[(v == 0) | (r > client.range_max)] = np.inf  # 0 = no echo (REP 117: +inf)
        assert np.array_equal(s.ranges, r)
    try:
        for kind, tok, _ in items:
            if kind == "bad":
                parse_lmdscandata(b" ".join(tok))
                raise AssertionError("a bad telegram parsed")
    except TelegramError:
        pass
