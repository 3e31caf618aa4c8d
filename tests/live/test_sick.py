"""CoLa-A framing and LMDscandata parsing, malformed telegram fuzzing."""

from __future__ import annotations

import math
import random

import numpy as np
import pytest

from fgloc.live.sick import (
    ColaFramer,
    SickClient,
    TelegramError,
    encode_lmdscandata,
    frame,
    parse_lmdscandata,
    telegram_to_scan,
)
from fgloc.types import LaserScan

# a telegram written by hand after the LMS1xx manual's field table (not produced by our encoder)
HAND = (
    b"sRA LMDscandata 1 1 89A27F 0 0 343 347 27477BA9 2747813B 0 0 7 0 0 1388 168 0 1 "
    b"DIST1 3F800000 00000000 FFF92230 1388 5 2E6 0 3E8 FFFF 1F4 0 0 0 0 0 0"
)


def test_parse_hand_written_telegram():
    t = parse_lmdscandata(HAND)
    assert t.command == "sRA" and t.scan_counter == 0x347
    assert t.scan_freq_hz == 50.0 and t.step_deg == 0.5 and t.start_angle_deg == -45.0
    assert t.values.tolist() == [0x2E6, 0, 1000, 0xFFFF, 500]
    s = telegram_to_scan(t, stamp=10.0, range_max=50.0)
    assert math.isclose(math.degrees(s.angle_min), -135.0)
    assert s.ranges[0] == pytest.approx(0.742) and s.ranges[2] == pytest.approx(1.0)
    assert np.isposinf(s.ranges[1])  # 0 = no echo -> +inf (REP 117)
    assert np.isposinf(s.ranges[3])  # 65.535 m > range_max -> +inf
    assert s.scan_time == pytest.approx(0.02)
    assert s.time_increment == pytest.approx(1 / 36000)  # measurement frequency 0x168 x 100 Hz
    rot = telegram_to_scan(t, stamp=10.0, time_increment_from="rotation")
    assert rot.time_increment == pytest.approx(0.02 * 0.5 / 360)


def _scan(n=541, seed=0):
    rng = np.random.default_rng(seed)
    r = rng.uniform(0.5, 30.0, n).astype(np.float32)
    r[::17] = np.inf
    return LaserScan(stamp=0.0, angle_min=math.radians(-135), angle_increment=math.radians(0.5),
                     range_min=0.05, range_max=50.0, ranges=r, scan_time=0.04, time_increment=1 / 18000)


def test_encode_parse_roundtrip():
    s = _scan()
    p = encode_lmdscandata(s, 5, 6, 1_000_000, 1_030_000)
    t = parse_lmdscandata(p)
    back = telegram_to_scan(t, 1.0)
    assert len(back.ranges) == 541
    fin = np.isfinite(s.ranges)
    assert np.array_equal(fin, np.isfinite(back.ranges))
    assert np.max(np.abs(back.ranges[fin] - s.ranges[fin])) <= 0.0005 + 1e-6
    assert back.angle_min == pytest.approx(s.angle_min, abs=1e-6)
    assert back.angle_increment == pytest.approx(s.angle_increment, abs=1e-7)
    assert back.scan_time == pytest.approx(0.04)
    assert back.time_increment == pytest.approx(1 / 18000)  # carried as the measurement frequency


def test_framer_garbage_and_truncation():
    f = ColaFramer()
    out = f.feed(b"xx" + frame("sEA LMDscandata 1") + b"\x02sSN LMDscan" + frame("abc") + b"yy")
    assert out == [b"sEA LMDscandata 1", b"abc"]
    assert f.stats.truncated == 1 and f.stats.garbage_bytes == 2 + 12 + 2


def _mutations(good: bytes, rng: random.Random) -> tuple[bytes, str]:
    tok = good.split(b" ")
    kind = rng.choice(["truncate", "bad_number", "wrong_count_less", "wrong_count_more", "drop_tail"])
    if kind == "truncate":
        return good[: rng.randint(5, len(good) - 10)], kind
    if kind == "bad_number":
        i = rng.randint(2, len(tok) - 8)
        tok[i] = b"ZZ" + tok[i]
        return b" ".join(tok), kind
    n_idx = 25  # index of the value count token in our encoder's layout
    n = int(tok[n_idx], 16)
    if kind == "wrong_count_less":
        del tok[n_idx + 1 : n_idx + 1 + rng.randint(7, 50)]
    elif kind == "wrong_count_more":
        tok[n_idx] = format(n + rng.randint(7, 50), "X").encode()
    else:
        tok = tok[: -rng.randint(2, 6)]
    return b" ".join(tok), kind


