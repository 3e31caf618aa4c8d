"""Gyro factor, odometry scales, sensor arbitration and latency: Jacobians, convergence, numbers."""
# ruff: noqa: B023

from __future__ import annotations

import math

import gtsam
import numpy as np
import pytest
from conftest import errors, make_synth

from fgloc.backends.factors import gyro_error, scaled_between_error, scaled_between_factor, scaled_delta
from fgloc.backends.health import ANGLE_ABSOLUTE, INSTANT_RATE, RATE, Arbiter, LatencyEstimator
from fgloc.backends.smoother import SlidingWindowSmoother, SmootherConfig
from fgloc.types import PoseFix


def _num(f, x0, retract, n, eps=1e-6):
    e0 = f(x0)
    J = np.zeros((len(e0), n))
    for k in range(n):
        d = np.zeros(n)
        d[k] = eps
        J[:, k] = (f(retract(x0, d)) - f(retract(x0, -d))) / (2 * eps)
    return J


def test_scaled_odometry_factor_jacobians_match_numerical_differentiation():  # noqa: B023 (lambdas used at once)
    rng = np.random.default_rng(0)
    rp = lambda p, d: p.retract(d)  # noqa: E731
    for _ in range(10):
        xi = gtsam.Pose2(*rng.normal(0, 1, 3))
        delta = np.array([0.08, 0.02, 0.4]) * rng.uniform(-1, 1, 3)
        xj = xi.compose(gtsam.Pose2(*delta))
        s = np.array([rng.uniform(0.8, 1.2), rng.uniform(1.0, 2.5)])
        meas = scaled_delta(delta, s)[0] + rng.normal(0, 0.01, 3)
        for bend in (True, False):  # False: the chord integrated along a gyro's heading
            _, (Hi, Hj, Hs) = scaled_between_error(xi, xj, s, meas, True, bend)
            Ni = _num(lambda p: scaled_between_error(p, xj, s, meas, False, bend)[0], xi, rp, 3)
            Nj = _num(lambda p: scaled_between_error(xi, p, s, meas, False, bend)[0], xj, rp, 3)
            Ns = _num(lambda v: scaled_between_error(xi, xj, v, meas, False, bend)[0], s, lambda v, d: v + d, 2)
            assert np.abs(Hi - Ni).max() < 1e-7 and np.abs(Hj - Nj).max() < 1e-7 and np.abs(Hs - Ns).max() < 1e-7
        _, (_, _, Hs) = scaled_between_error(xi, xj, s, meas)
    # the GTSAM factor (only the yaw-rate scale a variable) reports the same whitened Jacobians
    v = gtsam.Values()
    v.insert(1, xi)
    v.insert(2, xj)
    v.insert(3, np.array([s[1]]))
    f = scaled_between_factor(1, 2, None, 3, meas, np.eye(3) * 1e-4, fixed_scales=(float(s[0]), 1.0))
    A = f.linearize(v).jacobian()[0]
    assert A.shape == (3, 7)
    assert np.allclose(A[:, 6] * np.sqrt(1e-4 + 1e-8), Hs[:, 1], rtol=1e-3)


def test_scaled_delta_is_exact_for_a_constant_twist():
    from fgloc.geometry import exp

    u = np.array([0.8, 0.1, 0.7])
    T = 0.2
    reported = exp(u * T * np.array([1.05, 1.05, 2.0]))  # 5 % more speed, twice the turn
    true, _ = scaled_delta(reported, np.array([1 / 1.05, 0.5]))
    assert np.allclose(true, exp(u * T), atol=1e-12)


def test_gyro_factor_error_and_jacobians():
    from fgloc.backends.factors import gyro_factor

    v = gtsam.Values()
    v.insert(1, gtsam.Pose2(0.0, 0.0, 0.1))
    v.insert(2, gtsam.Pose2(1.0, 0.0, 0.4))
    v.insert(3, np.array([0.002]))
    f = gyro_factor(1, 2, 3, 0.31, 0.5, 0.01)
    e = gyro_error(0.1, 0.4, 0.002, 0.31, 0.5)
    assert e == pytest.approx(0.4 - 0.1 - (0.31 - 0.001))
    A, b = f.linearize(v).jacobian()
    assert np.allclose(A * 0.01, [[0, 0, -1, 0, 0, 1, 0.5]])
    assert -b[0] * 0.01 == pytest.approx(e)


