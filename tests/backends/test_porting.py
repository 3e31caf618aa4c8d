"""robot_localization and nav2 parameter files -> fgloc config, on real files, and run on a log."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from fgloc.config import parse_config
from fgloc.porting import from_nav2, from_robot_localization

DATA = Path(__file__).resolve().parent / "data" / "porting"


def test_husky_ros1_file_converts_with_a_line_per_dropped_parameter():
    cfg, notes = from_robot_localization(yaml.safe_load((DATA / "husky_localization.yaml").read_text()))
    inputs = parse_config(cfg).sources.inputs
    assert inputs["odom0"] == {"type": "odometry", "topic": "/husky_velocity_controller/odom",
                               "use": ["x", "y", "yaw"], "differential": True}
    assert inputs["imu0"] == {"type": "imu", "topic": "/imu/data", "use": ["yaw", "vyaw"], "differential": True}
    joined = "\n".join(notes)
    assert "odom0_config: z not carried over" in joined
    assert "imu0_config: roll, pitch, vroll, vpitch not carried over" in joined
    assert "imu0_remove_gravitational_acceleration: fgloc does not fuse accelerations" in joined
    assert "frequency: 50" in joined
    assert len(notes) == 4


def test_robot_localization_ros2_example_layout():
    # the sensor / filter parameters of cra-ros-pkg/robot_localization params/ekf.yaml (ROS 2 layout)
    f = [False] * 15

    def vec(*on):
        v = list(f)
        for i in on:
            v[i] = True
        return v

    q = np.diag([0.05, 0.05, 0.06, 0.03, 0.03, 0.06, 0.025, 0.025, 0.04, 0.01, 0.01, 0.02, 0.01, 0.01, 0.015])
    params = {"ekf_filter_node": {"ros__parameters": {
        "frequency": 30.0, "sensor_timeout": 0.1, "two_d_mode": False, "publish_tf": True,
        "map_frame": "map", "odom_frame": "odom", "base_link_frame": "base_link", "world_frame": "odom",
        "odom0": "example/odom", "odom0_config": vec(0, 1, 11), "odom0_queue_size": 2, "odom0_differential": False,
        "odom0_relative": False, "odom0_pose_rejection_threshold": 5.0, "odom0_twist_rejection_threshold": 1.0,
        "odom1": "example/odom2", "odom1_config": vec(2, 11), "odom1_differential": False, "odom1_relative": True,
        "pose0": "example/pose", "pose0_config": vec(0, 1), "pose0_differential": True,
        "pose0_rejection_threshold": 2.0,
        "twist0": "example/twist", "twist0_config": vec(6, 7, 8), "twist0_rejection_threshold": 2.0,
        "imu0": "example/imu", "imu0_config": vec(3, 4, 5, 9, 10, 11, 12, 13, 14), "imu0_differential": False,
        "imu0_relative": True, "imu0_pose_rejection_threshold": 0.8,
        "use_control": True, "control_config": [True, False, False, False, False, True],
        "process_noise_covariance": q.reshape(-1).tolist(),
        "initial_estimate_covariance": (np.eye(15) * 1e-9).reshape(-1).tolist()}}}
    cfg, notes = from_robot_localization(params)
    c = parse_config(cfg)
    src = c.sources.inputs
    # absolute odometry poses as increments (the odom-frame EKF's only position source), per axis
    assert src["odom0"] == {"type": "odometry", "topic": "/example/odom", "use": ["x", "y", "vyaw"],
                            "differential": True}
    assert src["odom1"] == {"type": "odometry", "topic": "/example/odom2", "use": ["vyaw"]}
    assert src["pose0"] == {"type": "pose", "topic": "/example/pose", "use": ["x", "y"], "frame_id": "odom",
                            "differential": True, "gate": 4.0}
    assert src["imu0"]["use"] == ["yaw", "vyaw", "roll", "pitch"]  # two_d_mode false: roll, pitch level
    assert src["twist0"] == {"type": "twist", "topic": "/example/twist", "use": ["vx", "vy"]}  # vz: a note
    assert (c.ekf.q_xy, c.ekf.q_theta, c.ekf.q_v, c.ekf.q_w) == (0.05, 0.06, 0.025, 0.02)
    j = "\n".join(notes)
    for expected in ("odom0_config: absolute x, y of an odometry fused as its increments",
"twist0 (/example/twist): fgloc integrates one twist source, the first (odom0)",
                     "twist0_config: vz not carried over",
                     "imu0_config: vroll, vpitch, ax, ay, az not carried over",
                     "two_d_mode: false", "use_control: fgloc has no control input",
                     "odom0_queue_size: a ROS subscription setting", "sensor_timeout:",
                     "odom0_twist_rejection_threshold: 1 not carried over",
                     "odom1 (/example/odom2): fgloc integrates one odometry source, the first (odom0)"):
        assert expected in j, expected


def test_differential_is_what_robot_localization_does_with_it():
    # ADVRHumanoids/concert_localization config/ekf.yaml: odom0 vx, vy with odom0_differential: true,
    # which r_l applies to pose variables only (the velocities are fused as they are)
    f = [False] * 15
    vel = list(f)
    vel[6] = vel[7] = True
    yaw_rate = list(f)
    yaw_rate[11] = True
    cfg, notes = from_robot_localization({"odom0": "/odom", "odom0_config": vel, "odom0_differential": True,
                                          "imu0": "/imu", "imu0_config": yaw_rate, "imu0_differential": True})
    src = parse_config(cfg).sources.inputs
    assert src["odom0"] == {"type": "odometry", "topic": "/odom", "use": ["vx", "vy"]}
    assert src["imu0"] == {"type": "imu", "topic": "/imu", "use": ["vyaw"]}
    assert sum("has no effect" in n for n in notes) == 2


def test_nav2_amcl_section_converts():
    cfg, notes = from_nav2(yaml.safe_load((DATA / "nav2_params_amcl.yaml").read_text()))
    a = parse_config(cfg).frontends.amcl
    assert (a.alpha1, a.alpha5, a.sigma_hit, a.z_hit, a.z_rand) == (0.2, 0.2, 0.2, 0.5, 0.5)
    assert (a.laser_max_beams, a.min_particles, a.max_particles, a.update_min_d) == (60, 500, 2000, 0.25)
    assert a.robot_model_type == "differential" and a.laser_model_type == "likelihood_field"
    assert any(n.startswith("do_beamskip:") for n in notes) and any("--scan-topic scan" in n for n in notes)
    assert not any(n.startswith(("alpha", "z_hit", "max_beams")) for n in notes)
    r = parse_config(cfg).ros2  # nav2's ROS interface, for fgloc live --ros2
    assert (r.scan_topic, r.global_frame_id, r.odom_frame_id, r.tf_broadcast, r.transform_tolerance_s) == \
        ("/scan", "map", "odom", True, 1.0)


def test_cli_writes_a_checked_config(tmp_path, capsys):
    from fgloc.cli import main
    from fgloc.config import load_config

    out = tmp_path / "fgloc.yaml"
    assert main(["config", "from-robot-localization", str(DATA / "husky_localization.yaml"), "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "not carried over: imu0_remove_gravitational_acceleration" in printed
    assert load_config(out).sources.inputs["imu0"]["topic"] == "/imu/data"
    assert main(["config", "from-nav2", str(DATA / "nav2_params_amcl.yaml"), "-o", str(out), "--force"]) == 0
    assert load_config(out).frontends.amcl.sigma_hit == 0.2


def test_converted_husky_config_runs_a_skid_steer_log_with_its_topics():
    from fgloc.geometry import compose, inverse
    from fgloc.localization import Localizer, Session
    from fgloc.sim import run_scenario

    cfg, _ = from_robot_localization(yaml.safe_load((DATA / "husky_localization.yaml").read_text()))
    sim = run_scenario({"drive": "skid", "route": [[17.5, 3.0], [27.5, 3.0], [27.5, 9.0]], "speed_mps": 0.7,
                        "yaw_rate_radps": 0.7, "robot": {"wheel_radius_m": 0.165, "half_track_m": 0.28},
                        "odom": {"rate_hz": 20.0, "twist_sigma": [0.02, 0.01, 0.02], "scrub_factor": [1.4, 2.5],
                                 "scrub_ref_radps": 0.7},
                        "imu": {"mount_rpy_deg": [0.0, 0.0, 90.0]}, "laser": {"enabled": False}}, seed=3)
    rename = {"/odom": "/husky_velocity_controller/odom", "/imu": "/imu/data"}
    msgs = [(rename.get(t, t), m) for t, m in sim.messages]
    for backend in ("ekf", "smoother"):
        loc = Localizer(None, sim.laser_mount, backend=backend, config=cfg)
        tr = Session(loc).run(msgs)
        h = loc.stats["sources"]
        assert h["odom0"].accepted > 0.95 * len(sim.topic("/odom"))
        assert h["imu0"].accepted > 0.95 * len(sim.topic("/imu"))
        gt = sim.ground_truth
        T = compose(gt.interpolate(tr.stamps[0])[0], inverse(tr.poses[0]))
        end = compose(T, tr.poses[-1:])[0]
        err = float(np.hypot(*(end[:2] - gt.interpolate(tr.stamps[-1])[0][:2])))
        # 16 m with one turn and no absolute heading (the Husky fuses its IMU differentially): the
        # wheels' yaw from their radius mismatch (~0.005 rad/s at 0.7 m/s) and the gyro bias are
        # barely separable so soon; measured 0.04 m (EKF), 0.37 m (smoother)
        assert err < 0.03 * gt.path_length(), (backend, err)


def test_misspelt_parameters_get_a_suggestion_and_gps_says_what_it_needs():
    """A misspelt name is not 'no fgloc equivalent' but 'did you mean'; gpsN and a navsat_transform
    node say what GPS would need."""
    vel = [False] * 6 + [True, True] + [False] * 7
    cfg, notes = from_robot_localization({
        "ekf_se_map": {"frequncy": 30, "odom0": "/odom", "odom0_config": vel, "odom0_queue_sise": 5,
                       "gps0": "/gps/fix"},
        "navsat_transform": {"magnetic_declination_radians": 0.0, "yaw_offset": 0.0, "zero_altitude": True}})
    assert parse_config(cfg).sources.inputs["odom0"]["use"] == ["vx", "vy"]
    j = "\n".join(notes)
    assert "frequncy: not a robot_localization parameter (did you mean frequency?)" in j
    assert "odom0_queue_sise: not a robot_localization parameter (did you mean odom0_queue_size?)" in j
    assert "gps0: sensor_msgs/NavSatFix (GPS) is not read by fgloc: fusing it needs a datum" in j
    assert "navsat_transform (navsat_transform_node): sensor_msgs/NavSatFix (GPS)" in j
    assert "no fgloc equivalent" not in j
