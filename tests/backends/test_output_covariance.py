"""The smoother's output covariance: never below the last fix it took, growing while it dead-reckons."""

from __future__ import annotations

import numpy as np
import pytest

from fgloc.backends.smoother.covariance import covariance_bound, timing_covariance

BLACKOUT = (2.0, 4.0)  # the laser silent from 2 s for 4 s
ROUTE = [[2.5, 3.0], [9.5, 3.0]]  # a 7 m leg of the paper's hall


def _spd(rng: np.random.Generator, scale: float) -> np.ndarray:
    a = rng.standard_normal((3, 3)) * scale
    return a @ a.T + np.eye(3) * 1e-6


def test_covariance_bound_holds_both_and_keeps_what_already_holds():
    rng = np.random.default_rng(0)
    for _ in range(50):
        p, q = _spd(rng, 0.1), _spd(rng, 0.1)
        b = covariance_bound(p, q)
        x = rng.standard_normal((200, 3))
        vb, vp, vq = (np.einsum("ni,ij,nj->n", x, m, x) for m in (b, p, q))
        assert np.all(vb >= vp * (1 - 1e-9)) and np.all(vb >= vq * (1 - 1e-9))
        assert np.allclose(b, b.T)
    p = np.diag([4e-4, 4e-4, 1e-4])
    assert np.array_equal(covariance_bound(p, p * 0.5), p)  # already larger: unchanged
    assert np.allclose(covariance_bound(p * 0.5, p), p)  # smaller in every direction: the other
    assert np.allclose(covariance_bound(np.zeros((3, 3)), p), p)  # not positive definite: the other


class _Fused:
    """The fused poses the session publishes (/fused_pose), with their covariances."""

    wants_fused = True
    wants_messages = False

    def __init__(self) -> None:
        self.t: list[float] = []
        self.cov: list[np.ndarray] = []

    def on_message(self, topic, msg) -> None:
        pass

    def on_scan(self, stamp, scan, fix_or_reason, fused) -> None:
        if fused is not None:
            self.t.append(float(fused.stamp))
            self.cov.append(np.asarray(fused.cov, dtype=float))

    def on_pose(self, stamp, fused) -> None:
        self.on_scan(stamp, None, "", fused)

    def close(self) -> None:
        pass


@pytest.fixture(scope="module")
def short_blackout():
    from fgloc.localization import build_session
    from fgloc.sim import run_scenario

    sim = run_scenario({"route": ROUTE, "faults": {"laser_blackout": {"start": BLACKOUT[0],
                                                                        "duration": BLACKOUT[1]}}}, seed=0)
    sink = _Fused()
    session = build_session(sim.map, sim.laser_mount, backend="smoother", initial_pose=sim.ground_truth.poses[0],
                            sinks=[sink])
    session.run(sim.messages)
    return sim, session.loc.online_trajectory(), session.loc, sink


def test_smoother_covariance_grows_while_dead_reckoning(short_blackout):
    _sim, online, _loc, _sink = short_blackout
    t0, t1 = BLACKOUT[0], BLACKOUT[0] + BLACKOUT[1]
    t = online.stamps
    var_xy = online.covs[:, 0, 0] + online.covs[:, 1, 1]
    var_yaw = online.covs[:, 2, 2]
    silent = (t > t0 + 1.2) & (t < t1 - 0.05)  # the dead-reckoned poses (every 0.1 s after a second of silence)
    assert np.count_nonzero(silent) > 20
    v, w = var_xy[silent], var_yaw[silent]
    assert np.all(np.diff(v) > 0) and np.all(np.diff(w) >= 0)
    before = float(np.median(var_xy[(t > t0 - 1.0) & (t < t0)]))
    assert v[-1] > 4.0 * before
    after = float(np.median(var_xy[(t > t1 + 1.0) & (t < t1 + 2.0)]))
    assert after < 0.25 * v[-1]  # the fixes take over again


