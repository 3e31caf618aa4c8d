"""MCAP write -> read gives equal messages of every type, in time order."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fgloc.frames.static import transform_of
from fgloc.io import open_log
from fgloc.io.mcap_writer import LogWriter
from fgloc.io.msgdefs import SEPARATOR, full_text
from fgloc.io.ros import stamp_to_ns
from fgloc.io.topics import Topics
from fgloc.types import CompassHeading, Imu, LaserScan, Odometry, PoseFix, StaticTransform, Transform3D

T0 = 1_700_000_000.0


def _stamp(i: int, k: int) -> float:
    # sec + nanosec with odd nanoseconds so rounding errors would show
    return T0 + i + (k * 1_000_003 + 7) * 1e-9


def _messages(n: int = 20) -> list[tuple[str, object]]:
    rng = np.random.default_rng(1)
    out: list[tuple[str, object]] = [
        ("/tf_static", [StaticTransform("base_link", "laser", np.array([0.25, -0.1, 0.3]), z=0.4),
                        # an IMU turned 90 deg about x, then yawed: its whole rotation survives
                        transform_of("base_link", "imu_link", [0.0, 0.1, 0.2],
                                     [0.6532815, 0.2705981, 0.2705981, 0.6532815])])
    ]
    for i in range(n):
        r = rng.uniform(0.1, 20.0, 271).astype(np.float32)
        r[[0, 5]] = np.inf
        r[1] = -np.inf
        r[2] = np.nan
        out.append(("/scan", LaserScan(
            stamp=_stamp(i, 1), angle_min=-2.356194, angle_increment=0.0174533, range_min=0.5,
            range_max=50.0, ranges=r, time_increment=1e-4, scan_time=0.04,
            intensities=rng.uniform(0, 100, 271).astype(np.float32), frame_id="laser")))
        tc = np.diag([1e-3, 2e-3, 3e-3])
        tc[0, 2] = tc[2, 0] = 1e-4
        out.append(("/odom", Odometry(
            stamp=_stamp(i, 2), twist=np.array([0.8, -0.05, 0.1]), twist_cov=tc,
            pose=np.array([i * 0.1, 2.0, 0.3]), pose_cov=np.diag([0.01, 0.02, 0.03]))))
        out.append(("/imu", CompassHeading(
            stamp=_stamp(i, 3), yaw_rad=0.5 - i * 0.01, yaw_rate_radps=0.02,
            yaw_var=3e-4, yaw_rate_var=1e-5, frame_id="compass")))
        out.append(("/ground_truth", Odometry(
            stamp=_stamp(i, 4), twist=np.zeros(3), pose=np.array([i * 0.1, 2.0, -3.0]), frame_id="map")))
        out.append(("/fused_pose", PoseFix(
            stamp=_stamp(i, 5), pose=np.array([1.0, 2.0, 3.0 - i * 0.1]), cov=np.diag([0.1, 0.2, 0.05]),
            frame_id="map")))
        q = np.array([0.02, -0.03, math.sin(0.2 + 0.01 * i), math.cos(0.2 + 0.01 * i)])
        out.append(("/imu", Imu(
            stamp=_stamp(i, 6), orientation_xyzw=q / np.linalg.norm(q),
            angular_velocity_radps=np.array([0.01, -0.02, 0.3]),
            orientation_cov=np.diag([1e-4, 2e-4, 3e-3]), angular_velocity_cov=np.diag([1e-6, 2e-6, 3e-6]),
            linear_acceleration_mps2=np.array([0.1, 0.2, 9.81]), linear_acceleration_cov=np.eye(3) * 1e-2,
            frame_id="imu_link")))
    # sensors that leave fields out
    out.append(("/imu", CompassHeading(stamp=_stamp(n, 1), yaw_rad=None, yaw_rate_radps=0.3)))
    out.append(("/imu", CompassHeading(stamp=_stamp(n, 2), yaw_rad=1.0, yaw_rate_radps=None)))
    out.append(("/odom", Odometry(stamp=_stamp(n, 3), twist=np.array([0.1, 0.0, 0.0]))))
    out.append(("/imu", Imu(stamp=_stamp(n, 4), orientation_xyzw=None, angular_velocity_radps=np.zeros(3))))
    return out


def _assert_equal(a: object, b: object) -> None:
    if isinstance(a, CompassHeading):  # written yaw-only, read back as the whole Imu it is
        assert isinstance(b, Imu)
        b = b.heading()
    assert type(a) is type(b)
    if isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b)
        for x, y in zip(a, b, strict=True):
            assert (x.parent, x.child) == (y.parent, y.child)
            np.testing.assert_allclose(x.pose, y.pose, atol=1e-12)
            assert x.z == y.z
            assert isinstance(y, Transform3D) and y.rotation_xyzw is not None  # read with its whole rotation
            if isinstance(x, Transform3D):
                np.testing.assert_array_equal(y.rotation_xyzw, x.rotation_xyzw)
        return
    assert stamp_to_ns(a.stamp) == stamp_to_ns(b.stamp)  # type: ignore[attr-defined]
    if isinstance(a, LaserScan):
        assert isinstance(b, LaserScan)
        np.testing.assert_array_equal(a.ranges, b.ranges)  # inf, -inf and NaN preserved
        assert b.ranges.dtype == np.float32
        np.testing.assert_array_equal(a.intensities, b.intensities)
        for f in ("angle_min", "angle_increment", "range_min", "range_max", "time_increment", "scan_time"):
            assert getattr(b, f) == pytest.approx(getattr(a, f), rel=1e-7)  # float32 fields
        assert a.frame_id == b.frame_id
    elif isinstance(a, Odometry):
        assert isinstance(b, Odometry)
        np.testing.assert_allclose(b.twist, a.twist, atol=0)
        for f in ("twist_cov", "pose_cov"):
            if getattr(a, f) is None:
                assert getattr(b, f) is None
            else:
                np.testing.assert_allclose(getattr(b, f), getattr(a, f), atol=0)
        if a.pose is None:
            assert b.pose is None
        else:
            np.testing.assert_allclose(b.pose, a.pose, atol=1e-12)
        assert (a.frame_id, a.child_frame_id) == (b.frame_id, b.child_frame_id)
    elif isinstance(a, CompassHeading):
        assert isinstance(b, CompassHeading)
        assert (a.yaw_rad is None) == (b.yaw_rad is None)
        if a.yaw_rad is not None:
            assert b.yaw_rad == pytest.approx(a.yaw_rad, abs=1e-12)
        assert b.yaw_rate_radps == a.yaw_rate_radps
        for f in ("yaw_var", "yaw_rate_var"):
            va, vb = getattr(a, f), getattr(b, f)
            assert (math.isnan(va) and math.isnan(vb)) or va == vb
        assert a.frame_id == b.frame_id
    elif isinstance(a, Imu):
        assert isinstance(b, Imu)
        for f in ("orientation_xyzw", "angular_velocity_radps", "linear_acceleration_mps2", "orientation_cov",
                  "angular_velocity_cov", "linear_acceleration_cov"):
            if getattr(a, f) is None:
                assert getattr(b, f) is None, f
            else:
                np.testing.assert_array_equal(getattr(b, f), getattr(a, f))
        assert a.frame_id == b.frame_id
    elif isinstance(a, PoseFix):
        assert isinstance(b, PoseFix)
        np.testing.assert_allclose(b.pose, a.pose, atol=1e-12)
        np.testing.assert_allclose(b.cov, a.cov, atol=0)
        assert a.frame_id == b.frame_id


def test_roundtrip_every_type(tmp_path):
    msgs = _messages()
    path = tmp_path / "rt.mcap"
    with LogWriter(path) as w:
        for topic, m in msgs:
            w.write(topic, m)
    r = open_log(path)
    got = list(r.messages())
    assert len(got) == len(msgs)
    # written in time order, so read back in the same order
    for (ta, a), (tb, b) in zip(msgs, got, strict=True):
        assert ta == tb
        _assert_equal(a, b)
    s = r.summary()
    assert s["topics"]["/scan"] == {"type": "sensor_msgs/msg/LaserScan", "count": 20}
    assert s["topics"]["/imu"]["count"] == 43  # 22 yaw-only, 21 whole
    assert s["truncated"] is None and s["indexed"]
    assert r.laser_mount().pose == pytest.approx([0.25, -0.1, 0.3])
    gt = r.ground_truth()
    assert gt is not None and len(gt) == 20
    assert gt.poses[3] == pytest.approx([0.3, 2.0, -3.0])


def test_time_order_across_topics_and_explicit_stamp(tmp_path):
    path = tmp_path / "order.mcap"
    with LogWriter(path) as w:  # written out of order
        for i in (5, 1, 4, 2, 3):
            w.write("/odom", Odometry(stamp=10.0 + i, twist=np.array([i, 0.0, 0.0])))
            w.write("/imu", CompassHeading(stamp=10.5 + i, yaw_rad=0.1 * i))
        w.write("/odom", Odometry(stamp=0.0, twist=np.zeros(3)), stamp=100.0)
    got = list(open_log(path).messages())
    stamps = [m.stamp for _, m in got]  # type: ignore[attr-defined]
    assert stamps == sorted(stamps)
    assert stamps[-1] == 100.0  # header stamp from the explicit stamp argument
    assert [t for t, _ in got][:2] == ["/odom", "/imu"]


def test_renamed_topics_and_topic_filter(tmp_path):
    path = tmp_path / "renamed.mcap"
    with LogWriter(path) as w:
        for i in range(3):
            w.write("/base_scan", LaserScan(float(i), -1.0, 0.1, 0.1, 10.0, np.ones(21, np.float32)))
            w.write("/wheel_odom", Odometry(float(i) + 0.5, np.zeros(3)))
            w.write("/other", Odometry(float(i) + 0.6, np.zeros(3)))
    r = open_log(path, Topics(scan="/base_scan", odom="/wheel_odom"))
    got = list(r.messages())
    assert [t for t, _ in got] == ["/base_scan", "/wheel_odom"] * 3  # /other ignored
    assert [t for t, _ in r.messages({"/wheel_odom"})] == ["/wheel_odom"] * 3


def test_schema_is_rosbag2_ros2msg(tmp_path):
    from mcap.reader import make_reader

    text = full_text("nav_msgs/msg/Odometry")
    assert text.startswith("std_msgs/Header header\n")
    assert f"\n\n{SEPARATOR}\nMSG: geometry_msgs/PoseWithCovariance\n" in text
    assert "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n" in text
    assert text.count("MSG: geometry_msgs/Vector3") == 1
    path = tmp_path / "s.mcap"
    with LogWriter(path) as w:
        w.write("/odom", Odometry(1.0, np.zeros(3)))
    with path.open("rb") as f:
        rd = make_reader(f)
        assert rd.get_header().profile == "ros2"
        s = rd.get_summary()
        assert s is not None
        (schema,) = s.schemas.values()
        (chan,) = s.channels.values()
    assert (schema.name, schema.encoding, chan.message_encoding) == ("nav_msgs/msg/Odometry", "ros2msg", "cdr")
    assert schema.data.decode() == text


def test_independent_decoder_reads_our_cdr(tmp_path):
    """rosbags (a separate CDR implementation) decodes every message and parses every schema."""
    from mcap.reader import make_reader
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    msgs = _messages(3)
    path = tmp_path / "x.mcap"
    with LogWriter(path) as w:
        for topic, m in msgs:
            w.write(topic, m)
    ts = get_typestore(Stores.ROS2_HUMBLE)
    n = n_odom = 0
    with path.open("rb") as f:
        for schema, channel, message in make_reader(f).iter_messages(log_time_order=False):
            assert schema is not None
            types = get_types_from_msg(schema.data.decode(), schema.name)
            assert schema.name in types and "builtin_interfaces/msg/Time" in types
            ros = ts.deserialize_cdr(message.data, schema.name)
            if channel.topic == "/scan":
                src = next(m for t, m in msgs if t == "/scan" and stamp_to_ns(m.stamp) == message.log_time)
                np.testing.assert_array_equal(ros.ranges, src.ranges)  # type: ignore[attr-defined]
                assert ros.header.stamp.sec * 10**9 + ros.header.stamp.nanosec == message.log_time
            if channel.topic == "/odom" and message.log_time == stamp_to_ns(msgs[2][1].stamp):  # type: ignore[attr-defined]
                assert ros.twist.twist.linear.x == 0.8 and ros.twist.covariance[0] == 1e-3
                n_odom += 1
            n += 1
    assert n == len(msgs) and n_odom == 1


def _mount_log(path, statics, dynamics, frame="laser"):
    with LogWriter(path) as w:
        if statics:
            w.write("/tf_static", statics)
        for i in range(3):
            if dynamics:
                w.write("/tf", dynamics, stamp=float(i))
            w.write("/scan", LaserScan(float(i) + 0.5, -1.0, 0.1, 0.1, 10.0, np.ones(21, np.float32),
                                       frame_id=frame))
    return open_log(path)


def test_laser_mount_chain_tf_fallback_and_identity(tmp_path, caplog):
    a = StaticTransform("base_link", "mast", np.array([0.1, 0.0, math.pi / 2]), z=0.3)
    b = StaticTransform("mast", "laser_link", np.array([0.2, 0.0, 0.0]), z=0.1)
    r = _mount_log(tmp_path / "chain.mcap", [a, b], None, frame="laser_link")
    m = r.laser_mount()  # composed through the scan's frame_id
    assert (m.parent, m.child) == ("base_link", "laser_link")
    assert m.pose == pytest.approx([0.1, 0.2, math.pi / 2]) and m.z == pytest.approx(0.4)
    odom_tf = StaticTransform("odom", "base_link", np.array([5.0, 5.0, 1.0]))
    laser_tf = StaticTransform("base_link", "laser", np.array([-0.2, 0.05, math.pi]))
    r = _mount_log(tmp_path / "tf.mcap", None, [odom_tf, laser_tf])  # only on /tf (old drivers)
    assert r.laser_mount().pose == pytest.approx([-0.2, 0.05, -math.pi])
    r = _mount_log(tmp_path / "none.mcap", None, None)
    with caplog.at_level("WARNING"):
        m = r.laser_mount()
    assert m.pose == pytest.approx([0, 0, 0]) and (m.parent, m.child) == ("base_link", "laser")
    assert any("no transform base_link -> laser" in rec.message for rec in caplog.records)


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_written_file_passes_mcaps_own_reader_with_crcs(tmp_path, compression):
    """fgloc's MCAP writer (its own chunk builder) against the mcap package's reader: CRCs, summary,
    statistics, chunk and message indexes, message order and bytes; raw copies keep their schema."""
    from mcap.reader import NonSeekingReader, make_reader

    msgs = _messages(30)
    path = tmp_path / f"w_{compression}.mcap"
    with LogWriter(path, chunk_size=16 * 1024, compression=compression) as w:
        for topic, m in msgs:
            w.write(topic, m)
        w.write_raw("/other", "my/Type", b"int32 a\n", b"\x00\x01\x00\x00\x07\x00\x00\x00", 5, publish_time_ns=6)
    with path.open("rb") as f:
        rd = make_reader(f, validate_crcs=True)
        s = rd.get_summary()
        assert s is not None and s.statistics is not None
        assert s.statistics.message_count == len(msgs) + 1 == sum(s.statistics.channel_message_counts.values())
        assert s.statistics.chunk_count == len(s.chunk_indexes) > 3
        assert all(ci.message_index_offsets for ci in s.chunk_indexes)
        got = list(rd.iter_messages(log_time_order=True))
    times = [m.log_time for _, _, m in got]
    assert times == sorted(times) and len(got) == len(msgs) + 1
    other = [(s_, c, m) for s_, c, m in got if c.topic == "/other"]
    assert other[0][0].name == "my/Type" and other[0][2].data == b"\x00\x01\x00\x00\x07\x00\x00\x00"
    assert other[0][2].publish_time == 6
    with path.open("rb") as f:  # the data section streamed (the non-seeking reader checks chunk CRCs)
        assert sum(1 for _ in NonSeekingReader(f, validate_crcs=True).iter_messages()) == len(msgs) + 1
    r = open_log(path)
    for (ta, a), (tb, b) in zip(msgs, r.messages(), strict=False):
        assert ta == tb
        _assert_equal(a, b)
