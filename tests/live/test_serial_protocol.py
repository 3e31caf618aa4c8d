"""Serial protocol: encoding, CRC, incremental parsing, resync, drops, wrap-around, fuzzing."""

from __future__ import annotations

import random

import pytest

from fgloc.live.serial_protocol import (
    SYNC,
    FrameParser,
    crc16,
    crc16_ccitt,
    encode_sensor_frame,
)


def test_crc_matches_ccitt_false_check_value():
    assert crc16_ccitt(b"123456789") == 0x29B1
    assert crc16(b"123456789") == 0x29B1


def _frames(n, n_wheels=4, seq0=0, t0=0, dt_us=10_000):
    out = []
    for k in range(n):
        counts = [k * 7 - 3 * w for w in range(n_wheels)]
        out.append(
            (
                encode_sensor_frame(seq0 + k, t0 + k * dt_us, counts, (k * 13) % 3600 - 1800, k - 50),
                (seq0 + k) % 65536,
                tuple(counts),
            )
        )
    return out


@pytest.mark.parametrize("n_wheels", [2, 4])
def test_roundtrip_byte_by_byte(n_wheels):
    fr = _frames(20, n_wheels)
    data = b"".join(f for f, _, _ in fr)
    p = FrameParser()
    got = []
    for b in data:
        got += p.feed(bytes([b]))
    assert [g.seq for g in got] == [s for _, s, _ in fr]
    assert [g.counts for g in got] == [c for _, _, c in fr]
    assert got[3].heading_ddeg == (3 * 13) % 3600 - 1800 and got[3].gyro_cdps == 3 - 50
    assert p.stats.frames_ok == 20 and p.stats.crc_errors == 0 and p.stats.garbage_bytes == 0


def test_resync_after_garbage_and_bad_crc():
    fr = _frames(3)
    bad = bytearray(fr[1][0])
    bad[15] ^= 0xFF  # payload byte -> CRC error
    data = b"\x00\xa5\x13garbage" + fr[0][0] + bytes(bad) + b"\xa5" + fr[2][0]
    p = FrameParser()
    got = p.feed(data)
    assert [g.seq for g in got] == [0, 2]
    assert p.stats.crc_errors == 1
    assert p.stats.bytes_in == p.stats.frame_bytes_ok + p.stats.garbage_bytes + p.pending
    assert p.stats.dropped == 1  # seq 1 never arrived intact


def test_bad_length_rejected():
    p = FrameParser()
    got = p.feed(SYNC + bytes([200, 1]) + b"\x00" * 20 + _frames(1)[0][0])
    assert len(got) == 1 and p.stats.length_errors == 1


def test_sequence_and_timestamp_wrap():
    fr = _frames(10, seq0=65530, t0=(1 << 32) - 35_000, dt_us=10_000)
    p = FrameParser()
    got = p.feed(b"".join(f for f, _, _ in fr))
    assert [g.seq for g in got] == [(65530 + k) % 65536 for k in range(10)]
    assert p.stats.dropped == 0 and p.stats.seq_wraps == 1 and p.stats.time_wraps == 1
    # unwrapped time strictly increases by 10 ms
    t = [g.t_us_unwrapped for g in got]
    assert all(b - a == 10_000 for a, b in zip(t, t[1:], strict=False))


def test_drops_counted_from_gaps_and_reset_detected():
    fr = _frames(10)
    keep = [fr[i][0] for i in (0, 1, 4, 5, 9)]
    p = FrameParser()
    p.feed(b"".join(keep))
    assert p.stats.dropped == 2 + 3
    # MCU reboot: sequence jumps back to 0
    got = p.feed(_frames(2)[0][0])
    assert got[0].reset and p.stats.seq_resets == 1 and p.stats.dropped == 5


