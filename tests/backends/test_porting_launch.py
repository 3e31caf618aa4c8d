"""fgloc config from-robot-localization / from-nav2 on a ROS 1 launch file: params and static tfs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from fgloc.commands.porting import convert_file
from fgloc.config import parse_config
from fgloc.errors import ConfigError
from fgloc.frames.static import parse_static_transforms

LAUNCH = """<launch>
  <arg name="imu_yaw" default="-1.570796327"/>
  <node pkg="tf2_ros" type="static_transform_publisher" name="bl_imu"
        args="0 -0.3 0.52 $(arg imu_yaw) 0 1.570796327 base_link imu_link" />
  <node pkg="tf" type="static_transform_publisher" name="bl_laser"
        args="0.2 0 0.3 0 0 0 1 /base_link /laser 100" />
  <node pkg="tf2_ros" type="static_transform_publisher" name="map_odom" args="0 0 0 0 0 0 map odom" />
  <node pkg="robot_localization" type="ekf_localization_node" name="ekf">
    <param name="frequency" value="30"/>
    <param name="odom0" value="/wheels/odom"/>
    <param name="imu0" value="/imu/data"/>
    <param name="two_d_mode" value="true"/>
    <rosparam param="odom0_config">[false, false, false, false, false, false,
                                    true, true, false, false, false, true,
                                    false, false, false]</rosparam>
    <rosparam param="imu0_config">[false, false, false, false, false, true,
                                   false, false, false, false, false, true,
                                   false, false, false]</rosparam>
    <rosparam file="$(find my_robot)/params/more.yaml" command="load"/>
  </node>
  <node pkg="my_tests" type="pose_checker" name="checker"><param name="final_x" value="1.0"/></node>
</launch>
"""


@pytest.fixture
def launch(tmp_path: Path) -> Path:
    p = tmp_path / "robot.launch"
    p.write_text(LAUNCH)
    return p


def test_launch_file_params_and_mounts_carry_over(launch: Path) -> None:
    cfg, notes, text = convert_file("rl", launch)
    src = cfg["sources"]
    assert {n: (s["topic"], s["use"]) for n, s in src["inputs"].items()} == {
        "odom0": ("/wheels/odom", ["vx", "vy", "vyaw"]), "imu0": ("/imu/data", ["yaw", "vyaw"])}
    tfs = {e["child"]: e for e in src["static_transforms"]}
    assert set(tfs) == {"imu_link", "laser"}  # map -> odom is not a mount
    np.testing.assert_allclose(tfs["imu_link"]["rpy_deg"], [90.0, 0.0, -90.0])  # $(arg) substituted
    np.testing.assert_allclose(tfs["laser"]["xyzw"], [0, 0, 0, 1])
    imu, laser = parse_static_transforms(src["static_transforms"])
    np.testing.assert_allclose(imu.rotation_xyzw, [0.5, -0.5, -0.5, 0.5], atol=1e-9)
    assert laser.pose[0] == pytest.approx(0.2) and laser.z == pytest.approx(0.3)
    assert any("map -> odom" in n for n in notes)
    assert any("more.yaml" in n and "not read" in n for n in notes)
    parse_config(yaml.safe_load(text), source="converted")  # the written file is a valid config


def test_a_broken_launch_file_is_one_line(tmp_path: Path) -> None:
    p = tmp_path / "bad.launch"
    p.write_text("<launch><node name='x'></launch>")
    with pytest.raises(ConfigError, match="does not parse as XML") as e:
        convert_file("rl", p)
    assert "\n" not in str(e.value)


def test_pre_indigo_12_value_vectors(tmp_path: Path) -> None:
    """hydro / groovy: _config vectors and process noise of 12 variables (no accelerations)."""
    p = tmp_path / "groovy.launch"
    q = np.diag(np.arange(1, 13) / 100.0)
    p.write_text(f"""<launch><node pkg="robot_localization" type="ekf_localization_node" name="ekf">
      <param name="odom0" value="/ardrone/odometry/raw"/>
      <param name="imu0" value="/ardrone/imu"/>
      <rosparam param="odom0_config">[false, false, true, false, false, false,
                                      true, true, false, false, false, true]</rosparam>
      <rosparam param="imu0_config">[false, false, false, true, true, true,
                                     false, false, false, true, true, true]</rosparam>
      <rosparam param="process_noise_covariance">{q.reshape(-1).tolist()}</rosparam>
    </node></launch>""")
    cfg, notes, _ = convert_file("rl", p)
    assert {n: s["use"] for n, s in cfg["sources"]["inputs"].items()} == {"odom0": ["vx", "vy", "vyaw"],
                                                                           "imu0": ["yaw", "vyaw", "roll", "pitch"]}
    assert not any("expected 15" in n or "not a 15 x 15" in n for n in notes)
    assert cfg["ekf"] == {"q_xy": 0.02, "q_theta": 0.06, "q_v": 0.08, "q_w": 0.12}


def test_nav2_left_out_parameters_take_the_nodes_defaults(tmp_path: Path) -> None:
    """A nav2 file naming only a few parameters: the rest are nav2_amcl's defaults, not fgloc's; a
    ROS 1 amcl launch file: its names and ROS 1 amcl's defaults; several scan topics: one note."""
    from fgloc.porting import from_nav2

    cfg, notes = from_nav2({"amcl": {"ros__parameters": {"z_hit": 0.6, "max_particles": 3000,
                                                         "scan_topic": "front_scan rear_scan"}}})
    a = parse_config(cfg).frontends.amcl
    assert (a.robot_model_type, a.alpha1, a.alpha5, a.sigma_hit, a.update_min_d) == ("differential", 0.2, 0.2,
                                                                                       0.2, 0.25)
    assert (a.z_hit, a.max_particles, a.laser_model_type, a.laser_max_range) == (0.6, 3000, "likelihood_field", 100.0)
    assert sum("nav2_amcl's defaults" in n for n in notes) == 1
    assert any("one laser: pass --scan-topic front_scan to fgloc run" in n for n in notes)
    p = tmp_path / "amcl.launch"
    p.write_text("""<launch><node pkg="amcl" type="amcl" name="amcl">
      <param name="odom_model_type" value="omni-corrected"/><param name="odom_alpha1" value="0.1"/>
      <param name="laser_z_hit" value="0.9"/><param name="kld_err" value="0.02"/>
      <param name="update_min_d" value="0.1"/><param name="laser_model_type" value="likelihood_field"/>
    </node></launch>""")
    cfg, notes, _ = convert_file("nav2", p)
    a = parse_config(cfg).frontends.amcl
    assert (a.robot_model_type, a.alpha1, a.alpha2, a.z_hit, a.z_rand, a.pf_err) == ("omni", 0.1, 0.2, 0.9, 0.05, 0.02)
    assert (a.min_particles, a.max_particles, a.resample_interval, a.laser_max_beams) == (100, 5000, 2, 30)
    assert not any(n.startswith(("odom_alpha1", "laser_z_hit", "kld_err")) for n in notes)


