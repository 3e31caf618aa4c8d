"""EKF: a differential orientation source (robot_localization's ``imuN_differential``) is fused
as a heading with its own offset state, so stamp jitter cannot turn its increments into rate
spikes that the gate drops; beside a gyro with a scale error it keeps the heading."""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fgloc.backends.ekf_backend import EKFBackend
from fgloc.localization import Localizer
from fgloc.localization.sources import SourceRouter, parse_sources
from fgloc.types import Imu, Odometry, StaticTransform, Transform3D

SPECS = {
    "odom0": {"type": "odometry", "topic": "/wheels", "use": ["x", "y"], "differential": True},
    "imu0": {"type": "imu", "topic": "/gyro", "use": ["vyaw"]},
    "imu1": {"type": "imu", "topic": "/ahrs", "use": ["yaw"], "differential": True},
}
GYRO_SCALE = 0.88        # the gyro reports 88 % of the turn (and claims a placeholder 1 (rad/s)^2)
AHRS_OFFSET = 1.3        # the AHRS's heading frame is 1.3 rad from the odom frame
DURATION_S, SPEED, START_S = 42.0, 1.0, 2.0   # standing still for START_S (the localizer starts)


def _w(t: float) -> float:
    """Yaw rate: 4 s turns of +-0.5 rad/s between 6 s straight stretches."""
    ph = (t - START_S) % 20.0 if t >= START_S else -1.0
    return 0.5 if 2.0 <= ph < 6.0 else (-0.5 if 12.0 <= ph < 16.0 else 0.0)


@lru_cache(maxsize=1)
def _messages(seed: int = 0) -> tuple[list[tuple[float, str, object]], np.ndarray]:
    """Truth by Euler steps of 1 ms; wheels 20 Hz (poses), gyro and AHRS 100 Hz, every 25th AHRS
    message stamped 0.2 ms after the one before (a driver's stamp jitter)."""
    rng = np.random.default_rng(seed)
    out: list[tuple[float, str, object]] = []
    x = y = th = 0.0
    dt = 0.001
    n = int(DURATION_S / dt)
    ahrs_i = 0
    for k in range(1, n + 1):
        t = k * dt
        w = _w(t)
        v = SPEED if t >= START_S else 0.0
        x += v * math.cos(th) * dt
        y += v * math.sin(th) * dt
        th += w * dt
        if k % 50 == 0:
            out.append((t, "/wheels", Odometry(t, np.array([v, 0.0, w]), np.diag([1e-4, 1e-4, 1e6]),
                                               np.array([x, y, th]), np.diag([1e-4, 1e-4, 1e6]))))
        if k % 10 == 0:
            g = GYRO_SCALE * w + rng.normal(0.0, 0.002)
            out.append((t, "/gyro", Imu(t, None, np.array([0.0, 0.0, g]), None, np.eye(3), frame_id="base_link")))
            ahrs_i += 1
            stamp = t - 0.0098 if ahrs_i % 25 == 0 else t
            q = Rotation.from_euler("z", th + AHRS_OFFSET + rng.normal(0.0, 0.0005)).as_quat()
            out.append((stamp, "/ahrs", Imu(stamp, q, None, np.eye(3) * 1e-4, None, frame_id="base_link")))
    out.sort(key=lambda m: m[0])
    return out, np.array([x, y, th])


def _run(msgs) -> tuple[np.ndarray, Localizer]:
    loc = Localizer(None, StaticTransform("base_link", "laser", np.zeros(3)), backend="ekf")
    specs = parse_sources(SPECS)
    router = SourceRouter(loc, specs)
    by_topic = {s.topic: s for s in specs}
    for _, topic, m in msgs:
        router.on_message(by_topic[topic], m)
    loc.finish()
    return loc.backend.ekf.pose(), loc


def test_a_differential_orientation_keeps_the_heading_beside_a_gyro_with_a_scale_error():
    msgs, truth = _messages(0)
    pose, loc = _run(msgs)
    be = loc.backend
    assert isinstance(be, EKFBackend)
    assert be.sources["imu1.yaw"].accepted > 4000 and be.sources["imu1.yaw"].gated == 0
    err = float(np.hypot(*(pose[:2] - truth[:2])))
    # 40 m driven, 8 rad turned (the gyro alone would lose 0.96 rad of heading on the way)
    assert err < 0.1, err
    assert abs(math.remainder(float(pose[2]) - truth[2], 2 * math.pi)) < 0.03