def test_fuzz_100k_bytes_every_valid_frame_parsed_every_bad_one_counted():
    rng = random.Random(1234)
    stream = bytearray()
    sent = []
    n_corrupt = 0
    seq = 0
    while len(stream) < 100_000:
        r = rng.random()
        if r < 0.55:
            counts = [rng.randint(-(2**31), 2**31 - 1) for _ in range(rng.choice((2, 4)))]
            f = encode_sensor_frame(seq, rng.randint(0, 2**32 - 1), counts, rng.randint(-1800, 1799))
            stream += f
            sent.append((seq, tuple(counts)))
        elif r < 0.75:
            f = bytearray(encode_sensor_frame(seq, 5, [1, 2, 3, 4], 0))
            k = rng.randint(4, len(f) - 1)  # corrupt anything after sync+len: always a CRC error
            f[k] ^= rng.randint(1, 255)
            stream += f
            n_corrupt += 1
        elif r < 0.85:
            f = encode_sensor_frame(seq, 5, [1, 2, 3, 4], 0)
            stream += f[: rng.randint(2, len(f) - 1)]  # truncated frame (sync kept)
            n_corrupt += 1
        else:
            # random noise, without the sync pattern so the bookkeeping below is exact
            noise = bytes(rng.randint(0, 255) for _ in range(rng.randint(1, 60))).replace(b"\xa5", b"\x00")
            stream += noise
            continue
        seq = (seq + 1) % 65536
    p = FrameParser()
    got = []
    pos = 0
    while pos < len(stream):
        n = rng.randint(1, 700)
        got += p.feed(bytes(stream[pos : pos + n]))
        pos += n
    s = p.stats
    assert [(g.seq, g.counts) for g in got] == sent  # every valid frame, in order, intact
    assert s.bytes_in == len(stream) >= 100_000
    assert s.frame_bytes_ok + s.garbage_bytes + p.pending == s.bytes_in
    # every corrupt or truncated frame is rejected and counted (a truncated frame followed by
    # the next frame's bytes fails its CRC or length check)
    assert s.crc_errors + s.length_errors == n_corrupt
    # sequence numbers of the frames that never arrived intact are counted as drops
    assert s.dropped == n_corrupt
    print(f"fuzz: {s.as_dict()} corrupt={n_corrupt} valid={len(sent)}")


def test_fuzz_pure_random_bytes_never_crash():
    rng = random.Random(7)
    data = bytes(rng.getrandbits(8) for _ in range(100_000))
    p = FrameParser()
    for i in range(0, len(data), 333):
        p.feed(data[i : i + 333])
    s = p.stats
    assert s.bytes_in == 100_000
    assert s.frame_bytes_ok + s.garbage_bytes + p.pending == s.bytes_in


# --------------------------------------------------------------------------- issue 12 item 13


def test_heading_outside_range_rejected_and_counted():
    """A CRC-valid frame whose heading is outside -1800..3599 (0.1 deg) keeps its counts but
    loses the heading, counted ``bad_heading``; the extremes of the range are accepted."""
    p = FrameParser()
    bad = [3600, -1801, 5000, 0x7FFE, -32768]
    good = [-1800, 0, 1799, 3599]
    data = b"".join(encode_sensor_frame(k, k * 10_000, [k, 2 * k], h) for k, h in enumerate(bad + good))
    got = p.feed(data)
    assert len(got) == len(bad) + len(good) and p.stats.bad_heading == len(bad)
    assert [g.heading_ddeg for g in got] == [None] * len(bad) + good
    assert not any(g.has_heading for g in got[: len(bad)]) and all(g.has_heading for g in got[len(bad):])
    assert [g.counts for g in got] == [(k, 2 * k) for k in range(len(got))]  # the counts still count


def test_mcu_clock_step_back_is_not_a_71_minute_wrap():
    """A 1 ms step back of the MCU clock is a backwards step (counted), not +2^32 us; a real
    wrap (u32 overflow) still unwraps forward."""
    p = FrameParser()
    t = [1_000_000, 1_010_000, 1_009_000, 1_019_000]
    got = p.feed(b"".join(encode_sensor_frame(k, tk, [0, 0], None) for k, tk in enumerate(t)))
    assert [g.t_us_unwrapped - got[0].t_us_unwrapped for g in got] == [0, 10_000, 9_000, 19_000]
    assert p.stats.time_backwards == 1 and p.stats.time_wraps == 0
    p2 = FrameParser()
    t2 = [(1 << 32) - 5_000, 5_000]
    got2 = p2.feed(b"".join(encode_sensor_frame(k, tk, [0, 0], None) for k, tk in enumerate(t2)))
    assert got2[1].t_us_unwrapped - got2[0].t_us_unwrapped == 10_000
    assert p2.stats.time_wraps == 1 and p2.stats.time_backwards == 0


def test_frame_cut_short_does_not_hold_back_the_next_frame():
    """Bytes lost mid-frame: the cut frame's length reaches into the next (complete) frame; that
    frame is delivered at once (it waited for later bytes to fail the cut one's CRC, and at the
    end of a stream it was never delivered)."""
    cut = encode_sensor_frame(0, 5, [1, 2, 3, 4], 0)[:7]  # 4 wheels: 34 bytes announced, 7 + 26 < 34
    whole = encode_sensor_frame(1, 10_005, [5, 6], 100)  # 2 wheels: 26 bytes
    p = FrameParser()
    got = p.feed(cut + whole)
    assert [g.seq for g in got] == [1] and p.stats.truncated == 1 and p.pending == 0
    assert p.stats.bytes_in == p.stats.frame_bytes_ok + p.stats.garbage_bytes
