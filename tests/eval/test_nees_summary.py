"""nees_summary: the NEES of pose errors against their covariances, per axis, and what the worst carry."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fgloc.eval.metrics import nees_summary


def test_errors_of_one_sigma_on_each_axis():
    P = np.diag([4e-4, 1e-4, math.radians(0.5) ** 2])
    e = np.diag(np.sqrt(np.diag(P)))  # pose i: one sigma on axis i
    s = nees_summary(e, np.stack([P] * 3))
    assert s["n"] == 3
    assert s["nees_mean"] == pytest.approx(1.0) and s["nees_median"] == pytest.approx(1.0)
    assert (s["nees_x"], s["nees_y"], s["nees_yaw"]) == pytest.approx((1 / 3, 1 / 3, 1 / 3))
    assert s["rmse_m"] == pytest.approx(math.sqrt((4e-4 + 1e-4) / 3))
    assert s["rmse_deg"] == pytest.approx(0.5 / math.sqrt(3))
    assert s["sigma_xy_med_m"] == pytest.approx(math.sqrt(2.5e-4))
    assert s["sigma_yaw_med_deg"] == pytest.approx(0.5)


def test_correlated_covariance_counts_the_correlation():
    """2 cm along x and y where the axes are positively correlated: each axis alone is one sigma,
    the joint NEES 4/3 (the error lies along the covariance's long diagonal)."""
    P = np.array([[4e-4, 2e-4, 0.0], [2e-4, 4e-4, 0.0], [0.0, 0.0, 1e-4]])
    s = nees_summary(np.array([[0.02, 0.02, 0.0]]), P[None])
    assert s["nees_mean"] == pytest.approx(4 / 3)
    assert (s["nees_x"], s["nees_y"], s["nees_yaw"]) == pytest.approx((1.0, 1.0, 0.0))


def test_worst_share_says_when_a_few_fixes_set_the_mean():
    P = np.stack([np.eye(3) * 1e-4] * 21)
    e = np.zeros((21, 3))
    e[:, 0] = 0.01  # NEES 1 each
    e[7, 0] = 0.09  # one of 21: NEES 81
    s = nees_summary(e, P)
    assert s["nees_mean"] == pytest.approx(101 / 21)
    assert s["nees_median"] == pytest.approx(1.0)
    assert s["worst_share"] == pytest.approx(81 / 101)  # the worst 5 % of 21: one fix
    assert s["nees_trimmed"] == pytest.approx(1.0)  # the other 20


def test_chi_square_reference_values():
    """Honest covariances over many poses: mean 3, the worst 5 % carry ~17 % of the sum, the rest
    average ~2.63 (chi-square, 3 dof)."""
    rng = np.random.default_rng(0)
    L = np.array([[0.02, 0.0, 0.0], [0.01, 0.03, 0.0], [0.0, 0.002, 0.01]])
    P = L @ L.T
    e = rng.standard_normal((200_000, 3)) @ L.T
    s = nees_summary(e, np.broadcast_to(P, (len(e), 3, 3)))
    assert s["nees_mean"] == pytest.approx(3.0, abs=0.03)
    assert s["nees_median"] == pytest.approx(2.366, abs=0.03)
    assert s["worst_share"] == pytest.approx(0.167, abs=0.005)
    assert s["nees_trimmed"] == pytest.approx(2.631, abs=0.03)


def test_no_poses():
    assert nees_summary(np.zeros((0, 3)), np.zeros((0, 3, 3))) == {"n": 0}