def _turning_run(seconds=120.0, seed=0, scrub=(1.4, 2.5), wheel_gain=1.0):
    rng = np.random.default_rng(seed)
    dt = 0.01
    t = np.arange(0, seconds, dt)
    w = np.where((t % 20) < 3, 0.6 * np.sin(np.pi * (t % 20) / 3), 0.0)
    yaw = np.cumsum(w) * dt
    arb = Arbiter()
    arb.add_source("wheel", RATE, 0.05)
    arb.add_source("gyro", INSTANT_RATE, 0.01)
    arb.add_source("compass", ANGLE_ABSOLUTE, 0.02)
    arb.set_correction("wheel", gain=wheel_gain)
    for i, ti in enumerate(t):
        if i % 5 == 0:
            f = scrub[0] + (scrub[1] - scrub[0]) * min(abs(w[i]) / 0.6, 1.0)
            arb.add("wheel", ti, w[i] * f + rng.normal(0, 0.005), 0.02**2)
        arb.add("gyro", ti, w[i] + rng.normal(0, 0.005), 0.005**2)
        if i % 2 == 0:
            arb.add("compass", ti, yaw[i] + rng.normal(0, 0.008), 0.008**2)
        if i % 10 == 0:
            arb.update(ti)
    return arb


def test_arbiter_down_weights_the_yaw_source_the_other_two_disagree_with():
    arb = _turning_run()
    _, c_w = arb.noise("wheel")
    k_g, c_g = arb.noise("gyro")
    k_c, c_c = arb.noise("compass")
    assert c_w > 0.5  # scrub 1.4-2.5 uncorrected: the wheel's turns are ~100 % off
    assert c_g < 0.05 and c_c < 0.1  # the gyro and the compass agree with each other
    assert k_g <= 1.5 and k_c <= 1.5
    # a constant scrub, corrected by the yaw-rate scale the smoother estimates: consistent again
    assert _turning_run(scrub=(2.0, 2.0), wheel_gain=0.5).noise("wheel")[1] < 0.05
    assert _turning_run(scrub=(2.0, 2.0)).noise("wheel")[1] > 0.5


def test_arbiter_a_short_compass_step_barely_moves_its_weight():
    rng = np.random.default_rng(1)
    arb = Arbiter()
    arb.add_source("gyro", INSTANT_RATE, 0.01)
    arb.add_source("compass", ANGLE_ABSOLUTE, 0.02)
    arb.add_source("wheel", RATE, 0.05)
    for i, ti in enumerate(np.arange(0, 120, 0.01)):
        step = np.deg2rad(25.0) if 40 <= ti < 45 else 0.0  # +25 deg magnetic disturbance for 5 s
        arb.add("gyro", ti, rng.normal(0, 0.005), 0.005**2)
        arb.add("compass", ti, step + rng.normal(0, 0.008), 0.008**2)
        if i % 2 == 0:
            arb.add("wheel", ti, rng.normal(0, 0.01), 0.02**2)
        if i % 10 == 0:
            arb.update(ti)
    assert arb.noise("compass")[0] < 2.0


def test_latency_estimator_recovers_a_known_lag():
    rng = np.random.default_rng(2)
    est = LatencyEstimator()
    for _ in range(400):
        x = rng.normal(0, 0.3)  # change of yaw rate between two fixes
        r = 0.035 * x + rng.normal(0, 5e-4)
        est.add(x, r, (5e-4) ** 2, ref=rng.normal(0, 0.1), kind=0)
    d, s = est.estimate()
    assert d == pytest.approx(0.035, abs=0.001) and s < 0.001
    assert est.value() == pytest.approx(d)
    none = LatencyEstimator()
    for _ in range(400):
        x = rng.normal(0, 0.3)
        none.add(x, rng.normal(0, 5e-4), (5e-4) ** 2)
    assert none.value() == 0.0  # not significant: no correction


