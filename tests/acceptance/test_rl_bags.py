"""Issue 17 acceptance: fgloc on robot_localization's own real-robot regression bags.

r_l (BSD-3-Clause) checks its EKF on ``test1.bag`` (Clearpath Husky, 395 s, IMU mounted
rotated: the mount is a static transform in the launch file, not in the bag) and ``test2.bag``
(Jackal, 61 s) against a final position and tolerance written in each test's launch file.  Here
each test's r_l parameters go through ``fgloc config from-robot-localization`` and fgloc runs
the bag without a map, as ``tools/eval_rl_bags.py`` does (it prints the whole table).

The bags are not in this repository: the tests look in ``$FGLOC_RL_BAGS`` (folders separated by
``os.pathsep``), ``data/robot_localization`` and ``../shared/data/robot_localization`` for
``test1.bag``, ``test2.bag`` and r_l's ROS 1 ``test_ekf_localization_node_bag{1,2}.test``
(noetic-devel), and skip when they are absent; groovy-devel's ``test_ekf_localization_node_test_bag{1,2,3}.test``
(12-value _config vectors) with their ``test{1,2,3}.bag`` are used when a folder has them (keys
``groovy/testN.bag``: groovy's test1.bag is another robot than noetic's).

Whether fgloc ends within r_l's tolerance, per configuration and back-end, is
``test_rl_matrix.py``'s (the fusion matrix); this file checks the conversion and the sources.
"""

from __future__ import annotations

import importlib.util
import os
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

REPO = Path(__file__).resolve().parents[2]
NEEDED = ("test1.bag", "test2.bag", "test_ekf_localization_node_bag1.test", "test_ekf_localization_node_bag2.test")


def _folders() -> list[Path]:
    env = os.environ.get("FGLOC_RL_BAGS")
    return ([Path(e) for e in env.split(os.pathsep) if e] if env else []) + [
        REPO / "data" / "robot_localization", REPO.parent / "shared" / "data" / "robot_localization",
        REPO / "data" / "robot_localization-groovy", REPO.parent / "shared" / "data" / "robot_localization-groovy"]


