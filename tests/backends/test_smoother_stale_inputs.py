"""The smoother's prediction and factors where a sensor stream ends before the stamp asked for: a gyro
read at a lower rate than the odometry (or stopped), an odometry that stopped (a dead wheel driver)."""

from __future__ import annotations

import numpy as np
import pytest

from fgloc.backends.smoother import SlidingWindowSmoother
from fgloc.types import PoseFix

ODOM_COV = np.diag([1e-4, 1e-4, 1e-4])


def dead_reckon(gyro_until: float, span_s: float = 30.0, wheel_rate: float = 0.05, gyro_rate: float = 0.0):
    """A smoother started at the origin and fed ``span_s`` s of 50 Hz odometry (0.5 m/s, the wheels
    claiming ``wheel_rate`` rad/s) and a 20 Hz gyro (``gyro_rate``, stamps between the odometry's) until
    ``gyro_until``; no scan: its prediction to the last odometry stamp, and how long after the gyro's
    last reading that stamp is."""
    sm = SlidingWindowSmoother()
    sm.initialize(0.0, np.zeros(3))
    t_odo = np.arange(1, int(span_s * 50) + 1) * 0.02
    t_gyro = np.arange(0, int(span_s * 20)) * 0.05 - 0.037   # from before the start
    msgs = [(t, "odom") for t in t_odo] + [(t, "gyro") for t in t_gyro if t <= gyro_until]
    for t, kind in sorted(msgs):
        if kind == "odom":
            sm.add_odometry(float(t), np.array([0.5, 0.0, wheel_rate]), ODOM_COV)
        else:
            sm.add_gyro(float(t), gyro_rate, 1e-6)
    last_gyro = max(t for t, kind in msgs if kind == "gyro")
    return sm.predict(float(t_odo[-1]))[0], float(t_odo[-1] - last_gyro)


def test_dead_reckoning_turns_by_the_gyro_up_to_its_last_reading():
    # the newest odometry stamp is past the gyro's last reading (87 ms): the gyro still turns the
    # prediction up to there, the wheels (claiming 1.5 rad over the 30 s) only the rest
    pose, rest = dead_reckon(gyro_until=np.inf)
    assert 0.0 < rest < 0.1
    assert pose[2] == pytest.approx(0.05 * rest, abs=1e-6)
    assert pose[0] == pytest.approx(15.0, abs=1e-3) and abs(pose[1]) < 0.05   # the wheels: 9.3 m aside
    # a gyro that turns: its turn, not the wheels'
    pose, rest = dead_reckon(gyro_until=np.inf, gyro_rate=-0.02)
    assert pose[2] == pytest.approx(-0.02 * (30.0 - rest) + 0.05 * rest, abs=1e-6)


def test_dead_reckoning_after_a_gyro_stopped_follows_the_wheels():
    # the gyro stops at 20 s: its turn until then (0), the wheels' (0.05 rad/s) for the last 10 s
    pose, rest = dead_reckon(gyro_until=20.0)
    assert rest > 9.9 and pose[2] == pytest.approx(0.05 * rest, abs=1e-6)


