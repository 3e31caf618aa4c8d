"""A log that recorded a state estimator (robot_localization's ``/odometry/filtered``) with its inputs
has two nav_msgs/Odometry topics.  Without a configuration fgloc used neither ("no odometry ... name the
odometry topic"); it now fuses the wheels' own odometry and names the filter's output as the peer to
compare with.  A log whose only Odometry topic is a filter's output is used, and said to be one."""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest

from fgloc.io.topics import ODOMETRY, Topics, choose_topics, estimator_output, peer_output, truth_output

T0 = 1_700_000_000
N = 200  # 10 s at 20 Hz


@pytest.mark.parametrize("topic", ["/odometry/filtered", "/odometry/filtered_map", "odometry/filtered",
                                   "/odom/filtered", "/odom_filtered", "/filtered_odom", "/odometry/local",
                                   "/odometry/global", "/odometry/gps", "/robot_pose_ekf/odom_combined",
                                   "/jackal0/odometry/filtered"])
def test_filter_outputs_by_name(topic):
    assert estimator_output(topic)


@pytest.mark.parametrize("topic", ["/odom", "/wheel/odometry", "/husky_velocity_controller/odom", "/odometry",
                                   "/odometry/wheel", "/camera/odom/sample", "/pose", "/ground_truth"])
def test_sensor_odometry_by_name(topic):
    assert not estimator_output(topic)


def test_the_wheels_are_chosen_beside_a_filter():
    two = {"/wheel/odometry": ODOMETRY, "/odometry/filtered": ODOMETRY, "/odometry/gps": ODOMETRY}
    assert choose_topics(two, Topics(), "x.bag") == {"/wheel/odometry": "odom"}
    both_raw = {"/wheel/odometry": ODOMETRY, "/visual/odometry": ODOMETRY, "/odometry/filtered": ODOMETRY}
    assert choose_topics(both_raw, Topics(), "x.bag") == {}  # two sensors: the user names one
    assert choose_topics({"/odometry/filtered": ODOMETRY}, Topics(), "x.bag") == {"/odometry/filtered": "odom"}


def _write(path, topics: dict[str, tuple[float, float]]) -> None:
    """A ROS 1 bag: each topic a straight 0.5 m/s drive from the origin in direction (dx, dy)."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    T = ts.types
    with Writer(path) as w:
        conns = {t: w.add_connection(t, "nav_msgs/msg/Odometry", typestore=ts) for t in topics}
        for i in range(N):
            ns = T0 * 10**9 + i * 50_000_000
            for t, (dx, dy) in topics.items():
                yaw = math.atan2(dy, dx)
                d = 0.5 * i * 0.05
                hdr = T["std_msgs/msg/Header"](seq=i, stamp=T["builtin_interfaces/msg/Time"](sec=ns // 10**9,
                                               nanosec=ns % 10**9), frame_id="odom")
                pose = T["geometry_msgs/msg/Pose"](
                    position=T["geometry_msgs/msg/Point"](x=d * dx, y=d * dy, z=0.0),
                    orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2),
                                                                  w=math.cos(yaw / 2)))
                cov = np.diag([1e-3, 1e-3, 1e6, 1e6, 1e6, 1e-3]).ravel()
                vec = T["geometry_msgs/msg/Vector3"]
                twist = T["geometry_msgs/msg/Twist"](linear=vec(x=0.5, y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=0.0))
                msg = T["nav_msgs/msg/Odometry"](
                    header=hdr, child_frame_id="base_link",
                    pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=cov),
                    twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=cov))
                w.write(conns[t], ns, ts.serialize_ros1(msg, "nav_msgs/msg/Odometry"))


def _run(log, out, caplog) -> tuple[np.ndarray, str]:
    from fgloc.cli import main

    with caplog.at_level(logging.WARNING):
        rc = main(["run", str(log), "-o", str(out), "-q", "--backend", "ekf"])
    assert rc == 0, caplog.text
    return np.loadtxt(out / "trajectory.tum"), caplog.text


@pytest.mark.parametrize("wheels, peer, said_peer, hint", [
    ("/wheel/odometry", "/odometry/filtered", "named as filters' outputs (/odometry/filtered)", ""),
    ("/mobile_base_controller/odom", "/gazebo_odom", "named as ground truths (/gazebo_odom)", " --align-start"),
])
def test_run_fuses_the_wheels_and_names_the_peer(tmp_path, caplog, wheels, peer, said_peer, hint):
    """A filter's output (r_l's /odometry/filtered) or a simulator's truth (Gazebo's /gazebo_odom) beside the
    wheels: the wheels are fused, the other is named as the reference to compare with."""
    log = tmp_path / "peer.bag"
    _write(log, {wheels: (1.0, 0.0), peer: (0.0, 1.0)})
    tr, said = _run(log, tmp_path / "o", caplog)
    end = tr[-1, 1:3]
    assert end[0] > 4.5 and abs(end[1]) < 0.05, end  # along x, as the wheels went (the peer's copy went along y)
    assert f"using {wheels}" in said and said_peer in said
    assert f"fgloc eval OUT/trajectory.tum {log}:{peer}{hint}" in said


@pytest.mark.parametrize("topic, kind", [("/odometry/filtered", "a filter's output"),
                                         ("/ground_truth/state", "a ground truth")])
def test_a_peer_as_the_only_odometry_is_said_to_be_one(tmp_path, caplog, topic, kind):
    log = tmp_path / "only.bag"
    _write(log, {topic: (0.0, 1.0)})
    tr, said = _run(log, tmp_path / "o", caplog)
    assert math.hypot(*(tr[-1, 1:3] - tr[0, 1:3])) > 4.5  # it drove on that odometry
    assert f"using {topic}" in said and f"named as {kind}" in said


@pytest.mark.parametrize("topic", ["/gazebo_odom", "/ground_truth/state", "/base_pose_ground_truth",
                                   "/ground_truth_odom", "/odom_gt", "/gt/odom", "/vicon/jackal/odom",
                                   "/mocap_node/robot/odom", "/odom/truth"])
def test_ground_truths_by_name(topic):
    assert truth_output(topic) and peer_output(topic) == "a ground truth"


@pytest.mark.parametrize("topic", ["/odom", "/wheel/odometry", "/husky_velocity_controller/odom",
                                   "/elektron/mobile_base_controller/odom", "/rf2o/odom", "/t265/odom/sample",
                                   "/tgt_odom", "/odometry/filtered"])
def test_sensor_or_filter_odometry_is_no_truth(topic):
    assert not truth_output(topic)


def test_the_wheels_are_chosen_beside_a_ground_truth():
    """A simulated log with the simulator's truth beside the wheels (Gazebo's p3d plugin, as a course's
    Elektron bags record /gazebo_odom beside /elektron/mobile_base_controller/odom)."""
    sim = {"/elektron/mobile_base_controller/odom": ODOMETRY, "/gazebo_odom": ODOMETRY}
    assert choose_topics(sim, Topics(), "x.bag") == {"/elektron/mobile_base_controller/odom": "odom"}
    three = {"/wheel/odom": ODOMETRY, "/ground_truth/state": ODOMETRY, "/odometry/filtered": ODOMETRY}
    assert choose_topics(three, Topics(), "x.bag") == {"/wheel/odom": "odom"}