def test_latency_estimator_fits_its_newest_rows_as_its_buffer_grows_and_wraps():
    """A window of 64 rows fed 1000 pairs (its buffer grown, then its kept rows moved to the front many
    times) fits exactly what a fresh estimator fits on the last 64 pairs alone; the lag changes halfway,
    so rows from before the window would show."""
    rng = np.random.default_rng(7)
    rows = []
    for i in range(1000):
        x = rng.normal(0, 0.3)
        rows.append((x, (0.02 if i < 500 else 0.06) * x + rng.normal(0, 5e-4)))
    small = LatencyEstimator(max_rows=64)
    for x, r in rows:
        small.add(x, r, (5e-4) ** 2)
    fresh = LatencyEstimator()
    for x, r in rows[-64:]:
        fresh.add(x, r, (5e-4) ** 2)
    assert small.n == 1000 and small.estimate() == fresh.estimate()
    assert small.estimate()[0] == pytest.approx(0.06, abs=0.002)


def test_latency_estimator_refits_a_share_of_its_rows():
    """A long run asked every pair: the fit is redone after 25 new pairs or 2.5 % of the rows fitted,
    whichever is more (a refit reads every row: a fixed count made their cost quadratic in the log),
    and it still finds the lag."""
    rng = np.random.default_rng(4)
    est = LatencyEstimator()
    fits = 0
    last = None
    for _ in range(6000):
        x = rng.normal(0, 0.3)
        est.add(x, 0.02 * x + rng.normal(0, 5e-4), (5e-4) ** 2, ref=rng.normal(0, 0.1), kind=0)
        got = est.estimate()
        if got != last:
            fits += 1
            last = got
    # every pair up to min_pairs (50), then 25 pairs each up to 1000, 2.5 % after: 50 + 38 + ln 6 / ln 1.025
    # ~= 161 (a fixed 25: 288)
    assert 150 <= fits <= 170
    assert est.value() == pytest.approx(0.02, abs=5e-4)


def _feed_calibration(sm, s, yaw_scale, speed_scale, bias):
    rng = np.random.default_rng(3)
    sm.initialize(s.t_scan[0], s.fixes[0], np.eye(3) * 1e-4)
    tw = s.twist * np.array([speed_scale, speed_scale, yaw_scale])
    ev = [(t, 0, i) for i, t in enumerate(s.t_odo)] + [(t, 2, i) for i, t in enumerate(s.t_scan) if i > 0]
    t_g = np.arange(0.0, s.t_gt[-1], 0.01)
    w_true = np.interp(t_g, s.t_gt[1:], np.diff(np.unwrap(s.gt[:, 2])) / np.diff(s.t_gt))
    ev += [(t, 1, i) for i, t in enumerate(t_g)]
    ev.sort(key=lambda e: (e[0], -e[1]))
    for _, kind, i in ev:
        if kind == 0:
            sm.add_odometry(s.t_odo[i], tw[i], None)
        elif kind == 1:
            sm.add_gyro(t_g[i], w_true[i] + bias + rng.normal(0, 0.003), 0.003**2)
        else:
            sm.add_keyframe(s.t_scan[i], PoseFix(s.t_scan[i], s.fixes[i], np.diag([0.01, 0.01, 0.01]) ** 2))
    return sm.finish()


def test_smoother_scales_and_gyro_bias_converge_within_5_percent():
    s = make_synth(duration=40.0, noise=True, seed=4)
    sm = SlidingWindowSmoother(SmootherConfig(latency=False))
    tr = _feed_calibration(sm, s, yaw_scale=1.8, speed_scale=1.05, bias=0.002)
    sv, sw = sm.odom_scales()
    assert sv == pytest.approx(1.05, rel=0.05) and sw == pytest.approx(1.8, rel=0.05)
    assert sm.gyro_bias("imu") == pytest.approx(0.002, rel=0.05)
    assert errors(tr, s)[0] < 0.01


def test_ekf_yaw_scale_and_gyro_bias_converge_within_5_percent():
    from fgloc.backends.ekf import EKFConfig
    from fgloc.backends.ekf_backend import EKFBackend

    s = make_synth(duration=40.0, noise=True, seed=4)
    ekf = EKFBackend(EKFConfig(omni=True, latency=False))
    tr = _feed_calibration(ekf, s, yaw_scale=1.8, speed_scale=1.0, bias=0.002)
    assert ekf.odom_scales()[1] == pytest.approx(1.8, rel=0.05)
    # the bias from the fixes' headings beside the filter (GyroBias): 0.00204 after 40 s (0.00243
    # as an EKF state pulled by the wheels' yaw rate)
    assert ekf.gyro_bias() == pytest.approx(0.002, rel=0.05)
    assert errors(tr, s)[0] < 0.02


