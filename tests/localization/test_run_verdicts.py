"""The consistency monitor's one-line findings: the initial pose does not fit the map (its poses marked
lost, the run still usable); a configuration that makes the fusion diverge from odometry + IMU dead
reckoning (exit 3), while the same log with a right configuration stays ok."""

from __future__ import annotations

import csv

import numpy as np
import pytest
import yaml

from fgloc.config import load_config
from fgloc.localization import Localizer, Session

LEG = [[2.5, 3.0], [27.5, 3.0]]  # the paper's first leg (35 s)


def test_a_wrong_initial_pose_is_said_and_its_poses_are_marked_lost():
    from fgloc.sim import simulate_paper

    sim = simulate_paper(seed=0, route=LEG)
    msgs = [(t, m) for t, m in sim.messages if t != "/ground_truth"]
    wrong = np.array([6.0, 10.0, 1.0])  # 7.7 m and 57 deg from where the robot starts
    loc = Localizer(sim.map, sim.laser_mount, "smoother", "native", initial_pose=wrong, config=load_config())
    est = Session(loc).run(msgs)
    (v,) = [v for v in loc.stats["status"]["verdicts"] if v["kind"] == "initial_pose"]
    assert v["message"].startswith("the initial pose (6.00 m, 10.00 m, 57 deg) does not fit the map")
    assert not v["unusable"]
    status = np.array(loc.monitor.at(est.stamps)[0])
    err = np.hypot(*(est.poses[:, :2] - sim.ground_truth.interpolate(est.stamps)[:, :2]).T)
    assert (status == "lost").sum() >= 5 and (status == "ok").sum() > 0.9 * len(status)
    assert float(err[status == "lost"].min()) > 1.0      # the poses marked lost are the wrong ones (7.8 m)
    assert float(err[status == "ok"].max()) < 0.05       # ... and the ok ones are right (6 mm)


IMU_MOUNT = {"parent": "base_link", "child": "imu_link", "xyz": [0.0, 0.0, 0.0]}


def _config(tmp_path, name: str, rpy_deg: list[float]):
    """Wheels (vx, vy, vyaw) and the IMU's yaw rate, its mount given (upside down: the rate reversed)."""
    cfg = {"sources": {"inputs": {"odom": {"type": "odometry", "topic": "/odom", "use": ["vx", "vy", "vyaw"]},
                                  "imu": {"type": "imu", "topic": "/imu", "use": ["vyaw"]}},
                       "static_transforms": [{**IMU_MOUNT, "rpy_deg": rpy_deg}]}}
    path = tmp_path / name
    path.write_text(yaml.safe_dump(cfg))
    return path


@pytest.fixture(scope="module")
def imu_log(tmp_path_factory):
    """Two legs of the paper's rectangle by a robot with a 9-axis IMU (upright) and no laser."""
    from fgloc.sim import run_scenario, write_sim

    sim = run_scenario({"route": [[2.5, 3.0], [27.5, 3.0], [27.5, 17.0], [2.5, 17.0]],
                        "imu": {"mount_rpy_deg": [0.0, 0.0, 0.0]}, "laser": {"enabled": False}}, seed=0)
    return write_sim(sim, tmp_path_factory.mktemp("imu")) / "log.mcap"


@pytest.mark.parametrize("backend", ["smoother", "ekf"])
def test_a_diverging_configuration_is_one_line_and_exit_3(tmp_path, imu_log, backend, capsys):
    from fgloc.cli import main

    rc = main(["run", str(imu_log), "--config", str(_config(tmp_path, "upside_down.yaml", [180.0, 0.0, 0.0])),
               "--backend", backend, "-o", str(tmp_path / "bad"), "-q"])
    out = capsys.readouterr()
    assert rc == 3
    assert "the fusion diverged from odometry + IMU dead reckoning" in out.err
    assert len(out.err.strip().splitlines()) == 1
    rows = list(csv.reader((tmp_path / "bad" / "trajectory_status.csv").read_text().splitlines()[2:]))
    assert sum(r[4] == "suspect" for r in rows) > 0.3 * len(rows)


@pytest.mark.parametrize("backend", ["smoother", "ekf"])
def test_the_same_log_rightly_configured_stays_ok(tmp_path, imu_log, backend, capsys):
    from fgloc.cli import main

    rc = main(["run", str(imu_log), "--config", str(_config(tmp_path, "upright.yaml", [0.0, 0.0, 0.0])),
               "--backend", backend, "-o", str(tmp_path / "good"), "-q"])
    out = capsys.readouterr()
    assert rc == 0, out.err
    rows = list(csv.reader((tmp_path / "good" / "trajectory_status.csv").read_text().splitlines()[2:]))
    assert {r[4] for r in rows} == {"ok"}
