"""OdometryTracker: which twist is integrated when the odometry also carries poses (pose_deltas)."""

from __future__ import annotations

import numpy as np

from fgloc.geometry import compose1
from fgloc.geometry import exp as se2_exp
from fgloc.localization.config import PipelineConfig
from fgloc.localization.odometry import OdometryTracker
from fgloc.localization.sources import UNUSED_VAR


def _drive(tracker: OdometryTracker, twists: np.ndarray, true: np.ndarray, cov: np.ndarray,
           dt: float = 0.1, poses: bool = True) -> list[tuple[np.ndarray, np.ndarray]]:
    """Feed messages whose poses integrate ``true`` and whose twist is ``twists``."""
    pose = np.zeros(3)
    out = [tracker.step(0.0, twists[0], cov, pose.copy() if poses else np.zeros(3))]
    for i in range(1, len(twists)):
        pose = compose1(pose, se2_exp(true[i] * dt))
        out.append(tracker.step(i * dt, twists[i], cov, pose.copy() if poses else np.zeros(3)))
    return [(np.asarray(u), np.asarray(c)) for u, c in out]


def test_unused_yaw_is_not_taken_from_the_poses() -> None:
    """A source fusing vx, vy only (yaw variance UNUSED_VAR): its wheel yaw, in the poses, stays out."""
    n = 40
    true = np.tile([0.5, 0.0, 0.3], (n, 1))
    twists = true.copy()
    twists[:, 0] = 0.0  # the twist misses the forward speed: pose increments are used for vx
    cov = np.diag([1e-3, 1e-3, UNUSED_VAR])
    tr = OdometryTracker(PipelineConfig())
    out = _drive(tr, twists, true, cov)
    assert tr.from_poses > 30
    for u, c in out[1:]:
        assert c[2, 2] == UNUSED_VAR          # still unused
        assert u[2] == 0.0                    # handed on as 0: neither the poses' turn nor the message's
    assert abs(out[-1][0][0] - 0.5) < 0.02    # vx from the pose increments
    assert tr.twist[2] == 0.3                 # the front-ends' dead-reckoned pose keeps the message's turn


def test_unused_yaw_disagreement_does_not_replace_the_twist() -> None:
    """Only the used components take part in the agreement test."""
    n = 40
    true = np.tile([0.5, 0.0, 0.3], (n, 1))
    twists = true.copy()
    twists[:, 2] = 1.2  # a skid steer's wheel yaw, 4x the poses' (both from the wheels, both unused)
    tr = OdometryTracker(PipelineConfig())
    _drive(tr, twists, true, np.diag([1e-3, 1e-3, UNUSED_VAR]))
    assert tr.from_poses == 0
    tr = OdometryTracker(PipelineConfig())  # used: the poses win, as before
    _drive(tr, twists, true, np.diag([1e-3, 1e-3, 1e-3]))
    assert tr.from_poses > 30


def test_noisy_but_unbiased_twist_is_kept() -> None:
    """A twist 20 % off message by message but right on average agrees over the window: kept
    (r_l test1.bag's Husky: 3429 of 3952 twists were replaced message by message)."""
    n = 200
    true = np.tile([1.0, 0.0, 0.0], (n, 1))
    twists = true.copy()
    twists[:, 0] *= 1.0 + 0.2 * np.where(np.arange(n) % 2 == 0, 1.0, -1.0)
    tr = OdometryTracker(PipelineConfig())
    out = _drive(tr, twists, true, np.diag([1e-3, 1e-3, 1e-3]))
    assert tr.from_poses <= 2  # the first message's window is one message long
    assert out[-1][0][0] in (0.8, 1.2)


def test_missing_twist_is_replaced_by_the_pose_increments() -> None:
    """CARMEN: tv = rv = 0 while the poses move -> the pose increments' twist."""
    n = 40
    true = np.tile([0.4, 0.0, 0.2], (n, 1))
    tr = OdometryTracker(PipelineConfig())
    out = _drive(tr, np.zeros((n, 3)), true, np.diag([1e-3, 1e-3, 1e-3]))
    assert tr.from_poses == n - 1
    np.testing.assert_allclose(out[-1][0], [0.4, 0.0, 0.2], atol=1e-9)


def test_frozen_poses_keep_the_twist() -> None:
    """A driver that leaves the pose at zero (r_l test3.bag's AR.Drone): the twist, not zero motion."""
    n = 40
    true = np.tile([0.4, 0.1, 0.0], (n, 1))
    tr = OdometryTracker(PipelineConfig())
    out = _drive(tr, true, true, np.diag([1e-3, 1e-3, 1e-3]), poses=False)
    assert tr.from_poses == 0
    np.testing.assert_allclose(out[-1][0], [0.4, 0.1, 0.0])


def _stage_like(n: int = 300) -> np.ndarray:
    """10 Hz body twists: the speed and the turn rate change every second (a robot driven by waypoints)."""
    v = np.array([0.2, 0.5, 0.3, 0.6, 0.1])
    w = np.array([0.0, 0.5, -0.4, 0.0, 0.3, -0.2, 0.0])
    k = np.arange(n) // 10
    return np.c_[v[k % len(v)], np.zeros(n), w[k % len(w)]]


def _integrated(out: list[tuple[np.ndarray, np.ndarray]], dt: float = 0.1) -> np.ndarray:
    pose = np.zeros(3)
    for u, _ in out[1:]:
        pose = compose1(pose, se2_exp(u * dt))
    return pose


def test_a_twist_one_message_ahead_of_its_poses_gives_way_to_the_pose_increments() -> None:
    """Stage publishes with each pose the velocity of the step that follows it: the twist's
    increments match the pose increments one message later.  auto took the twist where the
    velocity held and the poses where it changed, counting a message's motion twice or not at all
    at each switch (Stage simpath2: an EKF + AMCL run 8 m RMSE off).  Once the shifted pairing fits
    far better over the run, the pose increments are taken: the path ends where the poses do."""
    true = _stage_like()
    truth = _integrated([(t, t) for t in true])
    for shift in (-1, 1):
        twists = np.roll(true, shift, axis=0)  # -1: message i carries the twist of step i + 1
        tr = OdometryTracker(PipelineConfig())
        out = _drive(tr, twists, true, np.diag([1e-3, 1e-3, 1e-3]))
        assert tr.offset.shift == shift
        assert tr.from_poses >= len(true) - 40
        assert float(np.hypot(*(_integrated(out)[:2] - truth[:2]))) < 0.02
        assert abs(_integrated(out)[2] - truth[2]) < 0.01
    # the same twists at their own stamps: kept (no shift found)
    tr = OdometryTracker(PipelineConfig())
    out = _drive(tr, true, true, np.diag([1e-3, 1e-3, 1e-3]))
    assert tr.offset.shift == 0 and tr.from_poses == 0
    np.testing.assert_allclose(_integrated(out), truth, atol=1e-9)
