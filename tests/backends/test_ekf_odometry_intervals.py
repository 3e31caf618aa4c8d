"""The EKF on odometry whose twist is the mean since the previous message (held backwards, as the
smoother integrates it): gaps of 1-2 s, 6 ms steps at 0.6 m/s, quantized pose-increment yaw rates.

A real e-puck's odometry (verlab/hero_common) reports exactly such twists; the EKF crossed each
interval with the previous message's velocity and ended 2.4 m off where the smoother ended 4 cm off.
"""

from __future__ import annotations

import math

import numpy as np

from fgloc.backends.ekf import EKF, MAX_PREDICT_STEP_S, EKFConfig, V, W
from fgloc.backends.ekf_backend import EKFBackend
from fgloc.geometry import compose1, wrap_scalar
from fgloc.geometry import exp as se2_exp


def _drive(be: EKFBackend, steps: list[tuple[float, float, float]], cov: np.ndarray,
           t0: float = 100.0) -> np.ndarray:
    """Feed ``(dt, v, w)`` intervals as held-back twists; returns the exactly integrated end pose."""
    be.initialize(t0, np.zeros(3), np.diag([1e-6, 1e-6, 1e-6]))
    be.add_odometry(t0, np.zeros(3), cov)
    pose, t = np.zeros(3), t0
    for dt, v, w in steps:
        t += dt
        pose = compose1(pose, se2_exp(np.array([v * dt, 0.0, w * dt])))
        be.add_odometry(t, np.array([v, 0.0, w]), cov)
    return pose


def _gappy_steps() -> list[tuple[float, float, float]]:
    """10 Hz messages with jitter, 6-35 ms steps at up to 0.67 m/s and 1-2 s gaps while turning
    (the pattern of the e-puck log's odometry)."""
    rng = np.random.default_rng(3)
    out: list[tuple[float, float, float]] = []
    for k in range(400):
        if k % 40 == 20:
            out.append((float(rng.uniform(1.0, 2.0)), float(rng.uniform(0.0, 0.12)), float(rng.uniform(-0.4, 0.4))))
        elif k % 13 == 5:
            out.append((float(rng.uniform(0.006, 0.035)), float(rng.uniform(0.3, 0.67)), 0.0))
        else:
            out.append((float(rng.uniform(0.03, 0.17)), float(rng.uniform(0.0, 0.1)), float(rng.uniform(-1.0, 1.0))))
    return out


def test_gappy_odometry_moves_the_ekf_by_its_increments() -> None:
    cov = np.diag([0.01**2, 0.01**2, 0.02**2])
    be = EKFBackend(EKFConfig())
    truth = _drive(be, _gappy_steps(), cov)
    got = be.current()
    assert got is not None
    err = float(np.hypot(*(got[1][:2] - truth[:2])))
    # measured at its stamp (the previous interval's velocity carried over each gap): 1.49 m, 54 deg
    assert err < 0.02, err
    assert abs(math.degrees(wrap_scalar(float(got[1][2] - truth[2])))) < 1.0


def test_paper_semantics_still_available() -> None:
    """``odom_held_back: false``: the twist measures the velocity at its stamp (the paper's EKF)."""
    cov = np.diag([0.01**2, 0.01**2, 0.02**2])
    be = EKFBackend(EKFConfig(odom_held_back=False))
    truth = _drive(be, _gappy_steps(), cov)
    got = be.current()
    assert got is not None
    assert float(np.hypot(*(got[1][:2] - truth[:2]))) > 0.2


def test_quantized_yaw_rates_integrate_whole() -> None:
    """Pose-derived yaw rates of a quantized heading (+-0.406 rad/s for one 21 ms step, 0 between)
    with a sigma growing with the rate: the sole odometry's turn is integrated whole, not shrunk
    by the filter's smoothing (measured at their stamps: 0.84 m, 10 deg off here; a HeRo's 2.4 m
    path ended 0.65 m off)."""
    be = EKFBackend(EKFConfig())
    steps, cov_of = [], []
    for k in range(2000):
        w = (0.406 if k % 3 == 0 else 0.0) if k < 1000 else (-0.406 if k % 4 == 0 else 0.0)
        steps.append((0.021, 0.06, w))
        s = 0.02 + 0.1 * (abs(w) + 0.06)
        cov_of.append(np.diag([(0.01 + 0.006) ** 2, 0.016**2, s * s]))
    t0 = 50.0
    be.initialize(t0, np.zeros(3), np.diag([1e-6, 1e-6, 1e-6]))
    pose, t = np.zeros(3), t0
    be.add_odometry(t, np.zeros(3), cov_of[0])
    for (dt, v, w), c in zip(steps, cov_of, strict=True):
        t += dt
        pose = compose1(pose, se2_exp(np.array([v * dt, 0.0, w * dt])))
        be.add_odometry(t, np.array([v, 0.0, w]), c)
    got = be.current()
    assert got is not None
    assert abs(math.degrees(wrap_scalar(float(got[1][2] - pose[2])))) < 0.5
    assert float(np.hypot(*(got[1][:2] - pose[:2]))) < 0.02


