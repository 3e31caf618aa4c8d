"""Factor Jacobians vs numerical differentiation; twist integration and its covariance."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from fgloc.backends.factors import body_covariance, compass_factor, fix_factor, offset_pose, pose_offset
from fgloc.backends.integration import integrate_twist
from fgloc.geometry import adjoint as se2_adjoint
from fgloc.geometry import exp as se2_exp


def _numerical_factor_jacobians(factor, values, keys, eps=1e-6):
    """Central differences of the whitened-free error through each key's retract."""
    out = []
    for k in keys:
        if gtsam.Symbol(k).chr() in (ord("x"), ord("o")):  # keyframes, compass offsets (Pose2 both)
            dim, at, ins = 3, values.atPose2, gtsam.Pose2
        else:
            dim, at, ins = 1, values.atRot2, gtsam.Rot2
        J = []
        for i in range(dim):
            d = np.zeros(dim)
            d[i] = eps
            vp, vm = gtsam.Values(values), gtsam.Values(values)
            vp.update(k, at(k).retract(d))
            vm.update(k, at(k).retract(-d))
            J.append((factor.unwhitenedError(vp) - factor.unwhitenedError(vm)) / (2 * eps))
        del ins
        out.append(np.array(J).T)
    return out


def test_compass_factor_jacobians_match_numerical():
    xk, ok = gtsam.symbol("x", 0), gtsam.symbol("o", 0)
    rng = np.random.default_rng(0)
    for _ in range(20):
        pose = gtsam.Pose2(*rng.uniform(-3, 3, 3))
        off = rng.uniform(-3, 3)
        z = rng.uniform(-np.pi, np.pi)
        f = compass_factor(xk, ok, z, 0.01, kernel="none")
        v = gtsam.Values()
        v.insert(xk, pose)
        v.insert(ok, offset_pose(off))
        assert pose_offset(v.atPose2(ok)) == pytest.approx(off)
        lin = f.linearize(v)
        A, b = lin.jacobian()
        assert list(f.keys()) == [ok, xk]
        Jn = np.hstack(_numerical_factor_jacobians(f, v, [ok, xk]))
        # the heading row (whitened by 1/sigma): [0, 0, -1] on the offset variable's heading (minus
        # the offset), [0, 0, 1] on the keyframe; the translation rows weigh nothing
        assert np.allclose(A[2] * 0.01, Jn[2], atol=1e-6)
        assert np.allclose(A[2] * 0.01, [0, 0, -1, 0, 0, 1], atol=1e-9)
        assert not A[:2].any()
        e = f.unwhitenedError(v)[2]
        assert -np.pi < e <= np.pi
        assert np.isclose(np.exp(1j * e), np.exp(1j * (pose.theta() + off - z)))


def test_fix_factor_uses_body_frame_covariance():
    pose = np.array([1.0, 2.0, np.pi / 2])
    cov = np.diag([0.04, 0.0001, 0.001])  # uncertain along map x
    cb = body_covariance(pose, cov)
    assert np.isclose(cb[1, 1], 0.04) and np.isclose(cb[0, 0], 0.0001)
    f = fix_factor(gtsam.symbol("x", 0), pose, cov, kernel="none")
    v = gtsam.Values()
    # 0.2 m off along map x == body -y: whitened error 0.2/0.2 = 1
    v.insert(gtsam.symbol("x", 0), gtsam.Pose2(1.2, 2.0, np.pi / 2))
    assert np.isclose(f.error(v), 0.5, atol=1e-6)


def test_twist_integration_exact_for_constant_twist():
    u = np.array([0.8, 0.1, 0.5])
    stamps = np.arange(0.02, 2.0001, 0.02)
    tw = np.tile(u, (len(stamps), 1))
    covs = np.zeros((len(stamps), 3, 3))
    d, c = integrate_twist(stamps, tw, covs, 0.0, 1.3)
    assert np.allclose(d, se2_exp(u * 1.3), atol=1e-12)
    assert np.allclose(c, 0.0)
    # matches gtsam's Expmap
    g = gtsam.Pose2.Expmap(u * 1.3)
    assert np.allclose(d, [g.x(), g.y(), g.theta()], atol=1e-12)


def test_adjoint_matches_gtsam():
    p = np.array([1.5, -0.4, 2.2])
    assert np.allclose(se2_adjoint(p), gtsam.Pose2(*p).AdjointMap())


