"""A ROS 1 bag written with rosbags' own writer and serializer converts with equal values."""

from __future__ import annotations

import numpy as np
import pytest

from fgloc.cli import main
from fgloc.geometry import yaw_to_quaternion
from fgloc.io import open_log
from fgloc.io.convert import import_log
from fgloc.types import Imu, LaserScan, Odometry

N = 15
T0 = 1_600_000_000


def _write_bag(path, scan_topic="/base_scan"):
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    if "tf2_msgs/msg/TFMessage" not in ts.fielddefs:
        ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
    T = ts.types
    Time, Header = T["builtin_interfaces/msg/Time"], T["std_msgs/msg/Header"]
    V3, Q = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]
    Point, Pose = T["geometry_msgs/msg/Point"], T["geometry_msgs/msg/Pose"]

    def quat(yaw):
        q = yaw_to_quaternion(yaw)
        return Q(x=q[0], y=q[1], z=q[2], w=q[3])

    def hdr(sec, nsec, frame):
        return Header(seq=0, stamp=Time(sec=sec, nanosec=nsec), frame_id=frame)

    def tf(sec, parent, child, x, y, z, yaw):
        return T["tf2_msgs/msg/TFMessage"](transforms=[T["geometry_msgs/msg/TransformStamped"](
            header=hdr(sec, 0, parent), child_frame_id=child,
            transform=T["geometry_msgs/msg/Transform"](translation=V3(x=x, y=y, z=z), rotation=quat(yaw)))])

    expected = []
    with Writer(path) as w:
        c = {
            "scan": w.add_connection(scan_topic, "sensor_msgs/msg/LaserScan", typestore=ts),
            "odom": w.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=ts),
            "imu": w.add_connection("/imu", "sensor_msgs/msg/Imu", typestore=ts),
            "tfs": w.add_connection("/tf_static", "tf2_msgs/msg/TFMessage", typestore=ts, latching=1),
            "tf": w.add_connection("/tf", "tf2_msgs/msg/TFMessage", typestore=ts),
        }

        def put(key, sec, nsec, msg):
            w.write(c[key], sec * 10**9 + nsec, ts.serialize_ros1(msg, msg.__msgtype__))

        put("tfs", T0, 0, tf(T0, "base_link", "laser", 0.3, -0.05, 0.2, 0.1))
        for i in range(N):
            sec, nsec = T0 + i, 123_456_789 + i
            ranges = np.linspace(0.5, 8.0, 91).astype(np.float32)
            ranges[3], ranges[4], ranges[5] = np.inf, -np.inf, np.nan
            scan = T["sensor_msgs/msg/LaserScan"](
                header=hdr(sec, nsec, "laser"), angle_min=-1.5, angle_max=1.5, angle_increment=3.0 / 90,
                time_increment=1e-4, scan_time=0.1, range_min=0.1, range_max=30.0,
                ranges=ranges, intensities=np.zeros(0, np.float32))
            put("scan", sec, nsec, scan)
            pcov = np.zeros(36)
            pcov[0], pcov[7], pcov[35] = 0.01, 0.02, 0.03
            tcov = np.zeros(36)
            tcov[0], tcov[7], tcov[35], tcov[5], tcov[30] = 1e-3, 2e-3, 3e-3, 1e-4, 1e-4
            odom = T["nav_msgs/msg/Odometry"](
                header=hdr(sec, nsec + 1000, "odom"), child_frame_id="base_link",
                pose=T["geometry_msgs/msg/PoseWithCovariance"](
                    pose=Pose(position=Point(x=0.1 * i, y=1.0, z=0.0), orientation=quat(0.05 * i)),
                    covariance=pcov),
                twist=T["geometry_msgs/msg/TwistWithCovariance"](
                    twist=T["geometry_msgs/msg/Twist"](linear=V3(x=0.5, y=0.01, z=0.0),
                                                       angular=V3(x=0.0, y=0.0, z=0.05)),
                    covariance=tcov))
            put("odom", sec, nsec + 1000, odom)
            ocov = np.zeros(9)
            ocov[8] = 4e-4
            wcov = np.zeros(9)
            wcov[8] = 1e-6
            imu = T["sensor_msgs/msg/Imu"](
                header=hdr(sec, nsec + 2000, "imu"), orientation=quat(-0.2 + 0.01 * i),
                orientation_covariance=ocov, angular_velocity=V3(x=0.0, y=0.0, z=0.05),
                angular_velocity_covariance=wcov, linear_acceleration=V3(x=0.0, y=0.0, z=9.8),
                linear_acceleration_covariance=np.full(9, -1.0) * np.eye(3).ravel())
            put("imu", sec, nsec + 2000, imu)
            put("tf", sec, nsec + 3000, tf(sec, "odom", "base_link", 0.1 * i, 1.0, 0.0, 0.05 * i))
            expected.append((sec, nsec, ranges, i))
    return expected