def test_malformed_telegrams_interleaved_all_counted():
    rng = random.Random(3)
    scans: list[LaserScan] = []
    client = SickClient("127.0.0.1", 1, on_scan=lambda s, t: scans.append(s), align_clock=False)
    stream = bytearray()
    n_good = n_bad = 0
    for k in range(300):
        good = encode_lmdscandata(_scan(181, k), k, k, k * 40_000, k * 40_000 + 20_000)
        if rng.random() < 0.5:
            stream += frame(good)
            n_good += 1
        else:
            bad, _ = _mutations(good, rng)
            stream += frame(bad)
            n_bad += 1
        if rng.random() < 0.2:
            stream += bytes(rng.getrandbits(8) for _ in range(rng.randint(1, 40))).replace(b"\x02", b"")
    pos = 0
    while pos < len(stream):
        n = rng.randint(1, 5000)
        for payload in client.framer.feed(bytes(stream[pos : pos + n])):
            client.handle_payload(payload, 1000.0 + pos * 1e-6)
        pos += n
    assert len(scans) == client.stats.scans == n_good
    assert client.stats.malformed == n_bad
    assert set(client.stats.malformed_by_reason) <= {"truncated", "bad_number", "wrong_count", "bad_count"}
    print(f"laser fuzz: {n_good} valid + {n_bad} malformed telegrams, {len(stream)} bytes; "
          f"by reason {client.stats.malformed_by_reason}, framing {client.framer.stats.as_dict()}")


def test_parse_errors_are_typed():
    with pytest.raises(TelegramError) as e:
        parse_lmdscandata(b"sSN LMDscandata 1 2 3")
    assert e.value.reason == "truncated"
    with pytest.raises(TelegramError) as e:
        parse_lmdscandata(b"sEA LMDscandata 1")
    assert e.value.reason == "not_scan"


# --------------------------------------------------------------------------- issue 12 item 8
# One telegram with a negative scale, negative counts or an over-long hex field raised
# OverflowError / IndexError / ValueError out of the parser and killed the client thread.

NASTY = [b"-1", b"-3F800000", b"-5", b"123456789ABCDEF01234", b"FFFFFFFFF", b"0x10", b"+5", b"1_0", b"G",
         b"BF800000", b"7F800000", b"7FC00000", b"0", b"FFFF", b"FFFFFFFF", b"10000"]


def _small_telegram(n=10):
    r = np.linspace(1.0, 3.0, n).astype(np.float32)
    s = LaserScan(stamp=0.0, angle_min=math.radians(-135), angle_increment=math.radians(0.5), range_min=0.05,
                  range_max=50.0, ranges=r, scan_time=0.04, time_increment=1 / 18000)
    return encode_lmdscandata(s, 1, 1, 100, 200)


@pytest.mark.parametrize("index, token", [(21, b"-3F800000"), (21, b"BF800000"), (25, b"-5"), (18, b"-1"),
                                          (19, b"-1"), (24, b"-1"), (26, b"123456789ABCDEF012345"),
                                          (9, b"123456789ABCDEF01234"), (27, b"-1"), (27, b"10000")])
def test_reported_overflow_telegrams_are_typed_errors(index, token):
    tok = _small_telegram().split(b" ")
    tok[index] = token
    with pytest.raises(TelegramError):
        parse_lmdscandata(b" ".join(tok))


def test_every_token_replaced_by_nasty_values_never_escapes():
    """Each token of a valid telegram replaced by each nasty token: the client counts or accepts
    every one and never raises; an accepted one has sane geometry."""
    good = _small_telegram()
    tok = good.split(b" ")
    scans: list[LaserScan] = []
    client = SickClient("127.0.0.1", 1, on_scan=lambda s, t: scans.append(s), align_clock=False)
    n = 0
    for i in range(len(tok)):
        for bad in NASTY:
            t = list(tok)
            t[i] = bad
            client.handle_payload(b" ".join(t), 1000.0 + n * 0.04)
            n += 1
    st = client.stats
    assert st.scans + st.malformed + st.other_telegrams + st.other_layer == n
    assert st.malformed > 0 and st.scans > 0
    for s in scans:
        assert s.angle_increment > 0 and len(s.ranges) == 10
        fin = s.ranges[np.isfinite(s.ranges)]
        assert np.all(fin >= 0)
    assert "internal_error" not in st.malformed_by_reason  # all caught by the parser's own checks


@pytest.mark.parametrize("less", [1, 2, 5])
def test_value_count_too_small_is_not_accepted_with_fewer_beams(less):
    """N announced smaller than the values sent: the values left over used to be read as the
    trailing presence flags and the scan accepted with fewer beams (a silent wrong scan)."""
    inf = np.inf  # sent as 0 (no echo), as common in real data as any value
    r = np.array([inf, 1.0, inf, 2.0, inf, inf, 3.0], dtype=np.float32)
    s = LaserScan(stamp=0.0, angle_min=-1.0, angle_increment=0.01, range_min=0.05, range_max=50.0, ranges=r,
                  scan_time=0.04)
    tok = encode_lmdscandata(s, 1, 1, 100, 200).split(b" ")
    i = tok.index(b"DIST1") + 5
    assert int(tok[i], 16) == 7
    tok[i] = format(7 - less, "X").encode()
    with pytest.raises(TelegramError) as e:
        parse_lmdscandata(b" ".join(tok))
    assert e.value.reason in ("wrong_count", "bad_count", "bad_number")