def test_ekf_becomes_omni_when_the_odometry_reports_lateral_velocity():
    from conftest import feed

    from fgloc.backends.ekf import EKFConfig
    from fgloc.backends.ekf_backend import EKFBackend

    s = make_synth(noise=True, seed=5, omni=True)  # vy = 0.2 sin(0.5 t)
    auto = EKFBackend(EKFConfig())  # omni: null
    e_auto = errors(feed(auto, s), s)[0]
    diff = EKFBackend(EKFConfig(omni=False))
    e_diff = errors(feed(diff, s), s)[0]
    assert auto.stats["omni"] and not diff.stats["omni"]
    assert e_auto < 0.5 * e_diff
    straight = make_synth(noise=False, seed=5, omni=False)
    plain = EKFBackend(EKFConfig())
    feed(plain, straight)
    assert not plain.stats["omni"]  # a diff drive stays in the paper's state


def test_ekf_yaw_scale_stays_positive_and_bounded_whatever_the_wheels_say():
    """Wheels whose yaw rate turns the other way than the gyro (a mirrored or miswired encoder):
    the EKF's yaw-rate scale (a state, as its logarithm) never leaves its physical range after any
    update (a linear scale state went to -0.41 through the gyro updates' correlations, clamped
    only after the encoder's), and a plain skid-steer scrub is still estimated."""
    from fgloc.backends.ekf import EKFConfig
    from fgloc.backends.ekf_backend import SCALE_MAX, SCALE_MIN, EKFBackend

    for wheel_gain, want in ((-1.5, None), (2.0, 2.0)):
        rng = np.random.default_rng(1)
        ekf = EKFBackend(EKFConfig(latency=False))
        ekf.initialize(0.0, np.zeros(3), np.eye(3) * 1e-4)
        seen = []
        for i in range(1, 6000):
            t = i * 0.01
            w = 0.6 * np.sin(t / 3.0)
            if i % 2 == 0:
                ekf.add_odometry(t, np.array([0.5, 0.0, wheel_gain * w + rng.normal(0, 0.02)]),
                                 np.diag([1e-4, 1e-4, 4e-4]))
            ekf.add_compass(t, None, np.nan, w + 0.002 + rng.normal(0, 0.003), 0.003**2)
            if i % 10 == 0:
                ekf.add_keyframe(t, None)
            seen.append(ekf.odom_scales()[1])
        assert SCALE_MIN - 1e-9 <= min(seen) and max(seen) <= SCALE_MAX + 1e-9
        if want is not None:
            assert ekf.odom_scales()[1] == pytest.approx(want, rel=0.05)


def test_gyro_factors_jacobians_match_numerical_differentiation():
    """The gyro's yaw-increment factors (with a bias variable, and with the bias known beside the
    graph: the smoother's default) against central differences of their own error."""
    from fgloc.backends.factors import gyro_factor, yaw_increment_factor

    rng = np.random.default_rng(3)
    for _ in range(5):
        xi, xj = gtsam.Pose2(*rng.normal(0, 1, 3)), gtsam.Pose2(*rng.normal(0, 1, 3))
        b = np.array([rng.normal(0, 0.01)])
        factors = ((gyro_factor(1, 2, 3, 0.31, 0.5, 0.01), (1, 2, 3)), (yaw_increment_factor(1, 2, 0.31, 0.01), (1, 2)))
        for f, keys in factors:
            v = gtsam.Values()
            v.insert(1, xi)
            v.insert(2, xj)
            if 3 in keys:
                v.insert(3, b)
            A = f.linearize(v).jacobian()[0] * 0.01  # unwhitened

            def err(vals: gtsam.Values) -> np.ndarray:
                return np.asarray(f.unwhitenedError(vals))

            cols = []
            for k in keys:
                n = 1 if k == 3 else 3
                for j in range(n):
                    d = np.zeros(n)
                    d[j] = 1e-6
                    vp, vm = gtsam.Values(v), gtsam.Values(v)
                    if k == 3:
                        vp.update(3, b + d)
                        vm.update(3, b - d)
                    else:
                        vp.update(k, v.atPose2(k).retract(d))
                        vm.update(k, v.atPose2(k).retract(-d))
                    cols.append((err(vp) - err(vm)) / 2e-6)
            # the yaw row (yaw_increment_factor is a BetweenFactorPose2 whose translation rows
            # have infinite sigmas: they weigh nothing, their whitened Jacobians are zero)
            assert A.shape[0] in (1, 3)
            assert np.abs(A[-1] - np.column_stack(cols)[-1]).max() < 1e-7
            assert not A[:-1].any()


