"""MCAP logs in ROS 1 encoding: what the ``mcap`` command line's ``convert`` writes from a bag.

Each ROS 1 connection becomes a channel with ``message_encoding: ros1`` and a schema named as
the bag names the type (``sensor_msgs/LaserScan``), encoding ``ros1msg``, holding the
connection's whole definition (``MSG:`` sections).  The test writes a ROS 1 bag with rosbags,
copies it into such an MCAP with the ``mcap`` writer, and reads both.
"""

from __future__ import annotations

import logging

import numpy as np
import pytest

from fgloc.cli import main
from fgloc.io import open_log
from fgloc.types import Imu, LaserScan, Odometry

N = 10
T0 = 1_552_909_053


def _bag(path):
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf/msg/tfMessage"))
    T = ts.types
    Time, Header = T["builtin_interfaces/msg/Time"], T["std_msgs/msg/Header"]
    V3, Q = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]
    with Writer(path) as w:
        c = {topic: w.add_connection(topic, typ, typestore=ts) for topic, typ in (
            ("/scan", "sensor_msgs/msg/LaserScan"), ("/odom", "nav_msgs/msg/Odometry"),
            ("/imu", "sensor_msgs/msg/Imu"), ("/tf", "tf/msg/tfMessage"))}
        for i in range(N):
            ns = T0 * 10**9 + i * 100_000_000
            hdr = Header(seq=i, stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id="laser")
            msgs = {
                "/scan": T["sensor_msgs/msg/LaserScan"](
                    header=hdr, angle_min=-3.12, angle_max=3.14, angle_increment=0.0175, time_increment=0.0,
                    scan_time=0.135, range_min=0.15, range_max=12.0,
                    ranges=np.linspace(0.5, 6.0, 360).astype(np.float32) + np.float32(0.01 * i),
                    intensities=np.zeros(0, np.float32)),
                "/odom": T["nav_msgs/msg/Odometry"](
                    header=Header(seq=i, stamp=hdr.stamp, frame_id="odom"), child_frame_id="base_footprint",
                    pose=T["geometry_msgs/msg/PoseWithCovariance"](
                        pose=T["geometry_msgs/msg/Pose"](
                            position=T["geometry_msgs/msg/Point"](x=0.05 * i, y=0.0, z=0.0),
                            orientation=Q(x=0.0, y=0.0, z=0.0, w=1.0)),
                        covariance=np.zeros(36)),
                    twist=T["geometry_msgs/msg/TwistWithCovariance"](
                        twist=T["geometry_msgs/msg/Twist"](linear=V3(x=0.5, y=0.0, z=0.0),
                                                           angular=V3(x=0.0, y=0.0, z=0.1)),
                        covariance=np.zeros(36))),
                "/imu": T["sensor_msgs/msg/Imu"](
                    header=Header(seq=i, stamp=hdr.stamp, frame_id="imu_link"),
                    orientation=Q(x=0.0, y=0.0, z=0.0, w=1.0), orientation_covariance=np.zeros(9),
                    angular_velocity=V3(x=0.0, y=0.0, z=0.1), angular_velocity_covariance=np.zeros(9),
                    linear_acceleration=V3(x=0.0, y=0.0, z=9.8), linear_acceleration_covariance=np.zeros(9)),
                "/tf": T["tf/msg/tfMessage"](transforms=[T["geometry_msgs/msg/TransformStamped"](
                    header=Header(seq=0, stamp=hdr.stamp, frame_id="base_footprint"), child_frame_id="laser",
                    transform=T["geometry_msgs/msg/Transform"](translation=V3(x=0.2, y=0.0, z=0.15),
                                                               rotation=Q(x=0.0, y=0.0, z=0.0, w=1.0)))]),
            }
            for k, (topic, msg) in enumerate(msgs.items()):
                w.write(c[topic], ns + k * 1000, ts.serialize_ros1(msg, msg.__msgtype__))


def _converted(bag, out):
    """``bag`` as ``mcap convert`` writes it: ros1 channels, ros1msg schemas named ``pkg/Type``."""
    from mcap.writer import Writer
    from rosbags.rosbag1 import Reader

    with Reader(bag) as r, out.open("wb") as f:
        w = Writer(f)
        w.start(profile="ros1", library="test")
        ids = {}
        for c in r.connections:
            sid = w.register_schema(name=c.msgtype.replace("/msg/", "/"), encoding="ros1msg",
                                    data=c.msgdef.data.encode())
            ids[c.id] = w.register_channel(topic=c.topic, message_encoding="ros1", schema_id=sid)
        for c, t, raw in r.messages():
            w.add_message(channel_id=ids[c.id], log_time=t, data=bytes(raw), publish_time=t)
        w.finish()


