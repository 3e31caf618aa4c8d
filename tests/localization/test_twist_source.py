"""A twist source (``geometry_msgs/TwistWithCovarianceStamped``, robot_localization's ``twistN``) end to end:
an MCAP written with fgloc's own writer, read back, fused as a body twist by ``fgloc run`` - the
same trajectory as the same twists given as odometry without poses - and a converted r_l parameter
file with ``twist0`` run by the command line."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from fgloc.app.run import RunRequest, run_log
from fgloc.config import parse_config
from fgloc.errors import ConfigError
from fgloc.eval.metrics import evaluate
from fgloc.io.mcap_writer import LogWriter
from fgloc.io.tum import read_tum
from fgloc.localization.sources import parse_sources
from fgloc.localization.sources.twist import in_base
from fgloc.types import Odometry, Twist

#: a sensor reporting its own twist, mounted 0.3 m ahead, 0.1 m right of base_link, turned +90 deg
SENSOR = {"parent": "base_link", "child": "flow_link", "xyz": [0.3, -0.1, 0.0], "rpy_deg": [0.0, 0.0, 90.0]}


@pytest.fixture(scope="module")
def sim():
    from fgloc.sim import simulate_paper

    return simulate_paper(seed=1, route=[[2.5, 3.0], [6.0, 3.0], [6.0, 5.0], [3.0, 5.0]])


def _write(path: Path, sim, how: str) -> Path:
    """The simulated run's odometry as ``how``: ``twist`` (base_link), ``sensor_twist`` (in SENSOR's frame)
    or ``odometry`` (nav_msgs/Odometry without poses); its IMU and ground truth as they are."""
    c, s = math.cos(math.radians(90.0)), math.sin(math.radians(90.0))
    J_inv = np.linalg.inv(np.array([[c, -s, -0.1], [s, c, -0.3], [0.0, 0.0, 1.0]]))  # in_base's map, inverted
    with LogWriter(path) as w:
        for topic, m in sim.messages:
            if topic == "/odom":
                tw, cov = np.asarray(m.twist, dtype=float), np.asarray(m.twist_cov, dtype=float)
                if how == "odometry":
                    w.write("/odom", Odometry(m.stamp, tw, cov, None, None, "odom", "base_link"))
                elif how == "twist":
                    w.write("/twist", Twist(m.stamp, tw, cov, "base_link"))
                else:
                    w.write("/twist", Twist(m.stamp, J_inv @ tw, J_inv @ cov @ J_inv.T, "flow_link"))
            elif topic in ("/imu", "/ground_truth"):
                w.write(topic, m)
    return path


def _config(path: Path, inputs: dict, static: list | None = None) -> Path:
    path.write_text(yaml.safe_dump({"sources": {"inputs": inputs, "static_transforms": static or []}}))
    return path


@pytest.mark.parametrize("backend", ["ekf", "smoother"])
def test_a_twist_source_is_fused_as_the_odometry_twist(sim, tmp_path, backend):
    """Twist + IMU in the odom frame: byte for byte the trajectory of the same twists as odometry
    messages without poses, every twist accepted, and near the ground truth."""
    twist = run_log(RunRequest(log=_write(tmp_path / "t.mcap", sim, "twist"), outdir=tmp_path / "t", backend=backend,
                               config=_config(tmp_path / "t.yaml", {"twist0": {"type": "twist", "topic": "/twist"},
                                                                    "imu0": {"type": "imu", "topic": "/imu"}}),
                               view_channels=False))
    odom = run_log(RunRequest(log=_write(tmp_path / "o.mcap", sim, "odometry"), outdir=tmp_path / "o",
                              backend=backend, view_channels=False,
                              config=_config(tmp_path / "o.yaml", {"odom0": {"type": "odometry", "topic": "/odom"},
                                                                   "imu0": {"type": "imu", "topic": "/imu"}})))
    assert (tmp_path / "t" / "trajectory.tum").read_bytes() == (tmp_path / "o" / "trajectory.tum").read_bytes()
    rep = twist.stats.sources["twist0"]
    assert (rep.kind, rep.topic, rep.use, rep.accepted, rep.skipped) == ("twist", "/twist", ["vx", "vy", "vyaw"],
                                                                      len(sim.topic("/odom")), 0)
    assert twist.stats.odometry == odom.stats.odometry == len(sim.topic("/odom"))
    # 8.5 m driven; SE(2)-aligned (odom frame) position RMSE measured 0.011 m (ekf), 0.007 m (smoother)
    assert twist.metrics is not None and twist.metrics.position_rmse_m < 0.03, twist.metrics


def test_a_twist_in_a_sensor_frame_is_turned_into_base_link(sim, tmp_path):
    """The same twists reported by a sensor mounted ahead, to the right and turned 90 deg: through its
    mount (sources.static_transforms) they give the base_link run's trajectory (to rounding)."""
    inputs = {"twist0": {"type": "twist", "topic": "/twist"}, "imu0": {"type": "imu", "topic": "/imu"}}
    base = run_log(RunRequest(log=_write(tmp_path / "b.mcap", sim, "twist"), outdir=tmp_path / "b", backend="ekf",
                              config=_config(tmp_path / "b.yaml", inputs), view_channels=False))
    mounted = run_log(RunRequest(log=_write(tmp_path / "s.mcap", sim, "sensor_twist"), outdir=tmp_path / "s",
                                 backend="ekf", config=_config(tmp_path / "s.yaml", inputs, [SENSOR]),
                                 view_channels=False))
    a, b = read_tum(tmp_path / "b" / "trajectory.tum"), read_tum(tmp_path / "s" / "trajectory.tum")
    assert np.array_equal(a.stamps, b.stamps) and np.allclose(a.poses, b.poses, atol=1e-6)
    assert mounted.stats.sources["twist0"].mount is None and base.stats.sources["twist0"].accepted > 100
    # without the mount the sensor's axes are taken as the robot's: the robot drives sideways
    unmounted = run_log(RunRequest(log=tmp_path / "s.mcap", outdir=tmp_path / "u", backend="ekf",
                                   config=_config(tmp_path / "u.yaml", inputs), view_channels=False))
    rep = unmounted.stats.sources["twist0"]
    assert rep.mount == f"no transform chain base_link -> flow_link (no transform names it): {rep.unmounted} " \
                        "messages used unmounted" and rep.unmounted == rep.accepted > 100, rep
    assert np.abs(read_tum(tmp_path / "u" / "trajectory.tum").poses[-1, :2] - a.poses[-1, :2]).max() > 1.0


