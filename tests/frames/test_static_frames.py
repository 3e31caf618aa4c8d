"""Static transforms the log lacks: config entries, static_transform_publisher arguments, the router."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fgloc.errors import ConfigError
from fgloc.frames.static import (
    entry_of_publisher_args,
    parse_static_transforms,
    static_transform_entry,
)
from fgloc.frames.tf import mount_of
from fgloc.localization.sources import SourceRouter, parse_sources
from fgloc.types import CompassHeading, Imu, StaticTransform

# robot_localization's test1 launch file: the Husky's IMU, rolled 90 deg and yawed -90 deg
HUSKY_ARGS = "0 -0.3 0.52 -1.570796327 0 1.570796327 base_link imu_link".split()


def test_publisher_args_become_an_entry_equal_to_the_quaternion_form() -> None:
    e = entry_of_publisher_args(HUSKY_ARGS)
    assert e is not None
    assert e["parent"] == "base_link" and e["child"] == "imu_link"
    np.testing.assert_allclose(e["rpy_deg"], [90.0, 0.0, -90.0], atol=1e-6)
    (t,) = parse_static_transforms([e])
    np.testing.assert_allclose(t.rotation_xyzw, [0.5, -0.5, -0.5, 0.5], atol=1e-9)  # hand-computed
    assert t.pose[2] == pytest.approx(-math.pi / 2) and t.z == pytest.approx(0.52)
    q = entry_of_publisher_args([*"0 -0.3 0.52 0.5 -0.5 -0.5 0.5".split(), "/base_link", "/imu_link", "100"])
    assert q is not None and q["child"] == "imu_link"
    (t2,) = parse_static_transforms([q])
    np.testing.assert_allclose(t2.rotation_xyzw, t.rotation_xyzw, atol=1e-9)
    assert entry_of_publisher_args("1 2 3 base_link".split()) is None
    assert entry_of_publisher_args("1 2 3 4 5 base_link imu".split()) is None


def test_cli_entry_and_mount_lookup() -> None:
    ts = parse_static_transforms([static_transform_entry("base_link", "laser", 0.2, 0.0, 0.3, 0.0, 0.0, 30.0)])
    m = mount_of("/laser", ts)
    assert m is not None and m.pose == pytest.approx([0.2, 0.0, math.radians(30)])
    assert mount_of("imu_link", ts) is None


@pytest.mark.parametrize(("entry", "message"), [
    ({"parent": "base_link", "child": "imu", "rpy": [0, 0, 0]}, "unknown key 'rpy'"),
    ({"parent": "map", "child": "imu"}, "mounts on the robot"),
    ({"parent": "base_link"}, "needs parent and child"),
    ({"parent": "base_link", "child": "imu", "xyz": [0, 0]}, "xyz: needs 3 numbers"),
    ({"parent": "base_link", "child": "imu", "xyzw": [0, 0, 0, 2]}, "not a unit quaternion"),
    ({"parent": "base_link", "child": "imu", "xyzw": [0, 0, 0, 1], "rpy_deg": [0, 0, 0]}, "not both"),
    ("base_link imu", "must be a mapping"),
])
def test_bad_entries_are_one_line_errors(entry: object, message: str) -> None:
    with pytest.raises(ConfigError, match=message) as e:
        parse_static_transforms([entry], source="f.yaml")
    assert "\n" not in str(e.value) and str(e.value).startswith("f.yaml: sources.static_transforms[0]")


class _Loc:
    odom_mode = True
    frontend = None

    def __init__(self) -> None:
        self.compass: list[CompassHeading] = []
        self.stats: dict = {}
        self.backend = None

    def on_compass(self, m: CompassHeading) -> None:
        self.compass.append(m)

    def compass_values(self, t: float, yaw: float | None, yaw_var: float, rate: float | None, rate_var: float) -> None:
        self.compass.append(CompassHeading(t, yaw, rate, yaw_var, rate_var))


def test_configured_mount_rotates_the_imu_and_wins_over_the_log() -> None:
    """A yaw-only reading of the Husky's IMU: its yaw minus the mount's (-90 deg); a log transform
    of the same frame does not replace the configured one; the unused tilted z rate is no skip."""
    loc = _Loc()
    mounts = parse_static_transforms([entry_of_publisher_args(HUSKY_ARGS)])
    router = SourceRouter(loc, parse_sources({"imu0": {"type": "imu", "topic": "/imu/data", "use": ["yaw"]}}),
                          mounts)
    router.on_tf([StaticTransform("base_link", "imu_link", np.zeros(3))])  # the log's (wrong) one
    spec = router.specs[0]
    router.on_message(spec, CompassHeading(1.0, 0.3, 0.05, 1e-4, 1e-4, frame_id="imu_link"))
    assert loc.compass[-1].yaw_rad == pytest.approx(0.3 + math.pi / 2)
    assert router.state["imu0"].health.skipped == 0
    # the whole Imu through the configured 3-D mount: the base level, heading 0.3 rad
    from scipy.spatial.transform import Rotation

    R_bi = Rotation.from_quat(mounts[0].rotation_xyzw)
    q_imu = (Rotation.from_euler("z", 0.3) * R_bi).as_quat()
    router.on_message(spec, Imu(2.0, q_imu, np.zeros(3), orientation_cov=np.eye(3) * 1e-4,
                                angular_velocity_cov=np.eye(3) * 1e-4, frame_id="imu_link"))
    assert len(loc.compass) == 2
    assert loc.compass[-1].yaw_rad == pytest.approx(0.3)