def test_smoother_output_covariance_holds_its_fixes(short_blackout):
    """While it tracks, each online pose's covariance is at least what one fix says (the fixes' floors:
    ``smoother.fix_min_sigma_xy`` / ``fix_min_sigma_theta``); the marginal alone was below them
    (1.8 mm / 0.01 deg against 3 mm / 0.1 deg on the paper run)."""
    _sim, online, loc, sink = short_blackout
    cfg = loc.backend.cfg
    t = online.stamps
    tracking = (t > 0.5) & ((t < BLACKOUT[0]) | (t > BLACKOUT[0] + BLACKOUT[1] + 0.5))
    assert np.count_nonzero(tracking) > 50
    c = online.covs[tracking]
    assert np.all(c[:, 0, 0] >= 0.999 * cfg.fix_min_sigma_xy**2)
    assert np.all(c[:, 1, 1] >= 0.999 * cfg.fix_min_sigma_xy**2)
    assert np.all(c[:, 2, 2] >= 0.999 * cfg.fix_min_sigma_theta**2)
    # the published pose too
    ft = np.array(sink.t)
    fc = np.array(sink.cov)[(ft > 0.5) & ((ft < BLACKOUT[0]) | (ft > BLACKOUT[0] + BLACKOUT[1] + 0.5))]
    assert len(fc) > 50
    assert np.all(fc[:, 0, 0] >= 0.999 * cfg.fix_min_sigma_xy**2) and np.all(fc[:, 2, 2] >= 0.999 *
                                                                                cfg.fix_min_sigma_theta**2)


def test_timing_covariance_is_the_twist_read_off_in_time():
    # a pose read dt off while moving with twist u is off by u dt: var(dt) u u^T, u in the covariance's frame
    c = timing_covariance(0.01, np.array([1.0, 0.0, 0.5]), np.pi / 2)
    assert np.allclose(c, 0.01 * np.outer([0.0, 1.0, 0.5], [0.0, 1.0, 0.5]))
    assert np.allclose(timing_covariance(0.0, np.ones(3), 0.3), 0.0)


def _turn_online(odom_period_s: float, jitter: bool):
    """A smoother on a steady turn (0.5 m/s, 0.6 rad/s) with exact odometry every ``odom_period_s`` and
    exact fixes every 0.42 s (fr079's spacing): its online trajectory and its final one."""
    from fgloc.backends.smoother import SlidingWindowSmoother, SmootherConfig
    from fgloc.geometry import between1
    from fgloc.geometry import exp as se2_exp
    from fgloc.geometry import log as se2_log
    from fgloc.types import PoseFix

    def pose(t: float) -> np.ndarray:
        return se2_exp(np.array([0.5, 0.0, 0.6]) * t)

    sm = SlidingWindowSmoother(SmootherConfig(odom_timing_jitter=jitter))
    sm.initialize(0.0, pose(0.0), np.eye(3) * 1e-6)
    events = sorted([(float(t), 0) for t in np.arange(odom_period_s, 6.0, odom_period_s)]
                    + [(float(t), 1) for t in np.arange(0.42, 5.5, 0.42)])
    cov_odom = np.diag([0.06, 0.06, 0.1]) ** 2
    cov_fix = np.diag([0.02, 0.02, np.radians(1.0)]) ** 2
    for t, kind in events:
        if kind == 0:
            sm.add_odometry(t, se2_log(between1(pose(t - odom_period_s), pose(t))) / odom_period_s, cov_odom)
        else:
            sm.add_keyframe(t, PoseFix(t, pose(t), cov_fix))
    final = sm.finish()
    return sm.online_trajectory(), final


def test_a_slow_odometry_s_timing_widens_the_output_covariance_only():
    # 8 Hz odometry places its pose at a keyframe stamp to within its 0.125 s period: at 0.6 rad/s
    # and 0.5 m/s the output covariance is at least (0.125^2 / 12) * (0.6^2, 0.5^2) (1.2 deg, 1.0 cm)
    # and wider than without the term (there: the fixes' 1 deg, 2 cm); the estimate is the same
    on, fin_on = _turn_online(0.125, True)
    off, fin_off = _turn_online(0.125, False)
    assert np.array_equal(fin_on.poses, fin_off.poses) and np.array_equal(on.poses, off.poses)
    s2 = 0.125**2 / 12.0
    late = on.stamps > 1.0
    yaw_on, yaw_off = on.covs[late, 2, 2], off.covs[late, 2, 2]
    assert np.all(yaw_on >= 0.9 * s2 * 0.6**2) and np.all(yaw_on > 1.5 * yaw_off)
    pos_on, pos_off = np.trace(on.covs[late, :2, :2], axis1=1, axis2=2), np.trace(off.covs[late, :2, :2], axis1=1,
                                                                                  axis2=2)
    assert np.all(pos_on >= 0.9 * s2 * 0.5**2) and np.all(pos_on > 1.1 * pos_off)
    # 50 Hz odometry places it to 20 ms: no term
    fast_on, _ = _turn_online(0.02, True)
    fast_off, _ = _turn_online(0.02, False)
    assert np.array_equal(fast_on.covs, fast_off.covs)