def test_bag_converts_with_equal_values(tmp_path):
    bag = tmp_path / "run.bag"
    expected = _write_bag(bag)
    from fgloc.io.topics import Topics

    res = import_log(bag, tmp_path / "run.mcap", Topics(scan="/base_scan"), progress=False)
    assert res.format == "rosbag1"
    assert res.counts == {"/scan": N, "/odom": N, "/imu": N, "/tf_static": 1, "/tf": N}
    r = open_log(res.dst)
    scans = [m for t, m in r.messages({"/scan"})]
    odoms = [m for t, m in r.messages({"/odom"})]
    imus = [m for t, m in r.messages({"/imu"})]
    for (sec, nsec, ranges, i), s, o, c in zip(expected, scans, odoms, imus, strict=True):
        assert isinstance(s, LaserScan) and isinstance(o, Odometry) and isinstance(c, Imu)
        assert s.stamp == sec + nsec * 1e-9
        np.testing.assert_array_equal(s.ranges, ranges)
        assert (s.angle_min, s.range_max, s.frame_id) == (-1.5, 30.0, "laser")
        assert s.angle_increment == pytest.approx(3.0 / 90, rel=1e-7)
        assert s.intensities is None
        assert o.stamp == sec + (nsec + 1000) * 1e-9
        assert o.pose == pytest.approx([0.1 * i, 1.0, 0.05 * i], abs=1e-12)
        assert o.twist == pytest.approx([0.5, 0.01, 0.05])
        np.testing.assert_allclose(o.twist_cov, [[1e-3, 0, 1e-4], [0, 2e-3, 0], [1e-4, 0, 3e-3]])
        np.testing.assert_allclose(o.pose_cov, np.diag([0.01, 0.02, 0.03]))
        # the whole Imu: orientation, rates, REP 145's absent acceleration (covariance[0] = -1)
        assert c.angular_velocity_radps is not None and c.angular_velocity_radps.tolist() == [0.0, 0.0, 0.05]
        assert c.linear_acceleration_mps2 is None and c.linear_acceleration_cov is None
        np.testing.assert_array_equal(c.orientation_cov, np.diag([0.0, 0.0, 4e-4]))
        h = c.heading()
        assert h.yaw_rad == pytest.approx(-0.2 + 0.01 * i, abs=1e-12)
        assert (h.yaw_rate_radps, h.yaw_var, h.yaw_rate_var) == (0.05, 4e-4, 1e-6)
    mount = r.laser_mount()
    assert (mount.parent, mount.child) == ("base_link", "laser")
    assert mount.pose == pytest.approx([0.3, -0.05, 0.1]) and mount.z == pytest.approx(0.2)


def test_bag_topics_keep_their_names_unless_renamed(tmp_path, capsys):
    """fgloc import keeps every topic's name (a config ported from the robot's own setup still fits);
    --rename OLD=NEW renames, and says so."""
    bag = tmp_path / "run.bag"
    _write_bag(bag, scan_topic="/front_laser")
    out = tmp_path / "o.mcap"
    assert main(["import", str(bag), "-o", str(out)]) == 0
    stdout = capsys.readouterr().out
    assert f"/front_laser: {N}" in stdout and "rosbag1" in stdout and "dropped" not in stdout
    assert open_log(out).summary()["topics"]["/front_laser"]["count"] == N
    assert main(["import", str(bag), "-o", str(out), "--rename", "front_laser=/scan"]) == 0
    stdout = capsys.readouterr().out
    assert "renamed: /front_laser -> /scan" in stdout
    assert set(open_log(out).summary()["topics"]) == {"/scan", "/odom", "/imu", "/tf", "/tf_static"}
    assert main(["import", str(bag), "-o", str(out), "--rename", "/front_laser"]) == 2
    assert capsys.readouterr().err.strip() == ("fgloc: error: --rename /front_laser: give OLD=NEW, e.g. "
                                               "--rename /imu/data=/imu")
    assert main(["import", str(bag), "-o", str(out), "--topic", "/imu"]) == 0
    stdout = capsys.readouterr().out
    assert f"(/imu: {N})" in stdout and f"dropped: /odom: {N} message(s), not asked for (--topic)" in stdout