def test_gyro_increment_variances_add_up_to_the_integral_of_shared_readings():
    """Keyframes (25 Hz) faster than the gyro (20 Hz): neighbouring intervals share readings, and
    the factors' variances must add up to the variance of the gyro's integral over them (each
    reading's error counted once, with its whole weight), not 2-3x less."""
    sm = SlidingWindowSmoother(SmootherConfig())
    sigma = 0.005
    ts = np.arange(0.0, 2.0, 0.05)
    for t in ts:
        sm.add_gyro(float(t), 0.1, sigma**2)
    # the integral of the linear interpolant: each interior reading weighs 0.05 s
    t0, t1 = 0.5, 1.5
    edges = np.arange(t0, t1 + 1e-9, 0.04)
    split = sum(sm._gyro_increment("imu.gyro", a, b)[1] for a, b in zip(edges[:-1], edges[1:], strict=True))
    whole_exact = sigma**2 * 0.05**2 * (t1 - t0) / 0.05
    assert split == pytest.approx(whole_exact, rel=0.05)
    d, _ = sm._gyro_increment("imu.gyro", t0, t1)
    assert d == pytest.approx(0.1 * (t1 - t0), abs=1e-12)
    # the arbiter's block variance: a reading inside the block is one error with its whole weight
    arb = Arbiter()
    arb.add_source("gyro", INSTANT_RATE, 0.01)
    for t in ts:
        arb.add("gyro", float(t), 0.1, sigma**2)
    inc, var = arb.increment("gyro", 0.51, 0.64)  # readings 0.55, 0.60 inside, 0.50 and 0.65 at the edges
    w = {0.50: 0.04 * 0.5 * (2 - 0.2 - 1.0), 0.55: 0.0, 0.60: 0.0, 0.65: 0.04 * 0.5 * 0.8}
    w[0.55] = 0.04 - w[0.50] + 0.025
    w[0.60] = 0.025 + 0.04 - w[0.65]
    assert inc == pytest.approx(0.1 * 0.13, abs=1e-12)
    assert var == pytest.approx(sigma**2 * sum(v * v for v in w.values()), rel=1e-9)


def test_scalar_pose2_log_and_derivative_equal_gtsams():
    from fgloc.backends.factors import pose2_log_and_derivative

    rng = np.random.default_rng(3)
    for k in range(400):
        x, y = rng.normal(0, 0.5, 2)
        p = gtsam.Pose2(float(x), float(y), float(rng.normal(0, [1.0, 1e-3, 1e-7, 1e-12][k % 4])))
        v1, v2, w, rows = pose2_log_and_derivative(p.x(), p.y(), p.theta())
        assert np.allclose([v1, v2, w], gtsam.Pose2.Logmap(p), rtol=0, atol=1e-12)
        assert np.allclose(rows, gtsam.Pose2.LogmapDerivative(p)[:2], rtol=0, atol=1e-9)


def _hat_by_svd(names, pairs, prior, n_eff, unresolved):
    """The arbiter's per-source variances as numpy's least squares / pseudo-inverse give them
    (what cornered_hat computed before its scalar normal equations)."""
    from scipy.optimize import nnls as scipy_nnls

    srcs = sorted({s for p in pairs for s in p})
    out = {}
    groups = {s: {s} for s in srcs}
    for a, b in pairs:
        if groups[a] is not groups[b]:
            merged = groups[a] | groups[b]
            for s in merged:
                groups[s] = merged
    for members in {id(g): sorted(g) for g in groups.values()}.values():
        plist = [p for p in pairs if p[0] in members]
        A = np.array([[1.0 if s in p else 0.0 for s in members] for p in plist])
        y = np.array([pairs[p] for p in plist])
        sig = np.array([pairs[p] * np.sqrt(2.0 / max(n_eff.get(p, 1e9), 1.0)) for p in plist])
        v = np.full(len(members), np.nan)
        if np.linalg.matrix_rank(A) == len(members):
            v = scipy_nnls(A, y)[0]
            Ap = np.linalg.pinv(A)
            sd = np.sqrt(np.maximum(np.diag(Ap @ np.diag(sig**2) @ Ap.T), 0.0))
            v[sd > 0.5 * np.maximum(v, [prior.get(s, 0.0) for s in members])] = np.nan
        for m, s in enumerate(members):
            if np.isfinite(v[m]):
                val = v[m]
            elif unresolved == "prior":
                val = prior.get(s, 0.0)
            else:
                continue
            out[s] = max(min(val, min(pairs[p] for p in plist if s in p)), 0.0)
    return out


