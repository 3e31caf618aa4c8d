"""OdometryTracker on poses stamped late and in bursts (a CARMEN logger: tv = rv = 0, the twist
comes from the pose increments): what is integrated still meets every pose increment, and what
the odom pose is carried on with past the last message is a plausible velocity."""

from __future__ import annotations

import numpy as np

from fgloc.geometry import between, compose1
from fgloc.geometry import exp as se2_exp
from fgloc.geometry import log as se2_log
from fgloc.localization.config import PipelineConfig
from fgloc.localization.odometry import OdometryTracker

TRUE_TWIST = np.array([0.4, 0.0, 0.3])  # m/s, m/s, rad/s
PERIOD_S = 0.1


def _bursty(n_groups: int, per_group: int = 4, spread_s: float = 0.0004) -> tuple[np.ndarray, np.ndarray]:
    """Stamps and poses of a 10 Hz odometry whose logger stamps ``per_group`` readings at once
    (each group at its last reading's time, ``spread_s`` apart): 0.4 m/s, 0.3 rad/s."""
    stamps, poses = [], []
    pose = np.zeros(3)
    for k in range(n_groups * per_group):
        g_end = (k // per_group + 1) * per_group - 1  # the group's last reading
        stamps.append(g_end * PERIOD_S + (k % per_group) * spread_s)
        poses.append(pose.copy())
        pose = compose1(pose, se2_exp(TRUE_TWIST * PERIOD_S))
    return np.array(stamps), np.array(poses)


def test_bursts_integrate_exactly_and_extrapolate_plausibly() -> None:
    stamps, poses = _bursty(30)
    tr = OdometryTracker(PipelineConfig())
    integ = poses[0].copy()
    for i in range(len(stamps)):
        u = np.asarray(tr.step(float(stamps[i]), np.zeros(3), None, poses[i])[0])
        if i:
            # what a back-end integrates (each twist held over (t_prev, t]) meets every pose increment
            integ = compose1(integ, se2_exp(u * (stamps[i] - stamps[i - 1])))
        assert np.max(np.abs(se2_log(between(integ, poses[i])))) < 1e-9, i
        assert np.max(np.abs(se2_log(between(compose1(poses[0], tr.pose), poses[i])))) < 1e-9, i
        if i >= 8 and i % 4:
            # within a group: the twist held over 0.4 ms is ~100 m/s; the one extrapolated with is
            # the mean over the last poses >= the baseline apart (the group before's last one)
            v = tr.extrapolation_twist()
            assert float(np.hypot(v[0], v[1])) < 1.05 * TRUE_TWIST[0], (i, v)
            assert abs(float(v[2])) < 1.05 * TRUE_TWIST[2], (i, v)
            if i % 4 == 3:  # the group complete: the robot's velocity
                np.testing.assert_allclose(v, TRUE_TWIST, atol=0.01)
    assert tr.short_increments > 60
    assert float(tr.twist[0]) > 50.0  # the one integrated is the burst's


def test_pose_at_after_a_burst_is_near_the_truth() -> None:
    """A scan 20 ms after a group's last stamp: the odom pose carried there is within 1 cm of
    the truth (8 m off with the held 100 m/s burst twist)."""
    stamps, poses = _bursty(10)
    tr = OdometryTracker(PipelineConfig())
    for t, p in zip(stamps, poses, strict=True):
        tr.step(float(t), np.zeros(3), None, p)
    t_scan = float(stamps[-1]) + 0.02
    true_last_t = (len(stamps) - 1) * PERIOD_S  # the last reading's true time (its group's end)
    truth = compose1(poses[-1], se2_exp(TRUE_TWIST * (t_scan - true_last_t)))
    got = compose1(poses[0], tr.pose_at(t_scan))
    assert float(np.hypot(*(got[:2] - truth[:2]))) < 0.01
    held = compose1(poses[0], compose1(tr.pose, se2_exp(tr.twist * (t_scan - tr.t))))
    assert float(np.hypot(*(held[:2] - truth[:2]))) > 1.0


def test_evenly_stamped_poses_are_unchanged() -> None:
    """No burst (a steady 10 Hz with 30 % jitter): every twist is log(between) / dt and the odom
    pose is carried on with it, as before."""
    rng = np.random.default_rng(0)
    n = 60
    stamps = np.cumsum(PERIOD_S * (1.0 + 0.3 * rng.uniform(-1, 1, n)))
    poses = [np.zeros(3)]
    for i in range(1, n):
        poses.append(compose1(poses[-1], se2_exp(TRUE_TWIST * (stamps[i] - stamps[i - 1]))))
    tr = OdometryTracker(PipelineConfig())
    for i in range(n):
        u = np.asarray(tr.step(float(stamps[i]), np.zeros(3), None, poses[i])[0])
        if i:
            want = se2_log(between(poses[i - 1], poses[i])) / (stamps[i] - stamps[i - 1])
            np.testing.assert_allclose(u, want, atol=1e-12)
            assert tr.extrapolation_twist() is tr.twist
    assert tr.short_increments == 0


def test_extrapolation_after_a_logger_flush_is_plausible() -> None:
    """A logger that stalls for 2.5 s and then writes the 25 poses of that time within 11 ms, 0.1 and
    0.8 ms apart in turn (intel writes ~20 ODOM lines and 10 scans within 10 ms so): sixteen poses
    of the flush span 6.4 ms, the burst baseline is 0.23 ms and the mean velocity over it 89 m/s
    (at ae59b2f, which carried that to the next scan).  The velocity extrapolated with reaches back
    past the flush (half the 5 s mean period per increment): within 5 % of 0.4 m/s."""
    tr = OdometryTracker(PipelineConfig())
    k = 0
    for _ in range(60):  # 6 s of 10 Hz poses, on time
        tr.step(k * PERIOD_S, np.zeros(3), None, se2_exp(TRUE_TWIST * k * PERIOD_S))
        k += 1
    t = (k - 1) * PERIOD_S + 2.5
    for j in range(25):  # the stall's poses, written after it
        t += 0.0008 if j % 2 else 0.0001
        tr.step(t, np.zeros(3), None, se2_exp(TRUE_TWIST * k * PERIOD_S))
        k += 1
    assert tr.burst
    v = tr.extrapolation_twist()
    assert abs(float(np.hypot(v[0], v[1])) - TRUE_TWIST[0]) < 0.05 * TRUE_TWIST[0], v
    assert float(tr.twist[0]) > 50.0  # the increment integrated is the flush's (exact)