def test_in_base_moves_a_twist_by_the_lever_arm():
    # a sensor 0.5 m ahead of a robot turning on the spot at 1 rad/s moves sideways at 0.5 m/s
    tw, cov = in_base(np.array([0.0, 0.5, 1.0]), np.eye(3) * 1e-4, 0.5, 0.0, 0.0)
    assert np.allclose(tw, [0.0, 0.0, 1.0]) and cov is not None and np.allclose(cov, cov.T)
    # turned 90 deg: the sensor's x is the robot's y
    tw, _ = in_base(np.array([0.2, 0.0, 0.0]), None, 0.0, 0.0, math.pi / 2)
    assert np.allclose(tw, [0.0, 0.2, 0.0])


def test_a_twist_source_takes_velocities_only():
    with pytest.raises(ConfigError, match=r"sources.inputs.t.use: 'x' is not one of vx, vy, vyaw"):
        parse_sources({"t": {"type": "twist", "topic": "/t", "use": ["x", "vx"]}})
    with pytest.raises(ConfigError, match=r"sources.inputs.t.differential: a twist source has no poses"):
        parse_sources({"t": {"type": "twist", "topic": "/t", "differential": True}})
    (spec,) = parse_sources({"t": {"type": "twist"}})
    assert (spec.topic, spec.use) == ("/twist", ("vx", "vy", "vyaw"))


def test_a_converted_robot_localization_config_with_twist0_runs(sim, tmp_path):
    """r_l parameters with twist0 (vx, vy, vyaw of its 15) and imu0 (yaw, vyaw): converted by
    `fgloc config from-robot-localization`, run by `fgloc run` on the written log."""
    flags = [False] * 15
    twist_cfg, imu_cfg = list(flags), list(flags)
    for j in (6, 7, 11):
        twist_cfg[j] = True
    for j in (5, 11):
        imu_cfg[j] = True
    rl = tmp_path / "ekf.yaml"
    rl.write_text(yaml.safe_dump({"ekf_filter_node": {"ros__parameters": {
        "frequency": 30.0, "two_d_mode": True, "world_frame": "odom",
        "twist0": "twist", "twist0_config": twist_cfg, "imu0": "imu", "imu0_config": imu_cfg}}}))
    log = _write(tmp_path / "log.mcap", sim, "twist")
    fg = [sys.executable, "-c", "import sys; from fgloc.cli import main; sys.exit(main())"]
    conv = subprocess.run([*fg, "config", "from-robot-localization", str(rl), "-o", str(tmp_path / "fgloc.yaml")],
                          capture_output=True, text=True, timeout=300)
    assert conv.returncode == 0, conv.stderr
    inputs = parse_config(yaml.safe_load((tmp_path / "fgloc.yaml").read_text())).sources.inputs
    assert inputs["twist0"] == {"type": "twist", "topic": "/twist", "use": ["vx", "vy", "vyaw"]}
    run = subprocess.run([*fg, "run", str(log), "--config", str(tmp_path / "fgloc.yaml"), "--backend", "ekf",
                          "-o", str(tmp_path / "out"), "-q"], capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    n = len(sim.topic("/odom"))
    assert f"twist0 (twist /twist: vx vy vyaw): {n} accepted" in run.stdout, run.stdout
    traj = read_tum(tmp_path / "out" / "trajectory.tum")
    rmse = evaluate(traj, sim.ground_truth, align=True).position_rmse_m  # the odom frame, SE(2)-aligned
    assert len(traj) > 100 and rmse < 0.03, rmse  # measured 0.011 m over 8.5 m