def test_twist_covariance_matches_monte_carlo():
    rng = np.random.default_rng(3)
    stamps = np.arange(0.02, 1.0001, 0.02)
    n = len(stamps)
    u = np.column_stack([0.8 * np.ones(n), np.zeros(n), 0.6 * np.sin(stamps)])
    sig = np.array([0.05, 0.02, 0.05])
    covs = np.tile(np.diag(sig**2), (n, 1, 1))
    d0, c = integrate_twist(stamps, u, covs, 0.0, 1.0)
    samples = []
    zero = np.zeros((n, 3, 3))
    for _ in range(1500):
        un = u + rng.normal(0, sig, u.shape)
        d, _ = integrate_twist(stamps, un, zero, 0.0, 1.0)
        # error in the body tangent space at d0 (gtsam Local)
        e = gtsam.Pose2.Logmap(gtsam.Pose2(*d0).between(gtsam.Pose2(*d)))
        samples.append(e)
    emp = np.cov(np.array(samples).T)
    assert np.allclose(np.sqrt(np.diag(emp)), np.sqrt(np.diag(c)), rtol=0.1)
    corr = emp[1, 2] / np.sqrt(emp[1, 1] * emp[2, 2])
    corr_pred = c[1, 2] / np.sqrt(c[1, 1] * c[2, 2])
    assert abs(corr - corr_pred) < 0.08


def test_kernel_cache_bounded_when_the_scale_varies_per_factor():
    """A per-factor scale (the compass's) must not grow the shared kernel cache without bound, and a
    scale past the cache still gets its own kernel."""
    from fgloc.backends import factors as fx

    base = gtsam.noiseModel.Isotropic.Sigma(3, 0.1)
    for i in range(500):
        fx.robust(base, "cauchy", 1.0 + i * 1e-3)
    assert fx.kernels_cached() <= fx.KERNELS_KEPT
    m = fx.robust(base, "huber", 2.5).robust()      # past the cache: made for this factor
    assert m.weight(1.0) == pytest.approx(1.0)
    assert m.weight(5.0) == pytest.approx(2.5 / 5.0)


def test_rate_integral_resumed_from_its_mark_is_the_fresh_sum():
    """A gyro integral from the same start to later and later stamps, resumed from its mark, gives the
    fresh sum's exact float (the readings growing at the end and trimmed at the front meanwhile), and a
    gap beyond ``max_gap`` still gives None."""
    from bisect import bisect_right

    from fgloc.backends.integration import rate_integral

    rng = np.random.default_rng(3)
    ts = np.cumsum(rng.uniform(0.005, 0.015, 1000)).tolist()
    rs = rng.normal(0.0, 0.5, 1000).tolist()
    t0 = ts[10] + 0.0031
    mark: list[float] = []
    n = 200
    checked = 0
    for t1 in np.linspace(t0 + 0.001, ts[-1] - 0.01, 150).tolist():
        while n < len(ts) and ts[n - 1] < t1 + 0.05:
            n += 1
        view_t, view_r = ts[:n], rs[:n]
        i = max(bisect_right(view_t, t0) - 1, 0)
        fresh = rate_integral(view_t, view_r, t0, t1, i, 0.25)
        resumed = rate_integral(view_t, view_r, t0, t1, i, 0.25, mark=mark)
        assert resumed == fresh
        checked += 1
    assert checked == 150 and mark and mark[0] > ts[900]
    # an earlier end than the mark's: summed from the start, the same answer
    t1 = ts[100] + 0.002
    assert rate_integral(ts, rs, t0, t1, 10, 0.25, mark=mark) == rate_integral(ts, rs, t0, t1, 10, 0.25)
    # the readings before the mark trimmed (indices shift): resumed by the mark's stamp
    k = 5
    t1 = ts[-5]
    full = rate_integral(ts, rs, t0, t1, 10, 0.25)
    rate_integral(ts, rs, t0, ts[800], 10, 0.25, mark=mark)
    assert rate_integral(ts[k:], rs[k:], t0, t1, 10 - k, 0.25, mark=mark) == full
    # a gap after the mark: None, resumed or not
    gap_t = ts[:900] + [t + 1.0 for t in ts[900:]]
    assert rate_integral(gap_t, rs, t0, gap_t[-3], 10, 0.25, mark=mark) is None
    assert rate_integral(gap_t, rs, t0, gap_t[-3], 10, 0.25) is None