def test_cornered_hat_scalar_equals_least_squares():
    """The arbiter's scalar normal-equation solve gives what numpy's SVD least squares / pseudo-inverse
    and scipy's nnls give, on random pair sets of 2-5 sources (separable or not, with negative
    unconstrained solutions, resolved or not)."""
    from fgloc.backends.health import cornered_hat

    rng = np.random.default_rng(11)
    clipped = resolved = 0
    for _ in range(1500):
        m = int(rng.integers(2, 6))
        names = [f"s{i}" for i in range(m)]
        pairs = {(names[i], names[j]): float(rng.exponential(1.0) * 10 ** rng.uniform(-8, 0))
                 for i in range(m) for j in range(i + 1, m) if rng.random() < 0.7}
        if not pairs:
            continue
        n_eff = {p: float(rng.integers(1, 300)) for p in pairs if rng.random() < 0.9}
        prior = {n: float(rng.exponential(1.0) * 10 ** rng.uniform(-8, 0)) for n in names if rng.random() < 0.8}
        mode = "prior" if rng.random() < 0.5 else "omit"
        got = cornered_hat(names, pairs, prior, n_eff, mode)
        want = _hat_by_svd(names, pairs, prior, n_eff, mode)
        assert set(got) == set(want)
        scale = max(pairs.values())
        for s in got:
            assert got[s] == pytest.approx(want[s], rel=1e-9, abs=1e-12 * scale)
            clipped += got[s] == 0.0
            resolved += got[s] != prior.get(s, 0.0)
    assert clipped > 50 and resolved > 500  # both branches exercised


def test_compass_nearest_reading_in_and_out_of_stamp_order():
    from fgloc.backends.compass import CompassCalibrator

    for stamps in ([0.0, 0.05, 0.1, 0.1, 0.15], [0.0, 0.1, 0.05, 0.15, 0.2]):
        c = CompassCalibrator()
        for k, t in enumerate(stamps):
            c.add_compass(t, 0.1 * k, 0.0)
        for q in (0.075, 0.1, 0.125, 0.3, -0.2):  # the earliest of equally near readings, as min() over all
            best = min(range(len(stamps)), key=lambda i: abs(stamps[i] - q))
            expect = None if abs(stamps[best] - q) > c.max_dt else 0.1 * best
            got = c.compass_at(q)
            assert (got is None and expect is None) or got == pytest.approx(expect, abs=1e-12)


def _straight_run(heading_error, seconds=240.0, seed=3):
    """Gyro, wheels and a heading source (claimed 0.1 deg, its errors ``heading_error(t, rng)``) on
    a robot that mostly drives straight: the arbiter's view of the heading source."""
    rng = np.random.default_rng(seed)
    arb = Arbiter(long_blocks=(4, 16))
    arb.add_source("gyro", INSTANT_RATE, 0.01)
    arb.add_source("wheel", RATE, 0.05)
    arb.add_source("scan", ANGLE_ABSOLUTE, 0.005)
    dt = 0.01
    for i, ti in enumerate(np.arange(0, seconds, dt)):
        if i % 5 == 0:
            arb.add("gyro", ti, rng.normal(0, 0.005), 0.005**2)
        if i % 2 == 0:
            arb.add("wheel", ti, rng.normal(0, 0.005), 0.01**2)
        if i % 4 == 0:
            arb.add("scan", ti, heading_error(ti, rng), np.deg2rad(0.1) ** 2)
        if i % 10 == 0:
            arb.update(ti)
    return arb


