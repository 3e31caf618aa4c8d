"""A sensor's mount is the transform chain from the robot's base frame (REP 105: the odometry's
child_frame_id or sources.base_frame, whatever its name) to the sensor's frame, through
intermediate frames and links given either way round, from the log's tf, the config or the
command line; a frame no chain connects is used unmounted and said so (an IMU whose own orientation
says it is tilted is levelled instead: fgloc.app.imutilt)."""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from fgloc.app.run import RunRequest, run_log
from fgloc.frames.mounts import MountTable
from fgloc.frames.static import parse_static_transforms, transform_of
from fgloc.io.mcap_writer import LogWriter
from fgloc.io.tum import read_tum
from fgloc.types import Imu, Odometry, StaticTransform

#: the robot's base (the odometry's child_frame_id), an intermediate plate, the IMU upside down on it
BASE, PLATE, IMU = "chassis", "plate", "imu_sensor"
#: the plate is the tree's root: plate -> chassis (the chassis -> plate mount, the plate yawed +90 deg,
#: 0.1 m ahead and 0.2 m up, published the other way round) and plate -> imu_sensor (rolled 180 deg,
#: 0.05 m to the side)
LINKS = [{"parent": PLATE, "child": BASE, "xyz": [0.0, 0.1, -0.2], "rpy_deg": [0.0, 0.0, -90.0]},
         {"parent": PLATE, "child": IMU, "xyz": [0.0, 0.05, 0.0], "rpy_deg": [180.0, 0.0, 0.0]}]
#: the composed chassis -> imu_sensor mount: Rz(90) Rx(180), at [0.1, 0, 0.2] + Rz(90) [0, 0.05, 0]
DIRECT = {"parent": BASE, "child": IMU, "xyz": [0.05, 0.0, 0.2], "rpy_deg": [180.0, 0.0, 90.0]}
YAW_RATE = 0.2  # rad/s, at 1 m/s


def _rot(t: StaticTransform) -> np.ndarray:
    return Rotation.from_quat(np.asarray(t.rotation_xyzw)).as_matrix()


def test_a_chain_through_a_plate_given_either_way_round_composes() -> None:
    table = MountTable(parse_static_transforms(LINKS))
    assert table.mount(IMU) is None  # no base named yet: base_link / base_footprint are not on the chain
    table.add_odometry_frames("odom", BASE)
    got, (want,) = table.mount(IMU), parse_static_transforms([DIRECT])
    assert got is not None and got.parent == BASE and got.child == IMU
    np.testing.assert_allclose(_rot(got), _rot(want), atol=1e-12)
    np.testing.assert_allclose([*got.pose[:2], got.z], [0.05, 0.0, 0.2], atol=1e-12)
    assert table.mount(BASE) is None and table.is_base(BASE)
    # the same links in the log's tf, the base configured by name
    logged = MountTable(base_frame=BASE)
    logged.add_tf(parse_static_transforms(LINKS))
    np.testing.assert_allclose(_rot(logged.mount("/" + IMU)), _rot(want), atol=1e-12)


def test_the_chain_between_base_footprint_and_base_link_is_honoured() -> None:
    # the odometry moves base_footprint; the IMU hangs on base_link, which is turned 30 deg on it
    turned = Rotation.from_euler("z", 30, degrees=True).as_quat()
    tfs = [transform_of("base_footprint", "base_link", [0, 0, 0.1], turned),
           transform_of("base_link", "imu_link", [0, 0, 0], [0, 0, 0, 1])]
    table = MountTable()
    table.add_tf(tfs)
    table.add_odometry_frames("odom", "base_footprint")
    m = table.mount("imu_link")
    assert m is not None and m.parent == "base_footprint" and m.pose[2] == pytest.approx(math.radians(30))
    assert m.z == pytest.approx(0.1)
    # base_link's own odometry: the IMU is mounted straight on it
    table2 = MountTable(base_frame="base_link")
    table2.add_tf(tfs)
    assert table2.mount("imu_link").pose[2] == pytest.approx(0.0)


def test_the_bases_motion_in_the_world_is_never_a_mount() -> None:
    table = MountTable(base_frame=BASE)
    for k in range(3):  # /tf: odom -> chassis moving, and an IMU published on odom
        table.add_tf([StaticTransform("odom", BASE, np.array([0.1 * k, 0.0, 0.0])),
                      StaticTransform("odom", IMU, np.zeros(3))])
    assert table.mount(IMU) is None
    assert table.unconnected(IMU) == f"no transform chain {BASE} -> {IMU} (the frames its links reach: odom)"


