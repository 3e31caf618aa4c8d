"""The smoother's prediction and factors where a sensor stream ends before the stamp asked for: a gyro
read at a lower rate than the odometry (or stopped), an odometry that stopped (a dead wheel driver)."""

from __future__ import annotations

import numpy as np
import pytest

from fgloc.backends.smoother import SlidingWindowSmoother

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