def test_arbiter_shows_fixes_better_than_claimed_unless_their_errors_vary_slowly():
    white = _straight_run(lambda t, rng: rng.normal(0, np.deg2rad(0.01)))
    assert white.shown_k("scan") < 0.3  # 0.01 deg shown against 0.1 deg claimed
    assert white.noise("scan")[0] == 1.0  # noise() keeps an absolute source at its claim
    # the same white noise plus a 0.5 deg error varying over ~10 s (a map error along the way):
    # invisible over 0.125 s, shown over the 2 s blocks
    slow = _straight_run(lambda t, rng: rng.normal(0, np.deg2rad(0.01)) + np.deg2rad(0.5) * np.sin(0.6 * t))
    assert slow.shown_k("scan") > 1.0
    assert slow._var["scan"] < 0.3**2 * slow.streams["scan"].claimed_mean  # the short blocks alone: better


def _gyro_bias_run(distortion_deg, seconds=300.0, seed=4, window_s=2.0):
    from fgloc.backends.health import GyroBias

    rng = np.random.default_rng(seed)
    gb = GyroBias(window_s=window_s)
    bias = 0.002
    for i, ti in enumerate(np.arange(0, seconds, 0.01)):
        gb.add_rate(ti, bias + rng.normal(0, 0.005), 0.005**2)
        if i % 5 == 0:  # 20 Hz headings: 0.5 deg white, a distortion along a loop driven in 60 s
            ph = 2 * np.pi * ti / 60.0
            shape = 0.6 * np.sin(3 * ph) + 0.4 * np.cos(5 * ph)
            err = np.deg2rad(0.5) * rng.normal() + np.deg2rad(distortion_deg) * shape
            gb.add_heading("imu.yaw", ti, err, np.deg2rad(0.5) ** 2 + 0.5 * np.deg2rad(distortion_deg) ** 2)
    return gb


def test_gyro_bias_within_5_percent_beside_a_heading_with_slowly_varying_errors():
    # readings that share a slowly varying error count as fewer readings (variance inflation of
    # their innovations over 2 s windows): the distortion's slope is not taken for the bias
    err, err_indep = [], []
    for seed in (1, 2, 3):
        gb = _gyro_bias_run(1.0, seed=seed)
        assert gb.value() == pytest.approx(0.002, rel=0.05)
        assert gb._vif["imu.yaw"][6] > 3.0
        err.append(abs(gb.value() - 0.002))
        err_indep.append(abs(_gyro_bias_run(1.0, seed=seed, window_s=math.inf).value() - 0.002))
    assert sum(err) < 0.5 * sum(err_indep)  # every reading independent: 2.02-2.06 mrad/s
    white = _gyro_bias_run(0.0)
    assert white.value() == pytest.approx(0.002, rel=0.05)
    assert white._vif["imu.yaw"][6] < 1.6  # white readings count as they are


