"""Metrics: zero on identical input, known offsets, wrap-around, association, APE/RPE."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fgloc.eval.metrics import (
    AssociationError,
    Metrics,
    align_se2,
    associate,
    error_series,
    evaluate,
    pairs_by_distance,
    position_errors_and_steps,
    track_errors,
)
from fgloc.geometry import compose
from fgloc.types import Trajectory

from .helpers import rectangle, straight

COUNTS = {"n", "n_unassociated", "rpe_dist_pairs", "rpe_time_pairs"}
NOT_ERRORS = COUNTS | {"t_start_s", "t_end_s", "duration_s", "path_length_m", "aligned",
                       "rpe_dist_delta_m", "rpe_time_delta_s"}


def _shifted(gt: Trajectory, dx: float, dy: float, dyaw: float) -> Trajectory:
    p = gt.poses.copy()
    p[:, 0] += dx
    p[:, 1] += dy
    p[:, 2] += dyaw
    return Trajectory(gt.stamps, p)


@pytest.mark.parametrize("make", [rectangle, straight])
def test_identical_trajectories_give_exactly_zero(make):
    gt = make()
    m = evaluate(gt, gt)
    d = m.to_dict()
    errors = {k: v for k, v in d.items() if k not in NOT_ERRORS}
    assert len(errors) >= 30
    assert all(v == 0.0 for v in errors.values()), {k: v for k, v in errors.items() if v != 0.0}
    assert m.n == len(gt) and m.n_unassociated == 0
    assert m.rpe_dist_pairs > 0 and m.rpe_time_pairs > 0
    assert m.path_length_m == pytest.approx(gt.path_length())


def test_known_offset_on_straight_segment():
    theta, dx, dy, dyaw = np.radians(30.0), 0.03, -0.02, np.radians(2.5)
    gt = straight(theta)
    m = evaluate(_shifted(gt, dx, dy, dyaw), gt)
    tol = dict(abs=1e-12)
    assert m.position_rmse_m == pytest.approx(math.hypot(dx, dy), **tol)
    assert m.ape_rmse_m == pytest.approx(math.hypot(dx, dy), **tol)
    assert m.ape_std_m == pytest.approx(0.0, abs=1e-12)
    assert m.heading_rmse_deg == pytest.approx(2.5, abs=1e-9)
    assert m.max_abs_x_m == pytest.approx(abs(dx), **tol)
    assert m.max_abs_y_m == pytest.approx(abs(dy), **tol)
    assert m.max_abs_heading_deg == pytest.approx(2.5, abs=1e-9)
    along = dx * math.cos(theta) + dy * math.sin(theta)
    cross = -dx * math.sin(theta) + dy * math.cos(theta)
    s = error_series(_shifted(gt, dx, dy, dyaw), gt)
    np.testing.assert_allclose(s.along, along, atol=1e-12)
    np.testing.assert_allclose(s.cross, cross, atol=1e-12)
    assert m.along_rms_m == pytest.approx(abs(along), **tol)
    assert m.along_mean_abs_m == pytest.approx(abs(along), **tol)
    assert m.along_max_abs_m == pytest.approx(abs(along), **tol)
    assert m.cross_rms_m == pytest.approx(abs(cross), **tol)
    assert m.cross_mean_abs_m == pytest.approx(abs(cross), **tol)
    assert m.cross_max_abs_m == pytest.approx(abs(cross), **tol)
    assert m.position_p95_m == pytest.approx(math.hypot(dx, dy), **tol)
    assert m.heading_p95_deg == pytest.approx(2.5, abs=1e-9)


def test_position_only_offset_gives_zero_rpe():
    gt = rectangle()
    m = evaluate(_shifted(gt, 0.05, -0.03, 0.0), gt)
    assert m.position_rmse_m == pytest.approx(math.hypot(0.05, 0.03), abs=1e-12)
    assert m.rpe_dist_pairs >= 70
    assert m.rpe_dist_trans_max_m == pytest.approx(0.0, abs=1e-12)
    assert m.rpe_dist_rot_max_deg == pytest.approx(0.0, abs=1e-9)
    assert m.rpe_time_trans_max_m == pytest.approx(0.0, abs=1e-12)
    assert m.rpe_time_rot_max_deg == pytest.approx(0.0, abs=1e-9)


def test_rigid_offset_rpe_zero_and_alignment_recovers_it():
    gt = rectangle()
    tf = np.array([1.5, -0.7, np.radians(20.0)])
    est = Trajectory(gt.stamps, compose(tf, gt.poses))
    m = evaluate(est, gt)
    assert m.position_rmse_m > 1.0
    assert m.heading_rmse_deg == pytest.approx(20.0, abs=1e-9)
    assert m.rpe_dist_trans_max_m == pytest.approx(0.0, abs=1e-9)
    assert m.rpe_dist_rot_max_deg == pytest.approx(0.0, abs=1e-9)
    back = align_se2(est.poses[:, :2], gt.poses[:, :2])
    np.testing.assert_allclose(compose(back, tf), [0.0, 0.0, 0.0], atol=1e-9)
    ma = evaluate(est, gt, align=True)
    assert ma.aligned
    assert ma.position_rmse_m == pytest.approx(0.0, abs=1e-9)
    assert ma.heading_rmse_deg == pytest.approx(0.0, abs=1e-7)


def test_heading_wraps_around():
    t = np.arange(10) * 0.1
    gt = Trajectory(t, np.column_stack([t, 0 * t, np.full(10, np.radians(179.0))]))
    est = Trajectory(t, np.column_stack([t, 0 * t, np.full(10, np.radians(-179.0))]))
    m = evaluate(est, gt)
    assert m.heading_rmse_deg == pytest.approx(2.0, abs=1e-9)
    assert m.max_abs_heading_deg == pytest.approx(2.0, abs=1e-9)
    np.testing.assert_allclose(np.degrees(error_series(est, gt).eyaw), 2.0, atol=1e-9)  # est - ref, wrapped


def test_interpolation_at_other_rate_and_offset_times():
    # reference at 100 Hz on a curve with yaw crossing +-180 deg; estimate at 17 Hz, offset stamps,
    # lying exactly on the same (piecewise-linear) curve -> errors are interpolation-exact zero
    t = np.arange(0.0, 20.0 + 1e-9, 0.01)
    yaw = np.radians(150.0) + 0.1 * t  # passes +180 at t ~ 5.2 s
    gt = Trajectory(t, np.column_stack([2.0 * t, 0.5 * t + 1.0, yaw]))
    te = 0.0037 + np.arange(0, 19.9, 1 / 17.0)
    est = Trajectory(te, np.column_stack([2.0 * te, 0.5 * te + 1.0, np.radians(150.0) + 0.1 * te]))
    m = evaluate(est, gt)
    assert m.n == len(te)
    assert m.position_rmse_m == pytest.approx(0.0, abs=1e-9)
    assert m.heading_rmse_deg == pytest.approx(0.0, abs=1e-7)
    # shortest-arc yaw: halfway between 170 and -170 deg is 180, not 0
    g2 = Trajectory([0.0, 1.0], [[0, 0, np.radians(170.0)], [0, 0, np.radians(-170.0)]])
    a = associate(Trajectory([0.25, 0.5], [[0, 0, 0], [0, 0, 0]]), g2, max_gap=2.0)
    np.testing.assert_allclose(np.degrees(np.abs(a.gt[:, 2])), [175.0, 180.0], atol=1e-9)


def test_association_span_and_gaps():
    t = np.concatenate([np.arange(0.0, 5.0, 0.1), np.arange(8.0, 10.0 + 1e-9, 0.1)])  # a 3 s hole
    gt = Trajectory(t, np.column_stack([t, 0 * t, 0 * t]))
    te = np.arange(-1.0, 11.0, 0.25)  # starts before and ends after the reference
    est = Trajectory(te, np.column_stack([te, 0 * te, 0 * te]))
    a = associate(est, gt)  # default max_gap 0.5 s
    assert np.all((a.stamps >= 0.0) & (a.stamps <= 10.0))
    assert not np.any((a.stamps > 4.9 + 1e-9) & (a.stamps < 8.0 - 1e-9))
    inside = (te >= 0) & (te <= 10)
    in_hole = (te > 4.9 + 1e-9) & (te < 8.0 - 1e-9)
    assert len(a) == int(np.sum(inside & ~in_hole))
    m = evaluate(est, gt)
    assert m.n_unassociated == len(te) - len(a)
    assert len(associate(est, gt, max_gap=5.0)) == int(np.sum(inside))
    np.testing.assert_allclose(a.gt[:, 0], a.stamps, atol=1e-12)


def test_direction_of_travel_for_sideways_motion_and_standstill():
    # mecanum driving sideways: heading 90 deg off the direction of travel; along/cross use travel
    gt = straight(theta=0.0, heading=np.radians(90.0))
    s = error_series(_shifted(gt, 0.02, 0.01, 0.0), gt)
    np.testing.assert_allclose(s.along, 0.02, atol=1e-12)
    np.testing.assert_allclose(s.cross, 0.01, atol=1e-12)
    # standing still: the heading is the direction
    t = np.arange(100) * 0.01
    still = Trajectory(t, np.column_stack([0 * t + 3.0, 0 * t, np.full(100, np.radians(90.0))]))
    s2 = error_series(_shifted(still, 0.02, 0.01, 0.0), still)
    np.testing.assert_allclose(s2.along, 0.01, atol=1e-12)
    np.testing.assert_allclose(s2.cross, -0.02, atol=1e-12)


def test_ape_statistics_and_percentiles():
    t = np.arange(5.0)
    gt = Trajectory(t, np.zeros((5, 3)))
    off = np.array([0.0, 0.1, 0.2, 0.3, 0.9])
    est = Trajectory(t, np.column_stack([off, 0 * t, 0 * t]))
    m = evaluate(est, gt)
    assert m.ape_mean_m == pytest.approx(off.mean())
    assert m.ape_median_m == pytest.approx(0.2)
    assert m.ape_std_m == pytest.approx(off.std())
    assert m.ape_min_m == pytest.approx(0.0)
    assert m.ape_max_m == pytest.approx(0.9)
    assert m.ape_rmse_m == pytest.approx(math.sqrt(np.mean(off**2)))
    assert m.position_p95_m == pytest.approx(np.percentile(off, 95))
    # too short for any RPE pair: NaN in the dataclass, None in the dict
    assert m.rpe_dist_pairs == 0 and math.isnan(m.rpe_dist_trans_rmse_m)
    assert m.to_dict()["rpe_dist_trans_rmse_m"] is None


def test_rpe_distance_pairs_follow_the_reference_path():
    gt = straight(theta=0.0, speed=1.0, duration=10.0, rate=8.0)  # steps of exactly 0.125 m
    pairs = pairs_by_distance(gt.poses[:, :2], 1.0)
    assert len(pairs) == 10
    assert all(j - i == 8 for i, j in pairs)
    # a local error in one pose shows up in the two RPE pairs that use it, not elsewhere
    p = gt.poses.copy()
    p[40, 1] += 0.1
    m = evaluate(Trajectory(gt.stamps, p), gt)
    assert m.rpe_dist_trans_max_m == pytest.approx(0.1, abs=1e-12)
    assert m.rpe_dist_trans_rmse_m == pytest.approx(math.sqrt(2 * 0.01 / 10), abs=1e-12)


def test_bad_association_raises():
    gt = straight(t0=0.0)
    late = straight(t0=1000.0)
    with pytest.raises(AssociationError, match="do not overlap"):
        evaluate(late, gt)
    with pytest.raises(AssociationError, match="at least 2"):
        evaluate(Trajectory([1.0], [[0, 0, 0]]), gt)
    with pytest.raises(AssociationError):
        evaluate(gt, Trajectory([1.0], [[0, 0, 0]]))


def test_keys_are_documented_fields():
    m = evaluate(rectangle(), rectangle())
    assert list(m.to_dict()) == Metrics.keys()
    for k in ("position_rmse_m", "heading_rmse_deg", "max_abs_x_m", "max_abs_y_m", "max_abs_heading_deg",
              "along_rms_m", "cross_rms_m", "position_p95_m", "heading_p95_deg", "ape_rmse_m",
              "ape_median_m", "rpe_dist_trans_rmse_m", "rpe_time_rot_rmse_deg", "n", "duration_s"):
        assert k in Metrics.keys()


def test_position_errors_and_steps_show_a_jump_as_one_step():
    t = np.arange(0.0, 2.01, 0.1)
    gt = Trajectory(t, np.column_stack([t, 0 * t, 0 * t]))   # 1 m/s along x
    p = gt.poses.copy()
    p[10:, 1] += 0.3                                        # a 0.3 m jump sideways at t = 1 s
    err, step = position_errors_and_steps(Trajectory(t, p), gt)
    assert err.shape == (21,) and step.shape == (20,)
    assert np.allclose(err[:10], 0.0) and np.allclose(err[10:], 0.3)
    assert step.argmax() == 9 and step[9] == pytest.approx(0.3)
    assert np.allclose(np.delete(step, 9), 0.0)


def test_track_errors_split_along_and_across_the_reference_heading():
    # a robot heading north (+y): 3 cm ahead is +y, 2 cm to its left is -x; heading error wrapped
    ref = np.array([[1.0, 2.0, math.pi / 2], [0.0, 0.0, 0.0]])
    poses = np.array([[1.0 - 0.02, 2.0 + 0.03, math.pi / 2 + 0.01], [-0.01, 0.0, 2 * math.pi - 0.02]])
    along, cross, e = track_errors(poses, ref)
    np.testing.assert_allclose(along, [0.03, -0.01], atol=1e-12)
    np.testing.assert_allclose(cross, [0.02, 0.0], atol=1e-12)
    np.testing.assert_allclose(e[:, 2], [0.01, -0.02], atol=1e-12)