def stopped_odometry(stop_s: float = 4.0, seed: int = 0):
    """A robot driving along x at 0.8 m/s, braking to a standstill from 5 s to 6 s and standing until
    10 s; its 50 Hz odometry (the truth) stops at ``stop_s``, while 10 Hz fixes (5 mm noise) go on and
    an IMU reads its (zero) yaw rate at 20 Hz.  The smoother's online poses and the truth there."""
    rng = np.random.default_rng(seed)

    def x_at(t: float) -> float:   # 0.8 m/s, then -0.8 m/s^2 from 5 s
        return 0.8 * t if t <= 5.0 else 4.0 + 0.8 * min(t - 5.0, 1.0) - 0.4 * min(t - 5.0, 1.0) ** 2

    def v_at(t: float) -> float:
        return 0.8 if t <= 5.0 else max(0.0, 0.8 - 0.8 * (t - 5.0))

    sm = SlidingWindowSmoother()
    sm.initialize(0.0, np.zeros(3), np.diag([1e-4, 1e-4, 1e-4]))
    msgs = [(t, "odom") for t in np.arange(1, 501) * 0.02 if t <= stop_s]
    msgs += [(t, "gyro") for t in np.arange(-1, 201) * 0.05 + 0.003]
    msgs += [(t, "scan") for t in np.arange(1, 100) * 0.1 + 0.011]
    for t, kind in sorted(msgs):
        t = float(t)
        if kind == "odom":
            sm.add_odometry(t, np.array([v_at(t), 0.0, 0.0]), ODOM_COV)
        elif kind == "gyro":
            sm.add_gyro(t, 0.0, 1e-6)
        else:
            pose = np.array([x_at(t) + rng.normal(0, 0.005), rng.normal(0, 0.005), 0.0])
            sm.add_keyframe(t, PoseFix(t, pose, np.diag([0.005**2, 0.005**2, 1e-4])))
    on = sm.online_trajectory()
    return on, np.array([x_at(float(t)) for t in on.stamps])


def test_stopped_odometry_leaves_the_pose_to_the_fixes():
    # the odometry stops at 4 s (a dead wheel driver): its last twist (0.8 m/s) is not integrated on over
    # the 6 s that follow, the robot stops where the fixes say (integrated on: 1.6 m on by 10 s)
    on, truth = stopped_odometry()
    err = np.hypot(on.poses[:, 0] - truth, on.poses[:, 1])
    late = on.stamps > 4.0
    assert late.sum() > 50
    assert float(err[late].max()) < 0.03 and float(np.sqrt(np.mean(err[late] ** 2))) < 0.01
    # the prediction's covariance says the motion is unmeasured: along the track it grows over a
    # second without fixes, across it (a wheeled base: no sideways speed) it stays the odometry's
    _, cov = stopped_prediction()
    assert cov[0, 0] > 100 * cov[1, 1]


def stopped_prediction():
    """The prediction to 5 s of a smoother whose odometry (0.8 m/s along x, with a fix every 0.1 s)
    stopped at 4 s."""
    sm = SlidingWindowSmoother()
    sm.initialize(0.0, np.zeros(3), np.diag([1e-4, 1e-4, 1e-4]))
    for t in np.arange(1, 201) * 0.02:
        sm.add_odometry(float(t), np.array([0.8, 0.0, 0.0]), ODOM_COV)
        if abs(t * 10 - round(t * 10)) < 1e-9:
            sm.add_keyframe(float(t) + 0.011, PoseFix(float(t) + 0.011, np.array([0.8 * t + 0.0088, 0.0, 0.0]),
                                                      np.diag([0.005**2, 0.005**2, 1e-4])))
    return sm.predict(5.0)


def test_a_bursty_odometry_is_not_taken_for_a_stopped_one():
    # a CARMEN logger's odometry: four poses within 3 ms, then nothing for 0.4 s (its own rhythm, no
    # gap): 0.35 s after a burst the prediction's along-track variance is the odometry's, not a
    # stopped odometry's
    sm = SlidingWindowSmoother()
    sm.initialize(0.0, np.zeros(3), np.diag([1e-4, 1e-4, 1e-4]))
    bursts = np.arange(1, 51) * 0.4
    for tb in bursts:
        for k in range(4):
            sm.add_odometry(float(tb + 0.001 * k), np.array([0.5, 0.0, 0.0]), ODOM_COV)
        t = float(tb) + 0.2
        sm.add_keyframe(t, PoseFix(t, np.array([0.5 * t, 0.0, 0.0]), np.diag([0.005**2, 0.005**2, 1e-4])))
    _, cov = sm.predict(float(bursts[-1]) + 0.35)
    _, cov_stopped = stopped_prediction()
    assert cov[0, 0] < 0.01 * cov_stopped[0, 0]
