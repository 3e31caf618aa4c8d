"""Serial frames -> odometry / compass: plausibility limits from the robot's top speed (issue 12 item 13)."""

from __future__ import annotations

import math

import numpy as np

from fgloc.live.serial_link import FrameConverter, RobotParams, twist_to_wheel_speeds
from fgloc.live.serial_protocol import FLAG_COUNTS, FLAG_GYRO, FLAG_HEADING, FrameParser, encode_sensor_frame

DT_US = 20_000  # 50 Hz


def _convert(robot, twist, n, jumps=None, gyro_cdps=None):
    """Frames of a robot at a constant twist; ``jumps[k]`` is added to wheel 0's count from frame k on
    (a one-frame glitch is ``{k: J, k + 1: -J}``)."""
    w = twist_to_wheel_speeds(robot, np.asarray(twist, dtype=float))
    data = b""
    offset = 0
    for k in range(n):
        offset += (jumps or {}).get(k, 0)
        counts = [int(round(wi * k * DT_US * 1e-6 * robot.counts_per_rev / (2 * math.pi))) for wi in w]
        counts[0] += offset
        flags = FLAG_COUNTS | (FLAG_HEADING | FLAG_GYRO if gyro_cdps is not None else 0)
        data += encode_sensor_frame(k, 5_000_000 + k * DT_US, counts, 100 if gyro_cdps else None, gyro_cdps,
                                    flags)
    conv = FrameConverter(robot, align_clock=False)
    out = []
    for k, f in enumerate(FrameParser().feed(data)):
        out += conv.convert(f, 1000.0 + k * DT_US * 1e-6)
    return conv, [m for kind, m in out if kind == "odom"], [m for kind, m in out if kind == "imu"]


def test_counter_jump_of_2_pow_31_rejected_and_covered_by_the_next_frame():
    robot = RobotParams()  # mecanum, max 2 m/s, 180 deg/s
    twist = [0.6, 0.1, 0.3]
    conv0, clean, _ = _convert(robot, twist, 30)
    conv, odo, _ = _convert(robot, twist, 30, jumps={12: 2**31, 13: -(2**31)})
    speeds = np.array([math.hypot(o.twist[0], o.twist[1]) for o in odo])
    assert speeds.max() < 0.7  # was 2.6e7 m/s
    assert conv.implausible_twist == 1 and conv.counts_rebased == 0 and conv0.implausible_twist == 0
    assert len(odo) == len(clean) - 1  # only the glitched frame is lost ...
    # ... and no motion: the next frame spans both intervals (cumulative counts)
    assert np.allclose(odo[-1].pose, clean[-1].pose, atol=1e-5)  # count rounding: ~3 um


def test_counter_reset_without_mcu_restart_rebaselines_after_three_rejections():
    robot = RobotParams(drive="diff", wheel_radius_m=0.1, track_width_m=0.5, counts_per_rev=1000)
    conv, odo, _ = _convert(robot, [0.5, 0.0, 0.2], 30, jumps={10: -1_000_000})
    assert conv.implausible_twist == 3 and conv.counts_rebased == 1
    assert len(odo) == 29 - 3  # the third rejected frame is the new baseline
    assert all(abs(o.twist[0] - 0.5) < 0.02 for o in odo)


def test_limits_come_from_the_configured_top_speed():
    slow = RobotParams.from_dict({"drive": "mecanum", "max_speed_mps": 0.5, "max_yaw_rate_dps": 30.0})
    conv, odo, _ = _convert(slow, [1.0, 0.0, 0.0], 10)  # 1 m/s > 1.5 x 0.5 m/s
    assert odo == [] and conv.implausible_twist == 9
    conv, odo, _ = _convert(slow, [0.7, 0.0, math.radians(40.0)], 10)  # within 1.5 x the limits
    assert len(odo) == 9 and conv.implausible_twist == 0
    conv, odo, _ = _convert(slow, [0.0, 0.0, math.radians(50.0)], 10)  # 50 deg/s > 45 deg/s
    assert odo == [] and conv.implausible_twist == 9


def test_gyro_rate_beyond_the_turn_limit_dropped_heading_kept():
    robot = RobotParams()  # 180 deg/s -> rates above 270 deg/s are implausible
    conv, _, imu = _convert(robot, [0.0, 0.0, 0.0], 5, gyro_cdps=30_000)  # 300 deg/s
    assert len(imu) == 5 and all(m.yaw_rate_radps is None for m in imu)
    assert all(math.isclose(m.yaw_rad, math.radians(10.0)) for m in imu)
    assert conv.implausible_rate == 5
    conv, _, imu = _convert(robot, [0.0, 0.0, 0.0], 5, gyro_cdps=-20_000)  # -200 deg/s: plausible
    assert conv.implausible_rate == 0 and math.isclose(imu[0].yaw_rate_radps, math.radians(-200.0))
