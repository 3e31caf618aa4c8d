"""Smoother: a second odometry source (robot_localization's ``odom1``, a visual odometer beside the
wheels) is its own between-keyframe factor, gated against the keyframes' relative pose, its
translation's scale and yaw misalignment estimated (``aligned_between_factor``, whose Jacobians
are checked against central differences here)."""

from __future__ import annotations

import math

import gtsam
import numpy as np
import pytest

from fgloc.backends.factors import aligned_between_error
from fgloc.backends.smoother import SlidingWindowSmoother
from fgloc.localization import Localizer
from fgloc.localization.sources import SourceRouter, parse_sources
from fgloc.types import Imu, Odometry, StaticTransform

V, W = 1.0, 0.2


def numeric_jacobian(f, x: np.ndarray, eps: float = 1e-6) -> np.ndarray:
    cols = []
    for i in range(len(x)):
        dx = np.zeros(len(x))
        dx[i] = eps
        cols.append((f(x + dx) - f(x - dx)) / (2 * eps))
    return np.array(cols).T


def test_aligned_between_jacobians_match_central_differences():
    rng = np.random.default_rng(7)
    worst = 0.0
    for _ in range(100):
        xi = gtsam.Pose2(*rng.normal(0.0, 2.0, 3))
        xj = xi.compose(gtsam.Pose2(*rng.normal(0.0, 0.5, 3)))
        ab = np.array([1.0 + rng.normal(0.0, 0.2), rng.normal(0.0, 0.1)])
        m = rng.normal(0.0, 0.5, 3)
        e, (Hi, Hj, Hs) = aligned_between_error(xi, xj, ab, m)
        Ni = numeric_jacobian(lambda d, a=xi, b=xj, s=ab, z=m: aligned_between_error(a.retract(d), b, s, z, False)[0],
                              np.zeros(3))
        Nj = numeric_jacobian(lambda d, a=xi, b=xj, s=ab, z=m: aligned_between_error(a, b.retract(d), s, z, False)[0],
                              np.zeros(3))
        Ns = numeric_jacobian(lambda d, a=xi, b=xj, s=ab, z=m: aligned_between_error(a, b, s + d, z, False)[0],
                              np.zeros(2))
        worst = max(worst, float(np.abs(Hi - Ni).max()), float(np.abs(Hj - Nj).max()), float(np.abs(Hs - Ns).max()))
    assert worst < 1e-6


def test_aligned_between_error_is_zero_for_the_motion_the_source_reports():
    """A source reporting 0.9 times the translation, turned by 3 deg: (a, b) = 0.9 (cos, sin) 3 deg."""
    xi, rel = gtsam.Pose2(1.0, 2.0, 0.3), gtsam.Pose2(0.4, 0.05, 0.1)
    xj = xi.compose(rel)
    al = math.radians(3.0)
    ab = 0.9 * np.array([math.cos(al), math.sin(al)])
    t = 0.9 * np.array([[math.cos(al), -math.sin(al)], [math.sin(al), math.cos(al)]]) @ [0.4, 0.05]
    e, _ = aligned_between_error(xi, xj, ab, np.array([t[0], t[1], 0.1]), False)
    assert np.abs(e).max() < 1e-12


def _arc(specs: dict, visual, n: int = 400, outlier_at: int | None = None, gyro: bool = False
         ) -> tuple[np.ndarray, np.ndarray, Localizer]:
    """Wheels and a visual odometer at 20 Hz (and a gyro at 50 Hz) on a 0.2 rad/s arc at 1 m/s after
    1 s standing; ``visual(v, w)`` gives the visual twist.  Returns the smoother's last pose and the
    true pose at its stamp."""
    loc = Localizer(None, StaticTransform("base_link", "laser", np.zeros(3)), backend="smoother")
    sp = parse_sources(specs)
    router = SourceRouter(loc, sp)
    by = {s.topic: s for s in sp}
    msgs: list[tuple[float, str, object]] = []
    for k in range(1, n + 1):
        t = 0.05 * k
        v, w = (V, W) if t > 1.0 else (0.0, 0.0)
        msgs.append((t, "/wheels", Odometry(t, np.array([v, 0.0, 0.0]), np.diag([1e-4, 1e-4, 1e-4]))))
        vo = visual(v, w)
        if k == outlier_at:
            vo = np.array([vo[0], vo[1], 25.0])
        msgs.append((t + 0.001, "/vo", Odometry(t + 0.001, vo, np.diag([0.04, 0.04, 1e-4]))))
    if gyro:
        for k in range(1, int(n * 0.05 / 0.02) + 1):
            t = 0.02 * k + 0.0005
            msgs.append((t, "/gyro", Imu(t, None, np.array([0.0, 0.0, W if t > 1.0 else 0.0]), None,
                                         np.eye(3) * 1e-4, frame_id="base_link")))
    for _, topic, m in sorted(msgs, key=lambda m: m[0]):
        router.on_message(by[topic], m)
    traj = loc.finish()
    te = float(traj.stamps[-1]) - 1.0
    truth = np.array([V / W * math.sin(W * te), V / W * (1.0 - math.cos(W * te)), W * te])
    return np.asarray(traj.poses[-1], dtype=float), truth, loc


