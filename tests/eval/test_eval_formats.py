"""``fgloc eval`` and ``fgloc export`` read every format fgloc writes or reads: a run's MCAP
(/fused_pose), a simulated log (/ground_truth), a bag's odometry topic, a CARMEN corrected log."""

from __future__ import annotations

import json

import numpy as np
import pytest

from fgloc.eval.trajectories import read_trajectory
from fgloc.io.tum import read_tum
from fgloc.testing.cli import run_cli as fgloc


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    from fgloc.sim import simulate_paper, write_sim

    d = tmp_path_factory.mktemp("evalfmt")
    write_sim(simulate_paper(seed=1, route=[[2.5, 3.0], [7.5, 3.0]]), d / "sim")
    rc, _, err = fgloc("run", d / "sim" / "log.mcap", "--map", d / "sim" / "map.yaml", "--initial-pose", "2.5", "3",
                       "0", "-o", d / "out", "-q")
    assert rc == 0, err
    return d


def test_run_mcap_against_the_logs_ground_truth_equals_the_tum_files(run_dir):
    """run.mcap's /fused_pose vs log.mcap's /ground_truth: the numbers of the exported TUM files."""
    fused, src = read_trajectory(run_dir / "out" / "run.mcap")
    assert src.topic == "/fused_pose" and len(fused) > 50
    gt, gsrc = read_trajectory(run_dir / "sim" / "log.mcap")
    assert gsrc.topic == "/ground_truth"
    np.testing.assert_array_equal(gt.poses, read_tum(run_dir / "sim" / "ground_truth.tum").poses)
    rc, out, err = fgloc("export", f"{run_dir / 'out' / 'run.mcap'}:/fused_pose", "-o", run_dir / "fused.tum")
    assert rc == 0, err
    assert f"{len(fused)} poses of" in out
    rc, _, err = fgloc("export", run_dir / "sim" / "log.mcap", "-o", run_dir / "gt.tum")
    assert rc == 0, err
    a = json.loads(fgloc("eval", run_dir / "out" / "run.mcap", run_dir / "sim" / "log.mcap", "--json")[1])
    b = json.loads(fgloc("eval", run_dir / "fused.tum", run_dir / "gt.tum", "--json")[1])
    # the same numbers (TUM's quaternion round trip of the yaw: to 1e-12)
    assert a["metrics"] == pytest.approx(b["metrics"], rel=1e-9, abs=1e-12)
    assert 0 < a["metrics"]["position_rmse_m"] < 0.05
    assert a["reference"].endswith("log.mcap:/ground_truth")
    # exported again: refused without --force
    rc, _, err = fgloc("export", run_dir / "sim" / "log.mcap", "-o", run_dir / "gt.tum")
    assert rc == 2 and err.strip() == f"fgloc: error: {run_dir / 'gt.tum'}: exists; pass --force to overwrite it"


def test_topic_choice_and_its_errors(run_dir):
    log = run_dir / "sim" / "log.mcap"
    odom, src = read_trajectory(f"{log}:odom")  # resolved as ROS does: /odom
    assert src.topic == "/odom" and len(odom) > 100
    rc, _, err = fgloc("eval", run_dir / "out" / "trajectory.tum", log, "--topic", "/scan")
    assert rc == 2 and err.strip() == (f"fgloc: error: {log}: /scan is sensor_msgs/msg/LaserScan, not "
                                       "nav_msgs/Odometry, geometry_msgs/PoseWithCovarianceStamped or PoseStamped (its "
                                       "pose topics: /ground_truth (nav_msgs/msg/Odometry), "
                                       "/odom (nav_msgs/msg/Odometry))")
    rc, _, err = fgloc("eval", run_dir / "out" / "trajectory.tum", f"{log}:/nope")
    assert rc == 2 and "no topic /nope (its pose topics: /ground_truth" in err
    rc, _, err = fgloc("eval", run_dir / "out" / "trajectory.tum", f"{run_dir / 'sim' / 'ground_truth.tum'}:/x")
    assert rc == 2 and "a TUM file has no topics" in err


def test_bag_odometry_and_carmen_corrected_log(shared_data, repo_data, tmp_path):
    """A ROS 1 bag's only odometry topic; a CARMEN log's laser poses (the corrected log's are the
    reference the bundled excerpt's poses were matched from)."""
    tr, src = read_trajectory(shared_data / "robot_localization" / "test2.bag")
    assert src.topic == "/jackal_velocity_controller/odom" and len(tr) == 3060
    corr, csrc = read_trajectory(shared_data / "radish-reference" / "intel-corrected.log.gz")
    assert csrc.kind == "carmen" and len(corr) > 500
    raw, _ = read_trajectory(repo_data / "radish" / "intel-head.clf.bz2")
    assert len(raw) == 1200  # one pose per FLASER line
    rc, _, err = fgloc("export", shared_data / "radish-reference" / "intel-corrected.log.gz", "-o", tmp_path / "c.tum")
    assert rc == 0, err
    np.testing.assert_allclose(read_tum(tmp_path / "c.tum").poses[:, :2], corr.poses[:, :2], atol=1e-12)
