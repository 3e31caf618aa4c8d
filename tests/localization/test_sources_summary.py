"""What the run summary says about the inputs (fgloc.localization.sources), on real odometry's
patterns: twists replaced by pose increments, a lateral velocity that is exactly 0, a configured
source the log never feeds, and an IMU mount whose /tf_static is logged after the first IMU messages."""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fgloc.localization import Localizer
from fgloc.localization.sources import SourceRouter, parse_sources, summary_lines
from fgloc.localization.stats import RunStats
from fgloc.types import Imu, Odometry, StaticTransform, Transform3D

MOUNT = StaticTransform("base_link", "laser", np.zeros(3))


def _router(backend: str, inputs: dict | None = None) -> tuple[Localizer, SourceRouter]:
    loc = Localizer(None, MOUNT, backend, "none")
    router = SourceRouter(loc, parse_sources(inputs))
    router.configured_inputs = bool(inputs)
    return loc, router


def _drive(router: SourceRouter, vy_reported: float, n: int = 200, period_s: float = 0.02) -> None:
    """A robot driving 0.2 m/s straight along x; the driver reports ``vy_reported`` sideways."""
    spec = next(s for s in router.specs if s.type == "odometry")
    for k in range(n):
        t = 10.0 + k * period_s
        router.on_message(spec, Odometry(t, np.array([0.2, vy_reported, 0.0]), np.eye(3) * 1e-4,
                                         np.array([0.2 * k * period_s, 0.0, 0.0]), np.eye(3) * 1e-4))


@pytest.mark.parametrize("backend", ["ekf", "smoother"])
def test_the_summary_says_how_much_odometry_came_from_pose_increments(backend: str) -> None:
    """A HeRo driver reports a sideways speed equal to its forward one; pose_deltas auto takes the
    twist from the poses, and the odometry's summary line says so (it said only '200 accepted')."""
    loc, router = _router(backend)
    _drive(router, vy_reported=0.2)
    loc.finish()
    router.finish()
    n = int(loc.stats["odometry_from_poses"])
    assert 150 < n < 200
    line = next(x for x in summary_lines(RunStats.of(loc.stats)) if x.startswith("odom "))
    assert f"{n} of 200 from pose increments: the twist disagreed with the poses" in line, line
    assert loc.stats["sources"]["odom"].vy_max_mps == pytest.approx(0.2)


def test_a_lateral_velocity_of_exactly_zero_is_a_differential_drive_for_the_smoother_too() -> None:
    """A TurtleBot3's odometry (vy exactly 0): the smoother's summary said 'omni' where the EKF's
    said 'differential'; now both say differential, and a base that reports vy says how much."""
    models = {}
    for backend in ("smoother", "ekf"):
        for vy in (0.0, 0.03):
            loc, router = _router(backend)
            _drive(router, vy_reported=vy)
            loc.finish()
            router.finish()
            models[backend, vy] = loc.stats["motion_model"]
    assert models["smoother", 0.0].startswith("differential: the odometry's lateral velocity is 0"), models
    assert models["ekf", 0.0].startswith("differential"), models
    assert models["smoother", 0.03].startswith("omni") and "up to 0.030 m/s" in models["smoother", 0.03], models
    # the EKF was handed the pose increments' vy (0), under its omni switch-over: it says why
    assert models["ekf", 0.03].startswith("differential") and "up to 0.030 m/s" in models["ekf", 0.03], models


