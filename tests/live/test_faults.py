"""A live session fed garbage mid-stream (issue 12): noise bytes with false sync patterns on the
serial link, noise and one negative-scale CoLa-A telegram on the laser's TCP stream.  Poses
keep coming after it, every fault is counted, and the recording holds every valid message sent."""

from __future__ import annotations

import math
import random

import numpy as np

from fgloc.config import load_config
from fgloc.io import open_log
from fgloc.live.app import LiveSession
from fgloc.live.serial_protocol import SYNC
from fgloc.live.sick import encode_lmdscandata, frame
from fgloc.localization import build_session
from fgloc.testing.emulators import EmulatorPair
from fgloc.types import CompassHeading, LaserScan, Odometry, StaticTransform

from .streams import synthetic_messages

INJECT_SCAN = 40  # of 100 scans (4 s at 25 Hz)


def _serial_garbage(rng: random.Random) -> bytes:
    """Noise with sync patterns and a plausible header whose CRC fails."""
    noise = bytes(rng.getrandbits(8) for _ in range(150))
    fake = SYNC + bytes([22, 1]) + bytes(rng.getrandbits(8) for _ in range(24))  # 4-wheel length, bad CRC
    return noise[:50] + SYNC + noise[50:100] + fake + noise[100:]


def _negative_scale_telegram(scan: LaserScan) -> bytes:
    tok = encode_lmdscandata(scan, 999, 999, 0, 1000).split(b" ")
    i = tok.index(b"DIST1") + 1
    tok[i] = b"-" + tok[i]  # the scale factor: int(..., 16) gave -1065353216 -> OverflowError
    return frame(b" ".join(tok))


def test_garbage_and_a_negative_scale_telegram_mid_stream(tmp_path):
    msgs = synthetic_messages(duration=4.0)
    cfg = load_config()
    rng = random.Random(5)
    scans_src = [m for t, m in msgs if t == "/scan"]
    laser_junk = b"\x00junk\xff" * 20 + _negative_scale_telegram(scans_src[0]) + b"\x03\x03 more junk "
    n_frames = sum(1 for t, _ in msgs if t in ("/odom", "/imu"))
    pair = EmulatorPair.create(msgs, cfg.robot, mode="pty", speed=1.0, lead_s=0.5,
                               stm32_kw={"inject": {k: _serial_garbage(rng) for k in (n_frames // 3, n_frames // 2)}},
                               sick_kw={"inject": {INJECT_SCAN: laser_junk}})
    session = build_session(None, StaticTransform("base_link", "laser", np.zeros(3)), backend="ekf")
    rec = tmp_path / "live.mcap"
    sess = LiveSession(session, pair.stm32.url, pair.sick.address, config=cfg, record=rec)
    sess.start()
    pair.start()
    r = sess.runner
    r.run(until=lambda: pair.stm32.done.is_set() and pair.sick.done.is_set())
    r.run(duration=0.3)
    summary = sess.close()
    pair.stop()
    c = summary.counters

    # the laser client survived the bad telegram: counted, and the stream went on
    assert sess.laser is not None and sess.laser.failure is None
    assert c["laser"]["malformed"] == 1 and c["laser"]["malformed_by_reason"] == {"bad_number": 1}
    assert c["laser"]["garbage_bytes"] >= 120 and c["laser"]["connects"] == 1
    assert pair.sick.sent == list(range(len(scans_src)))
    assert c["laser"]["scans"] == len(scans_src)
    # poses after the injection: one per scan fused (backlog skips aside)
    t_inject = float(pair.clock.to_host(scans_src[INJECT_SCAN].stamp))
    after = sum(1 for t in r.live_stamps if t > t_inject)
    assert after >= 0.8 * (len(scans_src) - INJECT_SCAN)
    # the serial garbage was skipped without losing a frame
    assert c["serial"]["frames_ok"] == len(pair.stm32.sent) == n_frames
    assert c["serial"]["dropped"] == 0 and c["serial"]["crc_errors"] + c["serial"]["length_errors"] >= 1
    assert c["serial"]["garbage_bytes"] >= pair.stm32.stats.garbage_bytes
    assert sess.serial is not None and sess.serial.failure is None

    # the recording holds every valid message sent, in order and intact
    got: dict[str, list] = {"/odom": [], "/imu": [], "/scan": []}
    for topic, m in open_log(rec).messages():
        if topic in got:
            got[topic].append(m)
    odom_src = [pair.stm32.msgs[i][1] for kind, i in pair.stm32.sent if kind == "odom"]
    imu_src = [pair.stm32.msgs[i][1] for kind, i in pair.stm32.sent if kind == "imu"]
    assert len(got["/scan"]) == len(scans_src)
    for m, src in zip(got["/scan"], scans_src, strict=True):
        fin = np.isfinite(src.ranges)
        assert np.array_equal(np.isfinite(m.ranges), fin)
        assert np.max(np.abs(m.ranges[fin] - src.ranges[fin])) < 0.001  # mm resolution on the wire
    assert len(got["/odom"]) == len(odom_src) - 1  # the first counts are the baseline
    assert all(isinstance(m, Odometry) for m in got["/odom"])
    robot = cfg.robot
    q = 2 * math.pi / robot.counts_per_rev * robot.wheel_radius_m / 0.02  # one count in 20 ms, m/s
    tw = np.array([m.twist for m in got["/odom"]])
    ref = np.array([m.twist for m in odom_src[1:]])
    assert np.max(np.abs(tw - ref)[:, :2]) < 2 * q
    assert len(got["/imu"]) == len(imu_src)
    for m, src in zip([i.heading() for i in got["/imu"]], imu_src, strict=True):  # readers give the whole Imu
        assert isinstance(m, CompassHeading)
        assert abs(math.remainder(m.yaw_rad - src.yaw_rad, 2 * math.pi)) < math.radians(0.06)