def test_other_types_are_kept_and_nothing_is_dropped_silently(shared_data, tmp_path, capsys):
    """robot_localization's Husky bag: /fix (sensor_msgs/NavSatFix, a type fgloc does not read) is
    converted by rosbags and kept, with every name as recorded."""
    bag = shared_data / "robot_localization" / "test1.bag"
    out = tmp_path / "t1.mcap"
    assert main(["import", str(bag), "-o", str(out)]) == 0
    stdout = capsys.readouterr().out
    assert "(/fix: 989, /husky_velocity_controller/odom: 3952, /imu/data: 11865)" in stdout
    assert "dropped" not in stdout
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    with out.open("rb") as fh:
        fixes = [m for _s, c, _r, m in make_reader(fh, decoder_factories=[DecoderFactory()]).iter_decoded_messages(
            topics=["/fix"])]
    assert len(fixes) == 989 and 40 < fixes[0].latitude < 50 and fixes[0].header.frame_id


def test_a_type_that_cannot_be_copied_is_counted_and_named(tmp_path, capsys):
    """A ROS 1-encoded MCAP's topic of a type fgloc does not read cannot be written as ROS 2: it is
    listed as dropped, with its count and the reason."""
    from mcap.writer import Writer as McapWriter

    bag = tmp_path / "run.bag"
    _write_bag(bag)
    mid = tmp_path / "ros1.mcap"
    # the same messages in an MCAP of ROS 1 encoding, plus a std_msgs/String topic
    from rosbags.rosbag1 import Reader

    with Reader(bag) as r, mid.open("wb") as fh:
        w = McapWriter(fh)
        w.start("ros1", "test")
        ids = {}
        for c in r.connections:
            sid = w.register_schema(c.msgtype.replace("/msg/", "/"), "ros1msg", c.msgdef.data.encode())
            ids[c.id] = w.register_channel(c.topic, "ros1", sid)
        sid = w.register_schema("std_msgs/String", "ros1msg", b"string data")
        chatter = w.register_channel("/chatter", "ros1", sid)
        for c, t, raw in r.messages():
            w.add_message(ids[c.id], t, bytes(raw), t)
        for k in range(3):
            w.add_message(chatter, 1_000_000_000 + k, (2).to_bytes(4, "little") + b"hi", 1_000_000_000 + k)
        w.finish()
    assert main(["import", str(mid), "-o", str(tmp_path / "o.mcap")]) == 0
    stdout = capsys.readouterr().out
    assert "dropped: /chatter: 3 message(s), type std_msgs/msg/String that fgloc does not read" in stdout
    assert f"/base_scan: {N}" in stdout


def test_bag_without_usable_topics(tmp_path, capsys):
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    bag = tmp_path / "chatter.bag"
    with Writer(bag) as w:
        c = w.add_connection("/chatter", "std_msgs/msg/String", typestore=ts)
        w.write(c, 1, ts.serialize_ros1(ts.types["std_msgs/msg/String"](data="hi"), "std_msgs/msg/String"))
    assert main(["import", str(bag), "-o", str(tmp_path / "o.mcap")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "/chatter (std_msgs/msg/String)" in err and str(bag) in err


def test_bag_named_topic_missing(tmp_path, capsys):
    bag = tmp_path / "run.bag"
    _write_bag(bag)
    assert main(["import", str(bag), "-o", str(tmp_path / "o.mcap"), "--scan-topic", "/laser_front"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert str(bag) in err and "'/laser_front'" in err and "/base_scan, /imu, /odom, /tf, /tf_static" in err
    assert main(["info", str(bag)]) == 0  # info reads bags directly
    out = capsys.readouterr().out
    assert "rosbag1, 61 messages" in out and "/base_scan        15  sensor_msgs/msg/LaserScan" in out