def test_scaled_odometry_factor_drift_jacobians_match_numerical_differentiation():  # noqa: B023
    rng = np.random.default_rng(1)
    rp = lambda p, d: p.retract(d)  # noqa: E731
    add = lambda v, d: v + d  # noqa: E731
    for _ in range(10):
        xi = gtsam.Pose2(*rng.normal(0, 1, 3))
        delta = np.array([0.08, 0.02, 0.4]) * rng.uniform(-1, 1, 3)
        xj = xi.compose(gtsam.Pose2(*delta))
        s = np.array([rng.uniform(0.8, 1.2), rng.uniform(1.0, 2.5)])
        dr = rng.normal(0, 0.05, 2)
        meas = scaled_delta(delta, s)[0] + rng.normal(0, 0.01, 3)
        for bend in (True, False):
            e, (Hi, Hj, Hs, Hd) = scaled_between_error(xi, xj, s, meas, True, bend, dr)
            assert not np.array_equal(e, scaled_between_error(xi, xj, s, meas, False, bend)[0])
            Ni = _num(lambda p: scaled_between_error(p, xj, s, meas, False, bend, dr)[0], xi, rp, 3)
            Nj = _num(lambda p: scaled_between_error(xi, p, s, meas, False, bend, dr)[0], xj, rp, 3)
            Ns = _num(lambda v: scaled_between_error(xi, xj, v, meas, False, bend, dr)[0], s, add, 2)
            Nd = _num(lambda v: scaled_between_error(xi, xj, s, meas, False, bend, v)[0], dr, add, 2)
            # (the log's derivative loses ~1e-7 near a zero residual turn: 1 - cos(w) of ~1e-8)
            for H, N in ((Hi, Ni), (Hj, Nj), (Hs, Ns), (Hd, Nd)):
                assert np.abs(H - N).max() < 1e-6
            # a zero drift is the factor without it, to the bit
            e0 = scaled_between_error(xi, xj, s, meas, True, bend)
            e1 = scaled_between_error(xi, xj, s, meas, True, bend, (0.0, 0.0))
            assert np.array_equal(e0[0], e1[0])
            assert all(np.array_equal(a, b) for a, b in zip(e0[1], e1[1][:3], strict=True))
    # the GTSAM factor with the drift a variable: its last two columns are Hd, whitened
    Hd = scaled_between_error(xi, xj, s, meas, True, True, dr)[1][3]
    v = gtsam.Values()
    v.insert(1, xi)
    v.insert(2, xj)
    v.insert(3, np.array([s[1]]))
    v.insert(4, dr)
    f = scaled_between_factor(1, 2, None, 3, meas, np.eye(3) * 1e-4, fixed_scales=(float(s[0]), 1.0), kd=4)
    A = f.linearize(v).jacobian()[0]
    assert A.shape == (3, 9)
    assert np.allclose(A[:, 7:] * np.sqrt(1e-4 + 1e-8), Hd, rtol=1e-3, atol=1e-9)


def _feed_drift(cfg, drift, omni=True):
    s = make_synth(duration=20.0, noise=True, seed=4, omni=omni)
    sm = SlidingWindowSmoother(cfg)
    rng = np.random.default_rng(3)
    sm.initialize(s.t_scan[0], s.fixes[0], np.eye(3) * 1e-4)
    tw = s.twist.copy()
    if not omni:
        tw[:, 1] = 0.0   # a differential drive reports no sideways speed
    tw[:, 1] += drift[0] * tw[:, 0]   # a sideways creep and a turn per metre forward
    tw[:, 2] += drift[1] * tw[:, 0]
    ev = [(t, 0, i) for i, t in enumerate(s.t_odo)] + [(t, 2, i) for i, t in enumerate(s.t_scan) if i > 0]
    ev.sort(key=lambda e: (e[0], -e[1]))
    for _, kind, i in ev:
        if kind == 0:
            sm.add_odometry(s.t_odo[i], tw[i], np.diag([1e-4, 1e-4, 1e-4]))
        else:
            sm.add_keyframe(s.t_scan[i], PoseFix(s.t_scan[i], s.fixes[i] + rng.normal(0, [0.01, 0.01, 0.005]),
                                                 np.diag([0.01, 0.01, 0.005]) ** 2))
    return sm, errors(sm.finish(), s)[0]


def test_smoother_estimates_the_odometry_drift_per_metre():
    """A mecanum base's unequal wheel radii: the odometry reports 2 cm sideways and -0.01 rad of turn per metre
    forward; the drift variable finds both, and the trajectory is better for it."""
    sm, err = _feed_drift(SmootherConfig(latency=False, odom_drift=True), (0.02, -0.01))
    ly, lw = sm.odom_drift()
    assert ly == pytest.approx(0.02, rel=0.1) and lw == pytest.approx(-0.01, rel=0.1)
    off, err_off = _feed_drift(SmootherConfig(latency=False, odom_drift=False), (0.02, -0.01))
    assert tuple(off.odom_drift()) == (0.0, 0.0)
    assert err < 0.9 * err_off


def test_smoother_drift_of_a_differential_drive_stays_near_zero():
    """A differential drive whose wheels are right: it reports no sideways speed, so no sideways drift is
    estimated; the turn per metre stays within its noise of 0 and costs the trajectory under 2 %."""
    sm, err = _feed_drift(SmootherConfig(latency=False, odom_drift=True), (0.0, 0.0), omni=False)
    ly, lw = sm.odom_drift()
    assert ly == 0.0 and abs(lw) < 3e-4
    _, err_off = _feed_drift(SmootherConfig(latency=False, odom_drift=False), (0.0, 0.0), omni=False)
    assert err < 1.02 * err_off