def test_a_configured_source_the_log_never_feeds_is_a_warning(caplog: pytest.LogCaptureFixture) -> None:
    """A ported robot_localization config names /imu_broadcaster/imu; the log has /imu: the run goes
    on wheels-only (it did silently), with a warning naming the topic and the log's IMU topics."""
    inputs = {"odom0": {"type": "odometry", "topic": "/odom", "use": ["vx", "vyaw"]},
              "imu0": {"type": "imu", "topic": "/imu_broadcaster/imu", "use": ["vyaw"]}}
    loc, router = _router("smoother", inputs)
    router.log_topics = {"/odom": "nav_msgs/msg/Odometry", "/imu": "sensor_msgs/msg/Imu",
                         "/scan": "sensor_msgs/msg/LaserScan"}
    _drive(router, vy_reported=0.0)
    loc.finish()
    with caplog.at_level(logging.WARNING):
        router.finish()
    warned = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert warned == ["sources.inputs.imu0: no message on /imu_broadcaster/imu in the whole log; ran without it "
                      "(the log's Imu topics: /imu)"], warned
    line = next(x for x in summary_lines(RunStats.of(loc.stats)) if x.startswith("imu0 "))
    assert "0 accepted, no message on the topic in the whole log" in line and "gyro bias" not in line, line
    # the default layout (no sources configured): a log without /imu is a wheels-only log, no warning
    caplog.clear()
    loc, router = _router("smoother")
    _drive(router, vy_reported=0.0)
    loc.finish()
    with caplog.at_level(logging.WARNING):
        router.finish()
    assert not [r for r in caplog.records if r.levelno == logging.WARNING]
    # ... and its summary line says the IMU never came, rather than "0 accepted" alone
    line = next(x for x in summary_lines(RunStats.of(loc.stats)) if x.startswith("imu "))
    assert "0 accepted, no message on the topic in the whole log" in line, line


def _imu(t: float, yaw_base: float, R_bi: np.ndarray) -> Imu:
    q = Rotation.from_matrix(Rotation.from_euler("z", yaw_base).as_matrix() @ R_bi).as_quat()
    return Imu(t, q, np.zeros(3), np.eye(3) * 1e-4, np.eye(3) * 1e-6, frame_id="imu_link")


def test_a_mount_logged_after_the_first_imu_messages_is_no_missing_transform(caplog: pytest.LogCaptureFixture) -> None:
    """TurtleBot3 ROS 2 bags log /tf_static 0-53 ms after the first IMU message: fgloc warned 'no
    transform base_link -> imu_link' and the summary ended 'mount: no transform: identity' although
    the mount was applied from then on.  Now no warning, and the summary says when it came."""
    yawed = Rotation.from_euler("z", 90, degrees=True)
    mount = Transform3D("base_link", "imu_link", np.array([0.0, 0.0, math.pi / 2]), 0.1, yawed.as_quat())
    loc, router = _router("ekf")
    spec = next(s for s in router.specs if s.type == "imu")
    with caplog.at_level(logging.WARNING):
        for k in range(150):
            t = 5.0 + 0.02 * k
            if k == 3:
                router.on_tf([mount])
            router.on_message(spec, _imu(t, 0.3, yawed.as_matrix()))
        loc.finish()
        router.finish()
    assert not [r for r in caplog.records if "no transform" in r.getMessage()], caplog.text
    imu = loc.stats["sources"]["imu"]
    assert imu.mount == "from tf after 3 messages (identity until then)"
    # a frame whose mount never comes: warned once, after a second of its stamps (not at the first message)
    caplog.clear()
    loc, router = _router("ekf")
    spec = next(s for s in router.specs if s.type == "imu")
    with caplog.at_level(logging.WARNING):
        for k in range(30):
            router.on_message(spec, _imu(5.0 + 0.02 * k, 0.3, yawed.as_matrix()))
        assert not [r for r in caplog.records if "no transform" in r.getMessage()]
        for k in range(30, 150):
            router.on_message(spec, _imu(5.0 + 0.02 * k, 0.3, yawed.as_matrix()))
        loc.finish()
        router.finish()
    assert [r.getMessage() for r in caplog.records if "no transform" in r.getMessage()] == [
        "no transform chain base_link -> imu_link (no transform names it); the IMU is used unmounted (as if its "
        "axes were the base's): set sources.base_frame or give the mount (sources.static_transforms, "
        "--static-transform)"]
    imu = loc.stats["sources"]["imu"]
    assert imu.mount == "no transform chain base_link -> imu_link (no transform names it): 150 messages used unmounted"
    assert imu.unmounted == 150 and imu.to_dict()["unmounted"] == 150
    # a log shorter than the wait: warned at the end
    caplog.clear()
    loc, router = _router("ekf")
    spec = next(s for s in router.specs if s.type == "imu")
    with caplog.at_level(logging.WARNING):
        for k in range(10):
            router.on_message(spec, _imu(5.0 + 0.02 * k, 0.3, yawed.as_matrix()))
        loc.finish()
        router.finish()
    assert len([r for r in caplog.records if "no transform" in r.getMessage()]) == 1
