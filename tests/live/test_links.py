"""Serial link and laser client over real transports: pyserial loop://, pty, socket://, TCP."""

from __future__ import annotations

import math
import time

import numpy as np
import serial

from fgloc.live.serial_link import FrameConverter, RobotParams, SerialLink, twist_to_wheel_speeds
from fgloc.live.serial_protocol import encode_sensor_frame
from fgloc.live.sick import SickClient
from fgloc.testing.emulators import ReplayClock, SickEmulator, Stm32Emulator


def _wait(cond, timeout=10.0):
    t0 = time.monotonic()
    while not cond() and time.monotonic() - t0 < timeout:
        time.sleep(0.02)
    return cond()


def test_loop_url_counts_to_twist_diff_drive():
    robot = RobotParams(drive="diff", wheel_radius_m=0.1, track_width_m=0.5, counts_per_rev=1000)
    port = serial.serial_for_url("loop://", timeout=0.05)
    got = []
    link = SerialLink(None, FrameConverter(robot, align_clock=False), lambda k, m, a: got.append((k, m)),
                      port=port)
    link.start()
    twist = np.array([0.5, 0.0, 0.4])
    w = twist_to_wheel_speeds(robot, twist)  # rad/s
    for k in range(11):  # 100 Hz, cumulative counts starting near the int32 wrap
        c = [int(round(2**31 - 500 + wi * k * 0.01 * 1000 / (2 * math.pi))) for wi in w]
        port.write(encode_sensor_frame(k, 4_294_900_000 + k * 10_000, c, 450))
    assert _wait(lambda: len([1 for k, _ in got if k == "odom"]) == 10)
    link.stop()
    odo = [m for k, m in got if k == "odom"]
    tw = np.array([o.twist for o in odo])
    assert np.allclose(tw.mean(axis=0), twist, atol=0.015)  # one count over the 0.1 s window
    imu = [m for k, m in got if k == "imu"]
    assert len(imu) == 11 and math.isclose(imu[0].yaw_rad, math.radians(45.0))
    assert link.parser.stats.time_wraps == 1 and link.parser.stats.frames_ok == 11


def _check_replay(emu: Stm32Emulator, got, robot):
    src = [m for t, m in emu.msgs if t == "/odom"]
    odo = [m for k, m, _ in got if k == "odom"]
    st = np.array([emu.clock.to_run(o.stamp) for o in odo])
    srcst = np.array([m.stamp for m in src])
    i = np.clip(np.searchsorted(srcst, st - 2e-3), 0, len(src) - 1)
    # MCU clock (with its own offset and 40 ppm drift) mapped back to host time, as well as the
    # deliveries so far allow: a stamp can be no better than the fastest frame seen until then (a
    # loaded host that starves the reader at the start delays them all: 12 ms seen at load 13)
    arrival = np.array([a for k, _, a in got if k == "odom"])
    delay_run = (arrival - np.asarray(emu.clock.to_host(srcst[i]))) * emu.speed  # host s -> run s
    floor = np.maximum(np.minimum.accumulate(delay_run), 0.0)
    assert np.percentile(np.abs(st - srcst[i]) - floor, 95) < 0.003
    # the twist is the counts over the MCU's time since the previous intact odometry frame: compared with the
    # source of each frame by the emulator's record of the intact frames it wrote, in order (the stamps
    # above are no way to pair them while a loaded host delays the first deliveries)
    src_of = {k: j for j, k in enumerate(k for k, (t, _) in enumerate(emu.msgs) if t == "/odom")}
    intact = [src_of[k] for kind, k in emu.sent if kind == "odom"]
    assert len(odo) == len(intact) - 1  # one twist per intact frame after the first (the baseline)
    tw = np.array([o.twist for o in odo])
    ref = np.array([src[j].twist for j in intact[1:]]) * emu.speed  # replayed faster: host-time twist scales
    q = 2 * math.pi / robot.counts_per_rev * robot.wheel_radius_m * 50  # one count at 50 Hz, m/s
    assert np.max(np.abs(tw - ref)[:, :2]) < 2 * q