def _records(path):
    with open_log(path) as src:
        return [(r.topic, r.log_time_ns, r.msg) for r in src.records({"/scan", "/odom", "/imu", "/tf"})]


def test_ros1_encoded_mcap_reads_as_its_bag(tmp_path, caplog):
    bag, mcap = tmp_path / "run.bag", tmp_path / "run.mcap"
    _bag(bag)
    _converted(bag, mcap)
    with caplog.at_level(logging.WARNING):
        src = open_log(mcap)
        got = _records(mcap)
        assert src.laser_mount().pose == pytest.approx([0.2, 0.0, 0.0])
    assert "skipped" not in caplog.text and "robot centre" not in caplog.text
    want = _records(bag)
    assert len(got) == len(want) == 4 * N
    for (ta, na, a), (tb, nb, b) in zip(got, want, strict=True):
        assert (ta, na, type(a)) == (tb, nb, type(b))
        if isinstance(a, LaserScan):
            assert a.stamp == b.stamp and a.frame_id == b.frame_id == "laser"
            np.testing.assert_array_equal(a.ranges, b.ranges)
        elif isinstance(a, Odometry):
            assert a.stamp == b.stamp and np.array_equal(a.pose, b.pose) and np.array_equal(a.twist, b.twist)
        elif isinstance(a, Imu):
            assert a.heading().yaw_rate_radps == b.heading().yaw_rate_radps == pytest.approx(0.1)
        else:
            assert [(x.parent, x.child) for x in a] == [(x.parent, x.child) for x in b] == [("base_footprint", "laser")]
    assert {t: v["type"] for t, v in src.summary()["topics"].items()} == {
        "/scan": "sensor_msgs/msg/LaserScan", "/odom": "nav_msgs/msg/Odometry", "/imu": "sensor_msgs/msg/Imu",
        "/tf": "tf2_msgs/msg/TFMessage"}


def test_run_on_ros1_encoded_mcap(tmp_path, capsys):
    """fgloc run localizes it, and its run.mcap holds the inputs re-encoded as ROS 2 (the
    records carry no CDR bytes to copy)."""
    bag, mcap = tmp_path / "run.bag", tmp_path / "run.mcap"
    _bag(bag)
    _converted(bag, mcap)
    assert main(["run", str(mcap), "-o", str(tmp_path / "out"), "-q"]) == 0
    out = capsys.readouterr().out
    assert f"scans {N}, " in out and f"odometry {N}, imu {N}, " in out
    from mcap.reader import make_reader

    with (tmp_path / "out" / "run.mcap").open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    inputs = {ch.topic: ch.message_encoding for ch in summary.channels.values()
              if ch.topic in ("/scan", "/odom", "/imu", "/tf")}
    assert inputs == {"/scan": "cdr", "/odom": "cdr", "/imu": "cdr"}
    with open_log(tmp_path / "out" / "run.mcap") as src:
        got = [m for _, m in src.messages(["/scan"])]
    assert len(got) == N
    np.testing.assert_allclose(got[-1].ranges, np.linspace(0.5, 6.0, 360).astype(np.float32) + np.float32(0.09))


def test_import_converts_an_mcap(tmp_path, capsys):
    """fgloc import takes an MCAP like a bag (it said "already an MCAP log; nothing to import",
    though run reads it): a ROS 1-encoded one comes out in ROS 2 (cdr) with the bag's records."""
    bag, mcap = tmp_path / "run.bag", tmp_path / "run.mcap"
    _bag(bag)
    _converted(bag, mcap)
    out = tmp_path / "imported.mcap"
    assert main(["import", str(mcap), "-o", str(out)]) == 0
    assert "imported mcap run.mcap" in capsys.readouterr().out
    from mcap.reader import make_reader

    with out.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    assert {ch.topic: ch.message_encoding for ch in summary.channels.values()} == {
        "/scan": "cdr", "/odom": "cdr", "/imu": "cdr", "/tf": "cdr"}
    got, want = _records(out), _records(bag)
    assert [(t, n, type(m)) for t, n, m in got] == [(t, n, type(m)) for t, n, m in want]
    assert main(["import", str(out), "-o", str(out), "--force"]) == 2   # never the input itself
    assert "is the input" in capsys.readouterr().err
