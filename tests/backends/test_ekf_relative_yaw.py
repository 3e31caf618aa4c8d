"""EKF: a differential orientation source (robot_localization's ``imuN_differential``) is fused
as a heading with its own offset state, so stamp jitter cannot turn its increments into rate
spikes that the gate drops; beside a gyro with a scale error it keeps the heading."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import AHRS_SPECS, differential_ahrs_log, route, skid_steer_turns, without_capability
from scipy.spatial.transform import Rotation

from fgloc.backends.contract import Capability
from fgloc.backends.ekf_backend import EKFBackend
from fgloc.localization import Localizer
from fgloc.localization.sources import SourceRouter, parse_sources
from fgloc.types import CompassHeading, Imu, StaticTransform, Transform3D


def _run(msgs) -> tuple[np.ndarray, Localizer]:
    loc = Localizer(None, StaticTransform("base_link", "laser", np.zeros(3)), backend="ekf")
    route(loc, AHRS_SPECS, msgs)
    loc.finish()
    return loc.backend.ekf.pose(), loc


def test_a_differential_orientation_keeps_the_heading_beside_a_gyro_with_a_scale_error():
    msgs, truth = differential_ahrs_log()
    pose, loc = _run(msgs)
    be = loc.backend
    assert isinstance(be, EKFBackend)
    assert be.source_health()["imu1.yaw"].accepted > 4000 and be.source_health()["imu1.yaw"].gated == 0
    err = float(np.hypot(*(pose[:2] - truth[:2])))
    # 40 m driven, 8 rad turned (the gyro alone would lose 0.96 rad of heading on the way)
    assert err < 0.1, err
    assert abs(math.remainder(float(pose[2]) - truth[2], 2 * math.pi)) < 0.03


def test_without_the_heading_path_the_jittered_rates_lose_the_heading(monkeypatch: pytest.MonkeyPatch):
    """What the router did before (the increments as rates d_yaw / d_t): the same log ends
    metres off; the figure shows what the heading path fixes."""
    msgs, truth = differential_ahrs_log()
    without_capability(monkeypatch, EKFBackend, Capability.RELATIVE_YAW)
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

    capabilities = frozenset({Capability.RELATIVE_YAW})
    initialized = True
    encoder_sigmas = (0.01, 0.01, 0.02)

    def __init__(self) -> None:
        self.rel: list[tuple[float, float, float, str]] = []

    def add_relative_yaw(self, t, yaw, var, source):
        self.rel.append((t, yaw, var, source))

    def source_health(self):
        return {}

    def source_noise(self, name):
        return None


class _Loc:
    odom_mode = True
    frontend = None
    dead_reckoning = None  # the localizer's odometry + IMU dead reckoning (none in odom mode here)

    def __init__(self) -> None:
        self.backend = _RelBackend()
        self.stats: dict = {}
        self.compass: list = []

    def on_compass(self, m):
        self.compass.append(m)

    def compass_values(self, t, yaw, yaw_var, rate, rate_var):
        self.compass.append(CompassHeading(t, yaw, rate, yaw_var, rate_var))


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
    assert router.health()["imu0"].skipped == 1 and router.health()["imu0"].accepted == 2
    router.on_message(specs[2], Imu(2.0, Rotation.from_euler("z", 0.1).as_quat(), np.array([0.0, 0.0, 0.4]),
                                    np.eye(3) * 1e-4, np.eye(3) * 1e-4, frame_id="base_link"))
    assert len(loc.backend.rel) == 4


def _skid_steer_turns(scrub: float) -> tuple[EKFBackend, float]:
    """Four 90 deg turns at 0.7 rad/s between straights; the wheels report ``scrub`` times the turn
    and claim 0.01 rad/s; a differential AHRS (100 Hz) reads the true heading plus its own offset.
    Returns the back-end and the true final heading."""
    be = EKFBackend()
    be.initialize(0.0, np.zeros(3), np.diag([1e-4, 1e-4, 1e-4]))
    rng = np.random.default_rng(1)
    th = 0.0
    for k, t, th, w in skid_steer_turns():
        if k % 5 == 0:
            be.add_odometry(t, np.array([0.7, 0.0, scrub * w]), np.diag([1e-4, 1e-4, 1e-4]))
        be.add_relative_yaw(t, th + 0.4 + float(rng.normal(0.0, 0.002)), 1e-4, "ahrs")
    return be, th


def test_a_heading_that_creeps_off_on_scrubbing_wheels_is_reopened_not_reanchored():
    """A skid steer's wheels report 2.5x the turn: the filter's heading creeps past the gate in a
    turn.  The AHRS's increments are smooth (no jump), so the heading is re-opened to it; re-anchoring
    its offset after the gated run would keep the wheels' extra turn for good (~1.2 rad a turn)."""
    be, th = _skid_steer_turns(2.5)
    assert be.stats.get("relative_yaw_reanchored", 0) == 0
    assert be.stats.get("relative_yaw_reopened", 0) > 0
    assert abs(math.remainder(float(be.ekf.x[2]) - th, 2 * math.pi)) < 0.02
    # honest wheels: nothing gated, nothing re-opened
    be, th = _skid_steer_turns(1.0)
    assert be.stats.get("relative_yaw_reopened", 0) == 0 and be.source_health()["ahrs.yaw"].gated == 0
    assert abs(math.remainder(float(be.ekf.x[2]) - th, 2 * math.pi)) < 0.01