def _imu(t: float, yaw: float, mount: Rotation, orientation: bool = True) -> Imu:
    """The base at ``yaw`` turning at YAW_RATE, seen by an IMU mounted by ``mount`` (base -> imu)."""
    r_wi = Rotation.from_euler("z", yaw) * mount
    w_i = mount.inv().apply([0.0, 0.0, YAW_RATE])
    if not orientation:  # a gyro alone: nothing says where up is
        return Imu(t, None, w_i, None, np.diag([1e-4] * 3), frame_id=IMU)
    return Imu(t, r_wi.as_quat(), w_i, np.diag([1e-4] * 3), np.diag([1e-4] * 3), frame_id=IMU)


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The same 10 s drive with both links in /tf_static, one, none."""
    d = tmp_path_factory.mktemp("chains")
    mount = Rotation.from_matrix(_rot(parse_static_transforms([DIRECT])[0]))
    out = {}
    for name, tf in (("tf", LINKS), ("half", LINKS[:1]), ("bare", []), ("gyro", [])):
        with LogWriter(d / f"{name}.mcap") as w:
            if tf:
                w.write("/tf_static", parse_static_transforms(tf), stamp=99.99)
            for i in range(201):  # 20 Hz, 1 m/s, turning
                t = 100.0 + 0.05 * i
                w.write("/wheels", Odometry(t, np.array([1.0, 0.0, YAW_RATE]), np.diag([1e-3] * 3), None, None,
                                            "odom", BASE))
                w.write("/imu", _imu(t + 0.01, 0.3 + YAW_RATE * (0.05 * i + 0.01), mount, name != "gyro"))
        out[name] = d / f"{name}.mcap"
    return out


def _run(log: Path, out: Path, sources: dict, cli: list[dict] | None = None) -> tuple[np.ndarray, object]:
    cfg = out.with_suffix(".yaml")
    cfg.write_text(yaml.safe_dump({"sources": {"inputs": {
        "odom0": {"type": "odometry", "topic": "/wheels", "use": ["vx", "vy"]},
        "imu0": {"type": "imu", "topic": "/imu", "use": ["yaw", "vyaw"]}}, **sources}}))
    r = run_log(RunRequest(log=log, outdir=out, backend="ekf", config=cfg, force=True, view_channels=False,
                           static_transforms=cli or []))
    return read_tum(out / "trajectory.tum").poses, r


def test_mount_in_tf_static_in_the_config_or_on_the_command_line_gives_one_trajectory(
        logs: dict[str, Path], tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    runs = {
        "tf_static": _run(logs["tf"], tmp_path / "a", {}),
        "config": _run(logs["bare"], tmp_path / "b", {"base_frame": BASE, "static_transforms": LINKS}),
        "cli": _run(logs["bare"], tmp_path / "c", {}, [DIRECT]),
        "config + tf_static": _run(logs["half"], tmp_path / "d", {"static_transforms": LINKS[1:]}),
    }
    ref = runs["tf_static"][0]
    assert len(ref) > 50
    for name, (poses, r) in runs.items():
        assert r.stats.sources["imu0"].accepted == 201 and r.stats.sources["imu0"].unmounted == 0, name
        np.testing.assert_allclose(poses, ref, atol=1e-6, err_msg=name)
    # the heading followed the base's: 0.3 rad + 9.9 s (the last keyframe) at 0.2 rad/s
    assert ref[-1, 2] == pytest.approx(2.28, abs=0.005)
    # no chain from the base to the IMU, its orientation upside down: levelled (rolled 180 deg), said; it
    # turns the base's way (its turn about the vertical unknown: the heading is off by a constant)
    with caplog.at_level(logging.WARNING):
        poses, r = _run(logs["bare"], tmp_path / "f", {})
    assert any("no mount of the IMU frame imu_sensor" in m.getMessage() for m in caplog.records)
    assert r.stats.sources["imu0"].unmounted == 0
    turned = math.remainder((poses[-1, 2] - poses[0, 2]) - (ref[-1, 2] - ref[0, 2]), 2 * math.pi)
    assert abs(turned) < 0.01
    caplog.clear()
    # a gyro alone (nothing says where up is) with no chain: used unmounted, said once, counted on the source
    with caplog.at_level(logging.WARNING):
        poses, r = _run(logs["gyro"], tmp_path / "e", {})
    warned = [m.getMessage() for m in caplog.records if "no transform chain" in m.getMessage()]
    assert warned == [f"no transform chain {BASE} -> {IMU} (no transform names it); the IMU is used unmounted (as "
                      "if its axes were the base's): set sources.base_frame or give the mount "
                      "(sources.static_transforms, --static-transform)"]
    rep = r.stats.sources["imu0"]
    assert rep.unmounted == 201 and rep.mount == f"no transform chain {BASE} -> {IMU} (no transform names it): " \
                                                 "201 messages used unmounted"
    assert np.abs(poses[-1, :2] - ref[-1, :2]).max() > 1.0  # upside down: it turns the other way