def test_long_prediction_follows_the_arc() -> None:
    """A 2 s prediction while turning 90 deg is integrated in steps (one Euler step went straight
    along the old heading: 0.29 m off the arc of a 0.2 m/s, 0.785 rad/s turn)."""
    ekf = EKF(EKFConfig())
    ekf.initialize(0.0, np.zeros(3))
    ekf.x[V], ekf.x[W] = 0.2, math.pi / 4
    ekf.predict(2.0)
    arc = se2_exp(np.array([0.4, 0.0, math.pi / 2]))
    n = math.ceil(2.0 / MAX_PREDICT_STEP_S)
    assert float(np.hypot(*(ekf.x[:2] - arc[:2]))) < 0.4 * (math.pi / 2) / n
    assert math.isclose(float(ekf.x[2]), math.pi / 2, abs_tol=1e-9)


def test_a_gap_in_the_odometry_while_a_gyro_carries_the_filter() -> None:
    """20 Hz odometry at 0.1 m/s, then no message for 1.55 s while the robot sped up to 0.3 m/s, a
    gyro at 100 Hz carrying the filter through the gap with the old velocity: the message after the
    gap moves the pose by the velocity's change over the part already crossed, and the velocity's
    random walk over the gap does not move it again (0.15 m too far when it did; 0.15 m short
    measured at its stamp)."""
    for held, lo, hi in ((True, -0.005, 0.005), (False, -0.2, -0.1)):
        be = EKFBackend(EKFConfig(odom_held_back=held))
        be.initialize(0.0, np.zeros(3), np.diag([1e-6, 1e-6, 1e-6]))
        stamps = [0.05 * k for k in range(40)] + [3.5] + [3.5 + 0.05 * k for k in range(1, 30)]
        events = sorted([(float(t), "odom") for t in stamps] + [(0.005 + 0.01 * k, "gyro") for k in range(500)])
        prev, truth = 0.0, 0.0
        for t, kind in events:
            if kind == "gyro":
                be.add_gyro(t, 0.0, 1e-6)
                continue
            inc = 0.1 * max(0.0, min(t, 2.0) - prev) + 0.3 * max(0.0, t - max(prev, 2.0))
            v = inc / (t - prev) if t > prev else 0.0
            truth, prev = truth + inc, t
            be.add_odometry(t, np.array([v, 0.0, 0.0]), np.diag([1e-4, 1e-4, 4e-4]))
        t_end = float(be.ekf.t or 0.0)
        want = truth + 0.3 * (t_end - prev)  # the last message's velocity carried to the filter time
        assert lo < float(be.ekf.x[0]) - want < hi, (held, float(be.ekf.x[0]), want)


def test_first_interval_after_the_start_is_not_lost() -> None:
    """The localizer starts the filter after the odometry's first messages (odom frame: at the second):
    the first message after the start is the mean twist since the one before it, and moves the start
    pose by that whole increment.  Slow odometry (0.64 s, a CARMEN log's laser-line poses) turning 0.7 rad
    per step: crossed with no velocity, the first interval turned the whole path by its turn (0.42 m off
    after 30 steps; 0.008 m now)."""
    cov = np.diag([0.01**2, 0.01**2, 0.02**2])
    be = EKFBackend(EKFConfig())
    dt, t = 0.64, 100.0
    be.add_odometry(t - dt, np.zeros(3), cov)   # before the start
    be.add_odometry(t, np.array([1.0, 0.0, 0.5]), cov)
    be.initialize(t, np.zeros(3), np.diag([1e-6, 1e-6, 1e-6]))
    rng = np.random.default_rng(4)
    pose = np.zeros(3)
    for _ in range(30):
        v, w = float(rng.uniform(0.8, 1.2)), float(rng.uniform(-1.1, 1.1))
        t += dt
        pose = compose1(pose, se2_exp(np.array([v * dt, 0.0, w * dt])))
        be.add_odometry(t, np.array([v, 0.0, w]), cov)
    got = be.current()
    assert got is not None
    err = float(np.hypot(*(got[1][:2] - pose[:2])))
    assert err < 0.1, err
    assert abs(math.degrees(wrap_scalar(float(got[1][2] - pose[2])))) < 0.5