def test_without_the_heading_path_the_jittered_rates_lose_the_heading(monkeypatch: pytest.MonkeyPatch):
    """What the router did before (the increments as rates d_yaw / d_t): the same log ends
    metres off; the figure shows what the heading path fixes."""
    msgs, truth = _messages(0)
    monkeypatch.delattr(EKFBackend, "add_relative_yaw")
    pose, _ = _run(msgs)
    assert float(np.hypot(*(pose[:2] - truth[:2]))) > 1.0


def test_the_offset_is_reanchored_after_a_reinitialized_ahrs():
    """An AHRS that jumps by 2 rad (re-initialized) is gated, then re-anchored: the heading
    follows its increments again instead of being pulled 2 rad."""
    be = EKFBackend()
    be.initialize(0.0, np.zeros(3), np.diag([1e-4, 1e-4, 1e-4]))
    t = 0.0
    for k in range(1, 400):
        t = k * 0.01
        be.add_odometry(t, np.array([1.0, 0.0, 0.0]), np.diag([1e-4, 1e-4, 1e-4]))
        yaw = 0.5 + (2.0 if k >= 200 else 0.0)
        be.add_relative_yaw(t, yaw, 1e-4, "ahrs")
    assert be.stats.get("relative_yaw_reanchored", 0) == 1
    assert abs(float(be.ekf.x[2])) < 0.01


class _RelBackend:
    """A back-end that takes differential orientations as headings (records them)."""

    initialized = True
    encoder_sigmas = (0.01, 0.01, 0.02)

    def __init__(self) -> None:
        self.rel: list[tuple[float, float, float, str]] = []

    def add_relative_yaw(self, t, yaw, var, source):
        self.rel.append((t, yaw, var, source))


class _Loc:
    odom_mode = True
    frontend = None

    def __init__(self) -> None:
        self.backend = _RelBackend()
        self.stats: dict = {}
        self.compass: list = []

    def on_compass(self, m):
        self.compass.append(m)


def test_the_router_hands_a_differential_orientation_as_a_heading_through_its_mount():
    """Through a yawed, upside-down mount the base's yaw comes back; the first IMU is
    named ``imu`` (the EKF's first-source names), a second one by its own name; out of order is
    skipped; an IMU that also fuses vyaw keeps its gyro (no heading)."""
    specs = parse_sources({"imu0": {"type": "imu", "topic": "/a", "use": ["yaw"], "differential": True},
                           "imu1": {"type": "imu", "topic": "/b", "use": ["yaw"], "differential": True},
                           "imu2": {"type": "imu", "topic": "/c", "use": ["yaw", "vyaw"], "differential": True}})
    loc = _Loc()
    flip = Rotation.from_euler("z", 0.5) * Rotation.from_euler("x", math.pi)   # yawed 0.5 rad, upside down
    mount = Transform3D("base_link", "flipped", np.zeros(3), rotation_xyzw=flip.as_quat())
    router = SourceRouter(loc, specs, [mount])
    for t, yaw in ((1.0, 0.2), (1.1, 0.3), (1.05, 0.25)):
        q = (Rotation.from_euler("z", yaw) * flip).as_quat()
        router.on_message(specs[0], Imu(t, q, None, np.eye(3) * 1e-4, frame_id="flipped"))
        router.on_message(specs[1], Imu(t, Rotation.from_euler("z", yaw).as_quat(), None, np.eye(3) * 1e-4,
                                        frame_id="base_link"))
    got = [(t, round(y, 9), s) for t, y, _, s in loc.backend.rel]
    assert got == [(1.0, 0.2, "imu"), (1.0, 0.2, "imu1"), (1.1, 0.3, "imu"), (1.1, 0.3, "imu1")]
    assert router.health()["imu0"]["skipped"] == 1 and router.health()["imu0"]["accepted"] == 2
    router.on_message(specs[2], Imu(2.0, Rotation.from_euler("z", 0.1).as_quat(), np.array([0.0, 0.0, 0.4]),
                                    np.eye(3) * 1e-4, np.eye(3) * 1e-4, frame_id="base_link"))
    assert len(loc.backend.rel) == 4