YAW_ONLY = {"wheels": {"type": "odometry", "topic": "/wheels", "use": ["vx"]},
            "visual": {"type": "odometry", "topic": "/vo", "use": ["vyaw"]},
            "imu0": {"type": "imu", "topic": "/gyro", "use": ["vyaw"]}}


def test_the_smoother_fuses_a_second_odometry_sources_yaw_rate():
    """The wheels give no yaw: the visual odometer's yaw rate turns the smoother 3.8 rad (it was
    skipped before: the smoother integrated one twist source)."""
    pose, truth, loc = _arc(YAW_ONLY, lambda v, w: np.array([v, 0.0, w]))
    be = loc.backend
    assert isinstance(be, SlidingWindowSmoother)
    assert be.source_health()["visual"].accepted >= 395 and be.source_health()["visual"].gated == 0
    assert be.stats["velocity_factors"] >= 150       # every keyframe interval (155 measured)
    assert abs(math.remainder(float(pose[2]) - truth[2], 2 * math.pi)) < 0.005   # 0.2 mrad measured
    assert float(np.hypot(*(pose[:2] - truth[:2]))) < 0.1                      # 0.049 m measured
    assert "alignment:visual" not in be.chains  # it reports no translation: nothing to align


def test_an_outlier_of_the_second_source_is_gated_against_the_gyro():
    """A 25 rad/s spike (a lost track) is gated against the keyframes' turn, which the gyro gives
    (with the wheels' unused yaw alone nothing could tell it from a turn: not gated then)."""
    pose, truth, loc = _arc(YAW_ONLY, lambda v, w: np.array([v, 0.0, w]), outlier_at=200, gyro=True)
    assert loc.backend.source_health()["visual"].gated >= 1         # 2 keyframe intervals hold it
    assert abs(math.remainder(float(pose[2]) - truth[2], 2 * math.pi)) < 0.005   # 1.6 mrad measured


ALIGN = {"wheels": {"type": "odometry", "topic": "/wheels", "use": ["vx", "vy"]},
         "visual": {"type": "odometry", "topic": "/vo", "use": ["vx", "vy", "vyaw"]}}
MIS_RAD, SCALE = math.radians(3.0), 0.9


def _misaligned(v: float, w: float) -> np.ndarray:
    """What a camera turned 3 deg on the base, its scale 0.9, reports."""
    return np.array([SCALE * math.cos(MIS_RAD) * v, SCALE * math.sin(MIS_RAD) * v, w])


@pytest.mark.parametrize("gains", [True, False])
def test_a_misaligned_visual_odometer_is_calibrated_against_the_wheels(gains: bool,
                                                                      monkeypatch: pytest.MonkeyPatch):
    """A visual odometer turned 3 deg with scale 0.9 beside wheels 20x more certain: its scale and
    yaw misalignment are estimated, so it does not drag the path sideways (without the estimate:
    0.085 m off after 29 m instead of 0.012 m)."""
    if not gains:
        orig = SlidingWindowSmoother.__init__

        def no_gains(self, config=None):
            from fgloc.backends.smoother import SmootherConfig
            orig(self, SmootherConfig(odom_gains=False))

        monkeypatch.setattr(SlidingWindowSmoother, "__init__", no_gains)
    pose, truth, loc = _arc(ALIGN, _misaligned, n=600)
    be = loc.backend
    err = float(np.hypot(*(pose[:2] - truth[:2])))
    if gains:
        ab = be.chains["alignment:visual"].estimate
        assert math.hypot(*ab) == pytest.approx(SCALE, abs=0.01)                     # 0.900 measured
        assert math.atan2(ab[1], ab[0]) == pytest.approx(MIS_RAD, abs=math.radians(0.5))  # 3.27 deg
        assert err < 0.03                                                             # 0.012 m measured
    else:
        assert err > 0.06                                                             # 0.085 m measured