@pytest.fixture(scope="module")
def tool() -> ModuleType:
    spec = importlib.util.spec_from_file_location("eval_rl_bags", REPO / "tools" / "eval_rl_bags.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("eval_rl_bags", mod)  # its dataclasses look their module up
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def cases(tool: ModuleType) -> dict[str, Any]:
    pytest.importorskip("rosbags")
    for d in _folders():
        if all((d / n).is_file() for n in NEEDED):
            found = {c.bag.name: c for c in tool.find_cases([d])}
            # groovy-devel's parameters (test_bagN) from any of the folders
            found.update({f"groovy/{c.bag.name}": c for c in tool.find_cases([f for f in _folders() if f.is_dir()])
                          if "test_bag" in c.name})
            return found
    pytest.skip("robot_localization's test1.bag / test2.bag and their .test files not found "
                "($FGLOC_RL_BAGS, data/robot_localization, ../shared/data/robot_localization)")


@pytest.fixture(scope="module")
def work(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("rl")


@pytest.fixture(scope="module")
def converted(tool: ModuleType, cases: dict[str, Any], work: Path) -> dict[str, tuple[Path, list[str]]]:
    out = {}
    for bag, case in cases.items():
        cfg, notes, err = tool.convert(case, work)
        assert err is None, err
        out[bag] = (cfg, notes)
    return out


def test_rl_parameters_convert(converted: dict[str, tuple[Path, list[str]]]) -> None:
    """The r_l test parameters convert; the planar part of each _config vector is carried over."""
    import yaml

    # two_d_mode false, imu0 fusing roll and pitch: the IMU's attitude levels the odometry
    want = {"test1.bag": {"odom0": ("/husky_velocity_controller/odom", ["vx", "vy"]),
                          "imu0": ("/imu/data", ["yaw", "roll", "pitch"])},
            "test2.bag": {"odom0": ("/jackal_velocity_controller/odom", ["vx", "vy", "vyaw"]),
                          "imu0": ("/imu/data", ["yaw", "vyaw", "roll", "pitch"])}}
    for bag, sources in want.items():
        cfg = yaml.safe_load(converted[bag][0].read_text())
        got = {n: (s["topic"], s["use"]) for n, s in cfg["sources"]["inputs"].items()}
        assert got == sources, bag


def test_converted_launch_file_carries_the_imu_mount(converted: dict[str, Any]) -> None:
    """test1's launch file publishes the Husky's IMU mount (the bag lacks it): the config has it."""
    import yaml

    cfg = yaml.safe_load(converted["test1.bag"][0].read_text())
    (tf,) = cfg["sources"]["static_transforms"]
    assert (tf["parent"], tf["child"]) == ("base_link", "imu_link")
    assert tf["xyz"] == pytest.approx([0.0, -0.3, 0.52]) and tf["rpy_deg"] == pytest.approx([90.0, 0.0, -90.0])


def test_groovy_test1_launch_file_converts_with_its_mounts_on_mustang_base(converted: dict[str, Any]) -> None:
    """groovy's test_bag1: 12-value vectors, odom0 a differential x, y pose source, odom1 a twist,
    two differential IMUs; base_link_frame mustang_base (sources.base_frame), whose mounts (the xsens
    rolled 180 deg: 'non-right-handed frames') carry over on it."""
    import yaml

    if "groovy/test1.bag" not in converted:
        pytest.skip("groovy-devel's test1.bag and test_ekf_localization_node_test_bag1.test not found")
    cfg = yaml.safe_load(converted["groovy/test1.bag"][0].read_text())
    got = {n: (s["use"], s.get("differential", False)) for n, s in cfg["sources"]["inputs"].items()}
    assert got == {"odom0": (["x", "y"], True), "odom1": (["vx", "vy", "vyaw"], False),
                   "imu0": (["yaw", "vyaw", "roll", "pitch"], True), "imu1": (["yaw", "roll", "pitch"], True)}
    tfs = {t["child"]: t for t in cfg["sources"]["static_transforms"]}
    assert set(tfs) == {"xsens_sensor", "ref_imu"} and {t["parent"] for t in tfs.values()} == {"mustang_base"}
    assert cfg["sources"]["base_frame"] == "mustang_base"
    assert tfs["xsens_sensor"]["rpy_deg"] == pytest.approx([180.0, 0.0, 0.0])


def test_converted_config_names_the_topics(cases: dict[str, Any], converted: dict[str, Any], work: Path) -> None:
    """A converted r_l config is enough to run: its sources name the topics (no --odom-topic)."""
    from fgloc.app.run import RunRequest, run_log

    case = cases["test2.bag"]
    r = run_log(RunRequest(log=case.bag, outdir=work / "no-topics", backend="ekf", config=converted["test2.bag"][0],
                           force=True, view_channels=False))
    assert r.stats.sources["odom0"].accepted == 3060
    assert r.stats.sources["imu0"].accepted == 3061


def test_no_heading_source_is_no_traceback(tool: ModuleType, cases: dict[str, Any], work: Path) -> None:
    """test1 with odom0 fusing vx, vy and no IMU (nothing measures the heading): the smoother
    finishes; solver failures, if any, are counted (GTSAM's 'Indeterminate linear system' is not raised)."""
    import yaml

    from fgloc.app.run import RunRequest, run_log

    cfg = work / "no-heading.yaml"
    cfg.write_text(yaml.safe_dump({"sources": {"inputs": {"odom0": {
        "type": "odometry", "topic": "/husky_velocity_controller/odom", "use": ["vx", "vy"]}}}}))
    r = run_log(RunRequest(log=cases["test1.bag"].bag, outdir=work / "no-heading", backend="smoother", config=cfg,
                           force=True, view_channels=False))
    assert r.poses > 1000
    assert r.stats.sources["odom0"].accepted == 3952
    assert isinstance(r.stats.backend.get("solver_failures", 0), int)


def test_groovy_test1_smoother_fuses_the_second_odometry_and_the_differential_imu(
        tool: ModuleType, cases: dict[str, Any], converted: dict[str, Any], work: Path) -> None:
    """groovy's test_bag1 in the smoother: odom1 (the stereo odometer's twist) is a factor, not
    skipped; imu1's differential orientation is a heading factor per keyframe, not rates."""
    if "groovy/test1.bag" not in cases:
        pytest.skip("groovy-devel's test1.bag and test_ekf_localization_node_test_bag1.test not found")
    res = tool.run_fgloc(cases["groovy/test1.bag"].bag, converted["groovy/test1.bag"][0], "smoother", None, None,
                         work / "groovy-test1-sources")
    src, be = res["stats"].sources, res["stats"].backend
    assert src["odom1"].accepted == 1313 and src["odom1"].skipped == 0
    assert be["velocity_factors"] > 1200 and src["odom1"].stream_gated["backend"] < 100   # 1241 and 28 at 1st commit
    assert be["relative_yaw_factors"] >= be["keyframes"] - 1 and be.get("relative_yaw_reanchored", 0) == 0
    assert src["imu0"].gyro_bias_radps == pytest.approx(0.00257, abs=0.0005)  # imu1's increments observe it
