"""``fgloc config from-fuse``: a fuse (fuse_optimizers + fuse_models) parameter file becomes an fgloc
config with the same sensors; ``from-robot-localization`` on such a file names the command that reads it.
The first file is fuse's own tutorial (fuse_tutorials/config/fuse_simple_tutorial.yaml, TurtleBot3:
wheels' velocities and the gyro's yaw rate)."""

from __future__ import annotations

import pytest
import yaml

from fgloc.config import parse_config
from fgloc.errors import ConfigError
from fgloc.porting import from_fuse
from fgloc.testing.cli import last_error_line, run_cli

TUTORIAL = """
optimization_frequency: 20
transaction_timeout: 0.01
lag_duration: 0.5
motion_models:
  unicycle_motion_model:
    type: fuse_models::Unicycle2D
unicycle_motion_model:
  process_noise_diagonal: [0.100, 0.100, 0.100, 0.100, 0.100, 0.100, 0.1, 0.1]
sensor_models:
  initial_localization_sensor:
    type: fuse_models::Unicycle2DIgnition
    motion_models: [unicycle_motion_model]
    ignition: true
  odometry_sensor:
    type: fuse_models::Odometry2D
    motion_models: [unicycle_motion_model]
  imu_sensor:
    type: fuse_models::Imu2D
    motion_models: [unicycle_motion_model]
initial_localization_sensor:
  publish_on_startup: true
  initial_state: [0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000]
  initial_sigma: [0.100, 0.100, 0.100, 0.100, 0.100, 0.100, 0.100, 0.100]
odometry_sensor:
  topic: 'odom'
  twist_target_frame: 'base_footprint'
  linear_velocity_dimensions: ['x', 'y']
  angular_velocity_dimensions: ['yaw']
imu_sensor:
  topic: 'imu'
  twist_target_frame: 'base_footprint'
  angular_velocity_dimensions: ['yaw']
publishers:
  filtered_publisher:
    type: fuse_models::Odometry2DPublisher
filtered_publisher:
  topic: 'odom_filtered'
  base_link_frame_id: 'base_footprint'
  odom_frame_id: 'odom'
  map_frame_id: 'map'
  world_frame_id: 'odom'
"""

ROS2 = """
state_estimator:
  ros__parameters:
    lag_duration: 1.0
    sensor_models:
      wheels: {type: fuse_models::Odometry2D}
      imu: {type: fuse_models::Imu2D}
      accel: {type: fuse_models::Acceleration2D}
      fix: {type: fuse_models::Pose2D}
    wheels: {topic: /wheel/odometry, position_dimensions: [x, y], orientation_dimensions: [yaw], differential: true}
    imu: {topic: imu/data, orientation_dimensions: [yaw], angular_velocity_dimensions: [yaw],
          linear_acceleration_dimensions: [x, y], differential: true}
    accel: {topic: imu/data, linear_acceleration_dimensions: [x]}
    fix: {topic: /fix_pose, position_dimensions: [x, y]}
    publishers:
      out: {type: fuse_models::Odometry2DPublisher}
    out: {topic: odometry/fused, world_frame_id: map, base_link_frame_id: robot_base}
"""


def test_the_tutorial_keeps_its_sensors():
    cfg, notes = from_fuse(yaml.safe_load(TUTORIAL))
    parse_config(cfg)
    assert cfg["sources"]["inputs"] == {
        "odometry_sensor": {"type": "odometry", "topic": "/odom", "use": ["vx", "vy", "vyaw"]},
        "imu_sensor": {"type": "imu", "topic": "/imu", "use": ["vyaw"]}}
    assert cfg["sources"]["base_frame"] == "base_footprint"
    assert cfg["ekf"] == {"q_xy": 0.1, "q_theta": 0.1, "q_v": 0.1, "q_w": 0.1}
    assert cfg["pipeline"] == pytest.approx({"initial_sigma_xy_m": 0.1, "initial_sigma_yaw_deg": 5.729578})
    said = "\n".join(notes)
    assert "lag_duration" in said and "twist_target_frame" in said
    assert "fgloc eval OUT/trajectory.tum LOG:/odom_filtered --align-start" in said


def test_a_ros2_file_with_poses_and_accelerations():
    cfg, notes = from_fuse(yaml.safe_load(ROS2))
    parse_config(cfg)
    inputs = cfg["sources"]["inputs"]
    assert inputs["wheels"] == {"type": "odometry", "topic": "/wheel/odometry", "use": ["x", "y", "yaw"],
                                "differential": True}
    assert inputs["imu"] == {"type": "imu", "topic": "/imu/data", "use": ["yaw", "vyaw"], "differential": True}
    assert inputs["fix"] == {"type": "pose", "topic": "/fix_pose", "use": ["x", "y"], "frame_id": "map"}
    assert "accel" not in inputs and cfg["sources"]["base_frame"] == "robot_base"
    said = "\n".join(notes)
    assert "accel (fuse_models::Acceleration2D): fgloc does not fuse accelerations" in said
    assert "imu: linear_acceleration_dimensions not carried over" in said


def test_the_commands(tmp_path):
    f = tmp_path / "fuse_simple_tutorial.yaml"
    f.write_text(TUTORIAL)
    rc, _out, err = run_cli("config", "from-robot-localization", f)
    assert rc == 2 and last_error_line(err) == (f"{f}: a fuse configuration (fuse_optimizers' sensor_models), not "
                                                f"robot_localization's: fgloc config from-fuse {f} converts it")
    rc, out, _err = run_cli("config", "from-fuse", f, "-o", tmp_path / "fgloc.yaml")
    assert rc == 0 and "wrote" in out
    doc = yaml.safe_load((tmp_path / "fgloc.yaml").read_text())
    assert doc["sources"]["inputs"]["imu_sensor"]["use"] == ["vyaw"]
    gyro_only = tmp_path / "gyro.yaml"
    gyro_only.write_text("sensor_models:\n  g: {type: fuse_models::Imu2D}\n"
                         "g: {topic: imu, angular_velocity_dimensions: [yaw]}\n")
    rc, _out, err = run_cli("config", "from-fuse", gyro_only)
    assert rc == 2 and "no source of motion" in last_error_line(err)


def test_not_a_fuse_file():
    with pytest.raises(ConfigError, match="no parameters of the expected node found"):
        from_fuse({"ekf_node": {"odom0": "odom", "two_d_mode": True}})


def test_models_listed_by_name():
    """Older fuse files list the models as ``- name: ..., type: ...``."""
    cfg, _notes = from_fuse({"sensor_models": [{"name": "w", "type": "fuse_models::Twist2D"}],
                             "w": {"topic": "twist", "linear_velocity_dimensions": ["x"],
                                   "angular_velocity_dimensions": ["yaw"]}})
    assert cfg["sources"]["inputs"] == {"w": {"type": "twist", "topic": "/twist", "use": ["vx", "vyaw"]}}