def test_pty_replay_with_corruption_counts_everything(synth):
    robot = RobotParams()
    emu = Stm32Emulator(synth, robot, mode="pty", speed=2.0, corrupt_prob=0.1, garbage_prob=0.1, seed=3)
    got = []
    link = SerialLink(emu.url, FrameConverter(robot), lambda k, m, a: got.append((k, m, a)))
    link.start()
    emu.start()
    assert emu.done.wait(10)
    st = link.parser.stats
    _wait(lambda: st.frames_ok + st.crc_errors >= emu.stats.frames)  # bytes still in the pty
    time.sleep(0.2)
    link.stop()
    emu.stop()
    s = link.parser.stats
    n = emu.stats.frames
    assert s.frames_ok + s.crc_errors >= n  # nothing lost on the pty
    assert s.frames_ok == n - emu.stats.corrupted
    assert s.crc_errors == emu.stats.corrupted  # every corrupted frame counted once
    # their sequence numbers show up as gaps (a corrupted last frame has no successor to reveal it)
    assert emu.stats.corrupted - 1 <= s.dropped <= emu.stats.corrupted
    assert s.garbage_bytes >= emu.stats.garbage_bytes
    _check_replay(emu, got, robot)


def test_socket_url_replay(synth):
    robot = RobotParams()
    emu = Stm32Emulator(synth, robot, mode="tcp", speed=2.0)
    got = []
    link = SerialLink(emu.url, FrameConverter(robot), lambda k, m, a: got.append((k, m, a)))
    assert emu.url.startswith("socket://127.0.0.1:")
    link.start()
    assert _wait(lambda: link.connected)  # pyserial connected before the replay starts (none of it lost)
    emu.clock = ReplayClock(emu.s0, time.time() + 0.2, emu.speed)
    emu.start()
    assert emu.done.wait(10)
    _wait(lambda: link.parser.stats.frames_ok >= emu.stats.frames)  # bytes still in the socket
    link.stop()
    emu.stop()
    assert link.parser.stats.frames_ok == emu.stats.frames
    assert link.parser.stats.crc_errors == 0
    _check_replay(emu, got, robot)


def test_sick_stream_reconnect_and_malformed(synth):
    emu = SickEmulator(synth, speed=1.0, malformed_prob=0.2, seed=1)
    scans = []
    cl = SickClient("127.0.0.1", emu.port, lambda s, a: scans.append((s, a)), range_min=0.5, stall_timeout_s=1.0)
    cl.start()
    emu.start()
    assert _wait(lambda: len(scans) >= 20)
    emu.drop_connection(refuse_s=0.5)
    n_before = len(scans)
    assert _wait(lambda: cl.stats.connects >= 2 and len(scans) > n_before + 10)
    assert emu.done.wait(10)
    _wait(lambda: cl.stats.scans >= emu.sent_scans and cl.stats.malformed >= emu.stats.malformed)
    cl.stop()
    emu.stop()
    assert cl.stats.disconnects >= 1 and cl.stats.connects >= 2
    assert cl.stats.scans == len(scans) == emu.sent_scans
    assert cl.stats.malformed == emu.stats.malformed > 0
    # ranges survive the trip (mm resolution), +inf stays +inf
    src = [m for t, m in synth if t == "/scan"]
    src_t = np.array([m.stamp for m in src])
    # device clock aligned to the host: the minimum-delay filter has seen 15 scans by then (the
    # first scans' estimate is as late as their delivery, 10 ms at a load average of 10)
    for s, _ in scans[15:20]:
        j = int(np.argmin(np.abs(src_t - emu.clock.to_run(s.stamp))))
        assert abs(src_t[j] - emu.clock.to_run(s.stamp)) < 0.005
        ref = src[j]
        fin = np.isfinite(ref.ranges)
        assert np.array_equal(fin, np.isfinite(s.ranges))
        assert np.max(np.abs(s.ranges[fin] - ref.ranges[fin])) < 0.001


def test_socket_url_reconnects_after_drop(synth):
    robot = RobotParams()
    emu = Stm32Emulator(synth, robot, mode="tcp", speed=1.0, start_host=time.time() + 0.5)
    got = []
    link = SerialLink(emu.url, FrameConverter(robot), lambda k, m, a: got.append((k, m, a)))
    link.start()
    emu.start()
    assert _wait(lambda: len(got) > 50)
    emu.drop_connection()
    n_before = len(got)
    assert _wait(lambda: link.opens >= 2 and len(got) > n_before + 50)
    assert emu.done.wait(10)
    # the last frame may still be in the socket when the emulator reports done: let it arrive
    st = link.parser.stats
    _wait(lambda: st.frames_ok + st.dropped >= emu.stats.frames)
    link.stop()
    emu.stop()
    assert link.disconnects >= 1 and link.opens >= 2
    assert link.parser.stats.crc_errors == 0
    # frames sent while nobody was connected are lost; the sequence gap says how many
    assert link.parser.stats.frames_ok + link.parser.stats.dropped == emu.stats.frames
