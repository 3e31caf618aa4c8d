"""A second odometry source (visual odometry beside the wheels, robot_localization's odom1): the
EKF fuses its used velocity components as measurements; a back-end without ``add_velocity``
(the smoother) counts its messages as skipped, with the reason."""

from __future__ import annotations

import math

import numpy as np
from conftest import without_capability

from fgloc.backends.contract import Capability
from fgloc.backends.ekf_backend import EKFBackend
from fgloc.backends.smoother import SlidingWindowSmoother
from fgloc.localization import Localizer
from fgloc.localization.sources import SourceRouter, parse_sources
from fgloc.types import Odometry, StaticTransform

SPECS = {
    "wheels": {"type": "odometry", "topic": "/wheels", "use": ["vx"]},       # no yaw from the wheels
    "visual": {"type": "odometry", "topic": "/vo", "use": ["vyaw"]},         # the yaw rate from the camera
}
V, W = 1.0, 0.2


def _run(specs: dict, outlier_at: int | None = None) -> tuple[np.ndarray, np.ndarray, Localizer, SourceRouter]:
    loc = Localizer(None, StaticTransform("base_link", "laser", np.zeros(3)), backend="ekf")
    sp = parse_sources(specs)
    router = SourceRouter(loc, sp)
    by = {s.topic: s for s in sp}
    cov = np.diag([1e-4, 1e-4, 1e-4])
    x = y = th = 0.0
    t0 = 1.0  # the localizer starts at the first odometry: standing still until t0
    for k in range(1, 401):
        t = 0.05 * k
        v, w = (V, W) if t > t0 else (0.0, 0.0)
        if t > t0:  # exact arc over 0.05 s
            x += v / w * (math.sin(th + w * 0.05) - math.sin(th))
            y += -v / w * (math.cos(th + w * 0.05) - math.cos(th))
            th += w * 0.05
        router.on_message(by["/wheels"], Odometry(t, np.array([v, 0.0, 0.0]), cov))
        vo = np.array([v, 0.0, 25.0 if k == outlier_at else w])
        router.on_message(by["/vo"], Odometry(t + 0.001, vo, cov))
    loc.finish()
    return loc.backend.current()[1], np.array([x, y, th]), loc, router


def test_the_ekf_fuses_a_second_odometry_sources_yaw_rate():
    pose, truth, loc, router = _run(SPECS)
    be = loc.backend
    assert isinstance(be, EKFBackend)
    assert be.source_health()["visual"].accepted >= 380 and be.source_health()["visual"].gated == 0
    assert abs(math.remainder(float(pose[2]) - truth[2], 2 * math.pi)) < 0.02   # 3.8 rad turned
    # 19 m driven; 0.094 m: the filter's yaw rate starts one message (0.05 s) after the turn
    assert float(np.hypot(*(pose[:2] - truth[:2]))) < 0.15
    h = router.health()
    assert h["visual"].accepted >= 395 and h["visual"].skipped == 0


def test_an_outlier_of_the_second_source_is_gated():
    pose, truth, loc, _ = _run(SPECS, outlier_at=200)
    assert loc.backend.source_health()["visual"].gated == 1
    assert abs(math.remainder(float(pose[2]) - truth[2], 2 * math.pi)) < 0.02


def test_a_backend_without_velocity_updates_skips_the_second_source_with_the_reason(monkeypatch):
    # both shipped back-ends take a second source (EKFBackend and, since the smoother-rl work,
    # SlidingWindowSmoother.add_velocity); a back-end without add_velocity must skip it, saying why
    without_capability(monkeypatch, SlidingWindowSmoother, Capability.VELOCITY)
    loc = Localizer(None, StaticTransform("base_link", "laser", np.zeros(3)), backend="smoother")
    sp = parse_sources(SPECS)
    router = SourceRouter(loc, sp)
    for k in range(1, 4):
        router.on_message(sp[1], Odometry(0.1 * k, np.array([1.0, 0.0, 0.2]), np.eye(3) * 1e-4))
    assert router.health()["visual"].skipped == 3
    (reason,) = loc.stats["skipped_reasons"]
    assert "second odometry source" in reason and "EKF fuses its velocities" in reason