def test_no_source_of_motion_is_a_one_line_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """An r_l file whose odometry's _config is misspelt: robot_localization fuses nothing from it, and
    the converted config would not move the robot: exit 2 with the suggestion, nothing written."""
    from fgloc.cli import main

    p = tmp_path / "ekf.yaml"
    vel = [False] * 6 + [True, True, False, False, False, True] + [False] * 3
    p.write_text(yaml.safe_dump({"ekf_node": {"ros__parameters": {
        "odom0": "/wheel/odom", "odom0_confg": vel,
        "imu0": "/imu", "imu0_config": [False] * 5 + [True] + [False] * 9}}}))
    assert main(["config", "from-robot-localization", str(p), "-o", str(tmp_path / "out.yaml")]) == 2
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert err.count("\n") == 0
    assert err == (f"fgloc: error: {p}: the converted config has no source of motion (no input fgloc reads gives "
                   "x, y, vx or vy): odom0 (/wheel/odom): no odom0_config, so robot_localization fuses nothing "
                   "from it; skipped (odom0_confg: did you mean odom0_config?)")
    assert "not carried over: odom0 (/wheel/odom)" in captured.out
    assert not (tmp_path / "out.yaml").exists()


def test_mounts_on_the_filters_own_base_frame_carry_over_with_it(tmp_path: Path) -> None:
    """r_l's groovy test_bag1 launch: base_link_frame mustang_base, the IMU mounts published from
    it (one rolled 180 deg): carried over on mustang_base, which is the config's sources.base_frame;
    odom -> x is still no mount."""
    p = tmp_path / "mustang.test"
    p.write_text("""<launch>
  <node pkg="tf" type="static_transform_publisher" name="w" args="0 0 0 0 0 0 odom wheel_odometry 20" />
  <node pkg="tf" type="static_transform_publisher" name="x" args="0 0 0 0 0 3.141592654 mustang_base xsens 20" />
  <node pkg="robot_localization" type="ekf_localization_node" name="ekf">
    <param name="imu0" value="/xsens/imu_data"/>
    <param name="base_link_frame" value="mustang_base"/>
    <rosparam param="imu0_config">[false, false, false, false, false, true,
                                   false, false, false, false, false, true]</rosparam>
  </node>
</launch>
""")
    cfg, notes, _ = convert_file("rl", p)
    (tf,) = cfg["sources"]["static_transforms"]
    assert (tf["parent"], tf["child"]) == ("mustang_base", "xsens") and cfg["sources"]["base_frame"] == "mustang_base"
    np.testing.assert_allclose(tf["rpy_deg"], [180.0, 0.0, 0.0])
    assert not any("xsens" in n for n in notes), notes
    assert any("odom -> wheel_odometry is not a sensor mount" in n for n in notes)
    assert cfg["sources"]["inputs"]["imu0"]["use"] == ["yaw", "vyaw"]  # 12-element (groovy) vector
