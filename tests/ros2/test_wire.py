"""ROS 2's wire conventions, each rule checked as the rmw layers state it.

Sources (read from their public repositories): rmw_cyclonedds_cpp ``demangle.cpp`` /
``namespace_prefix.hpp`` / ``MessageTypeSupport_impl.hpp`` / ``serdata.cpp`` / ``rmw_node.cpp``
(``create_readwrite_qos``), rmw_fastrtps_shared_cpp ``namespace_prefix.cpp`` / ``TypeSupport_impl.cpp``,
rmw's ``qos_profiles.h``, tf2_ros' ``qos.hpp``, nav2's ``qos_profiles.hpp``, ``amcl_node.cpp`` and
``map_server.cpp``.  The CDR checks use Cyclone DDS' own (de)serializer as the second opinion.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from fgloc.ros2 import names, qos


# ----------------------------------------------------------------------------- names
@pytest.mark.parametrize("ros, dds", [
    ("/scan", "rt/scan"),                      # prefix "rt" + the fully qualified name
    ("/tf_static", "rt/tf_static"),
    ("/fgloc/status", "rt/fgloc/status"),      # namespaces keep their slashes
    ("amcl_pose", "rt/amcl_pose"),             # relative: resolved in the root namespace first
])
def test_topic_names_are_prefixed_like_rmw(ros: str, dds: str) -> None:
    assert names.dds_topic(ros) == dds
    assert names.ros_topic(dds) == names.resolve(ros)


def test_relative_names_resolve_in_the_namespace_and_service_prefixes() -> None:
    assert names.dds_topic("scan", namespace="/robot1") == "rt/robot1/scan"
    assert names.resolve("/a//b/") == "/a/b"
    assert names.dds_topic("/add_two_ints", prefix=names.REQUEST_PREFIX) == "rq/add_two_ints"
    assert names.PREFIXES == ("rt", "rq", "rr")
    # a DDS topic without a ROS prefix is not a ROS topic (rmw's _resolve_prefix returns "")
    assert names.ros_topic("DCPSPublication") is None
    assert names.ros_topic("rt") is None
    assert names.ros_topic("rtx/scan") is None
    with pytest.raises(ValueError):
        names.resolve("~/private")


@pytest.mark.parametrize("ros, dds", [
    ("sensor_msgs/msg/LaserScan", "sensor_msgs::msg::dds_::LaserScan_"),
    ("nav_msgs/Odometry", "nav_msgs::msg::dds_::Odometry_"),
    ("geometry_msgs/msg/PoseWithCovarianceStamped", "geometry_msgs::msg::dds_::PoseWithCovarianceStamped_"),
    ("tf2_msgs/msg/TFMessage", "tf2_msgs::msg::dds_::TFMessage_"),
    ("rosgraph_msgs/msg/Clock", "rosgraph_msgs::msg::dds_::Clock_"),
])
def test_type_names_are_mangled_like_rmw(ros: str, dds: str) -> None:
    assert names.dds_type(ros) == dds
    # demangling: '::' back to '/', 'dds_::' and the trailing '_' dropped
    assert names.ros_type(dds) == (ros if ros.count("/") == 2 else ros.replace("/", "/msg/"))


def test_foreign_dds_types_are_not_demangled() -> None:
    assert names.ros_type("ShapeType") == "ShapeType"             # no dds_:: -> not a ROS type
    assert names.ros_type("pkg::dds_::Thing") == "pkg::dds_::Thing"  # no trailing '_'
    with pytest.raises(ValueError):
        names.dds_type("LaserScan")


# ----------------------------------------------------------------------------- QoS
def test_profiles_are_ros2s() -> None:
    R, B, V, T = qos.RELIABLE, qos.BEST_EFFORT, qos.VOLATILE, qos.TRANSIENT_LOCAL
    # rmw qos_profiles.h
    assert (qos.SENSOR_DATA.reliability, qos.SENSOR_DATA.durability, qos.SENSOR_DATA.depth) == (B, V, 5)
    assert (qos.DEFAULT.reliability, qos.DEFAULT.durability, qos.DEFAULT.depth) == (R, V, 10)
    # tf2_ros qos.hpp: rclcpp::QoS(100) (reliable volatile); static: depth 1 (pub) / 100 (sub), transient local
    assert (qos.TF.reliability, qos.TF.durability, qos.TF.depth) == (R, V, 100)
    assert (qos.TF_STATIC_PUB.durability, qos.TF_STATIC_PUB.depth, qos.TF_STATIC_SUB.depth) == (T, 1, 100)
    # nav2: map_server and amcl_pose LatchedPublisherQoS (reliable, transient local, 1); AMCL's map subscription 3
    assert (qos.LATCHED_PUB.reliability, qos.LATCHED_PUB.durability, qos.LATCHED_PUB.depth) == (R, T, 1)
    assert (qos.MAP_SUB.reliability, qos.MAP_SUB.durability, qos.MAP_SUB.depth) == (R, T, 3)
    assert (qos.CLOCK.reliability, qos.CLOCK.depth) == (B, 1)


def test_requested_offered_matching() -> None:
    assert qos.compatible(qos.DEFAULT, qos.SENSOR_DATA) is None            # best-effort reader: any writer
    assert qos.compatible(qos.SENSOR_DATA, qos.DEFAULT) == "RELIABILITY"   # reliable reader, best-effort writer
    assert qos.compatible(qos.DEFAULT, qos.MAP_SUB) == "DURABILITY"        # latched reader, volatile writer
    assert qos.compatible(qos.LATCHED_PUB, qos.MAP_SUB) is None
    assert qos.compatible(qos.LATCHED_PUB, qos.INITIAL_POSE_SUB) is None   # volatile reader takes a latched writer


def test_dds_qos_is_rmw_cyclonedds() -> None:
    pytest.importorskip("cyclonedds")
    from cyclonedds.qos import Policy

    got = qos.to_dds(qos.LATCHED_PUB)
    assert got[Policy.History] == Policy.History.KeepLast(1)
    assert got[Policy.Durability] == Policy.Durability.TransientLocal
    # rmw_cyclonedds: durability service with the same history for transient local
    assert got[Policy.DurabilityService].history == Policy.History.KeepLast(1)
    assert got[Policy.WriterDataLifecycle] == Policy.WriterDataLifecycle(autodispose=False)
    # the sertype allows XCDR1 only (DDS_DATA_REPRESENTATION_FLAG_XCDR1)
    rep = got[Policy.DataRepresentation]
    assert rep.use_cdrv0_representation and not rep.use_xcdrv2_representation
    assert got[Policy.Reliability].max_blocking_time == int(qos.MAX_BLOCKING_S * 1e9)
    be = qos.to_dds(qos.SENSOR_DATA)
    assert be[Policy.Reliability] == Policy.Reliability.BestEffort
    assert be[Policy.Durability] == Policy.Durability.Volatile
    assert be[Policy.History] == Policy.History.KeepLast(5)


# ----------------------------------------------------------------------------- CDR
def _samples() -> dict[str, object]:
    from fgloc.types import Imu, LaserScan, Odometry, PoseFix, Transform3D

    rng = np.random.default_rng(3)
    ranges = rng.uniform(0.5, 20, 541).astype(np.float32)
    ranges[7] = np.inf
    return {
        "sensor_msgs/msg/LaserScan": LaserScan(12.25, -2.35, 0.0087, 0.5, 50.0, ranges, 1e-5, 0.04, None, "laser"),
        "nav_msgs/msg/Odometry": Odometry(3.5, np.array([0.4, -0.1, 0.2]), np.diag([1e-4, 2e-4, 3e-4]),
                                          np.array([1.0, 2.0, 0.5]), np.diag([0.1, 0.2, 0.3]), "odom", "base_link"),
        "sensor_msgs/msg/Imu": Imu(7.0, np.array([0.0, 0.0, 0.2, math.sqrt(1 - 0.04)]), np.array([0.01, 0.02, 0.3]),
                                   np.eye(3) * 0.01, np.eye(3) * 0.001, np.array([0.1, 0.0, 9.8]), None, "imu_link"),
        "geometry_msgs/msg/PoseWithCovarianceStamped": PoseFix(9.125, np.array([4.0, -1.5, 2.0]),
                                                               np.diag([0.01, 0.02, 0.003]), 1.0, "x", "map"),
        "tf2_msgs/msg/TFMessage": [Transform3D("base_link", "laser", np.array([0.25, 0.03, 0.1]), 0.2,
                                               np.array([0.0, 0.0, math.sin(0.05), math.cos(0.05)]))],
    }


@pytest.mark.parametrize("type_name", list(_samples()))
def test_fgloc_bytes_are_xcdr1_le_and_read_by_cyclone(type_name: str) -> None:
    """fgloc's bytes carry the CDR_LE encapsulation (00 01 00 00: XCDR1, little endian, as rmw_cyclonedds'
    and rmw_fastrtps' serializers write), decode with Cyclone's own deserializer into the same values,
    and Cyclone's XCDR1 serialization of that sample is fgloc's bytes again."""
    pytest.importorskip("cyclonedds")
    from fgloc.ros2 import codec
    from fgloc.ros2.msgtypes import idl_class

    msg = _samples()[type_name]
    stamp = 12.25 if type_name == "tf2_msgs/msg/TFMessage" else None
    t, data = codec.encode(msg, stamp)
    assert t == type_name
    assert data[:4] == b"\x00\x01\x00\x00"
    cls = idl_class(type_name)
    assert cls.__idl_typename__ == names.dds_type(type_name)
    sample = cls.deserialize(data)
    again = sample.serialize(use_version_2=False)
    pad = (-len(data)) % 4
    assert again == data + b"\x00" * pad or again == data
    back = codec.decode(type_name, again, "/x")
    if type_name == "sensor_msgs/msg/LaserScan":
        assert sample.header.frame_id == "laser" and sample.header.stamp.sec == 12
        np.testing.assert_array_equal(back.ranges, msg.ranges)
        assert back.angle_min == pytest.approx(msg.angle_min, abs=1e-6)
    elif type_name == "nav_msgs/msg/Odometry":
        assert sample.child_frame_id == "base_link"
        np.testing.assert_allclose(back.pose, msg.pose)
        np.testing.assert_allclose(back.twist, msg.twist)
    elif type_name == "tf2_msgs/msg/TFMessage":
        assert sample.transforms[0].transform.translation.z == pytest.approx(0.2)
        assert back[0].child == "laser"
        np.testing.assert_allclose(back[0].pose, msg[0].pose)
    elif type_name == "geometry_msgs/msg/PoseWithCovarianceStamped":
        assert sample.pose.covariance[35] == pytest.approx(0.003)
        np.testing.assert_allclose(back.pose, msg.pose)
    else:
        assert sample.angular_velocity.z == pytest.approx(0.3)
        np.testing.assert_allclose(back.angular_velocity_radps, msg.angular_velocity_radps)


@pytest.mark.parametrize("type_name", list(_samples()))
def test_restamp_moves_every_header_stamp_and_nothing_else(type_name: str) -> None:
    """``fgloc replay --now``: the header stamps (each transform's in a TFMessage, frame names of every
    length) moved by an exact number of nanoseconds, as Cyclone's deserializer reads them; with the stamps
    put back, Cyclone serializes the original bytes."""
    pytest.importorskip("cyclonedds")
    from fgloc.ros2 import codec
    from fgloc.ros2.msgtypes import idl_class
    from fgloc.types import Transform3D

    msg = _samples()[type_name]
    if type_name == "tf2_msgs/msg/TFMessage":  # three transforms: frame names of 4, 5 and 7 bytes with the NUL
        msg = msg + [Transform3D("odom", "base", np.array([1.0, 2.0, 0.0]), 0.0, np.array([0.0, 0.0, 0.0, 1.0])),
                     Transform3D("map", "odom_b", np.array([-3.0, 0.5, 0.0]), 0.0, np.array([0.0, 0.0, 0.6, 0.8]))]
    data = codec.encode(msg, 12.25 if type_name == "tf2_msgs/msg/TFMessage" else None)[1]
    shift = 1_765_000_000_987_654_321
    moved = codec.restamp(type_name, data, lambda t: t + shift)
    assert len(moved) == len(data) and moved != data
    cls = idl_class(type_name)
    a, b = cls.deserialize(data), cls.deserialize(moved)
    headers = [(x.header, y.header) for x, y in zip(a.transforms, b.transforms, strict=True)] \
        if type_name == "tf2_msgs/msg/TFMessage" else [(a.header, b.header)]
    for h0, h1 in headers:
        t0 = h0.stamp.sec * 1_000_000_000 + h0.stamp.nanosec
        assert h1.stamp.sec * 1_000_000_000 + h1.stamp.nanosec == t0 + shift
        h1.stamp = h0.stamp
    assert b == a
    assert codec.restamp(type_name, moved, lambda t: t - shift) == data
    with pytest.raises(codec.Undecodable):
        codec.restamp(type_name, data[:6], lambda t: t)


def test_map_clock_and_status_round_trip_through_cyclone() -> None:
    pytest.importorskip("cyclonedds")
    from fgloc.maps import OccupancyMap
    from fgloc.ros2 import codec
    from fgloc.ros2.msgtypes import idl_class

    grid = np.full((4, 6), -1, dtype=np.int16)
    grid[1, 2], grid[2, 3] = 100, 0
    m = OccupancyMap(grid, 0.05, np.array([-1.0, 2.0, 0.3]))
    data = codec.encode_map(m, 5.0)
    s = idl_class(codec.OCCUPANCY_GRID).deserialize(data)
    assert (s.info.width, s.info.height) == (6, 4)
    assert s.data[1 * 6 + 2] == 100 and s.data[0] == -1          # row-major from the origin, int8
    back = codec.decode(codec.OCCUPANCY_GRID, data)
    assert back.equals(m) and back.mode == "trinary"
    c = idl_class(codec.CLOCK).deserialize(codec.encode_clock(3.25))
    assert (c.clock.sec, c.clock.nanosec) == (3, 250_000_000)
    d = codec.encode_generic(codec.DIAGNOSTIC_ARRAY, {
        "header": {"stamp": {"sec": 1, "nanosec": 0}, "frame_id": ""},
        "status": [{"level": 2, "name": "fgloc: sub /scan", "message": "incompatible", "hardware_id": "/scan",
                    "values": [{"key": "matched", "value": "0"}]}]})
    st = idl_class(codec.DIAGNOSTIC_ARRAY).deserialize(d)
    assert st.status[0].level == 2 and st.status[0].values[0].key == "matched"


def test_undecodable_messages_raise_one_error() -> None:
    from fgloc.ros2 import codec

    for bad in (b"", b"\x00\x01", b"\x00\x01\x00\x00" + b"\xff" * 7, b"\x00\x01\x00\x00\x10\x00\x00\x00junk"):
        for t in ("sensor_msgs/msg/LaserScan", "nav_msgs/msg/Odometry", "tf2_msgs/msg/TFMessage",
                  codec.OCCUPANCY_GRID):
            with pytest.raises(codec.Undecodable):
                codec.decode(t, bad)


# ----------------------------------------------------------------------------- options
def test_domain_and_interface_options(monkeypatch: pytest.MonkeyPatch) -> None:
    from fgloc.errors import ConfigError
    from fgloc.ros2.transport import cyclone_config, domain_from_env

    monkeypatch.delenv("ROS_DOMAIN_ID", raising=False)
    assert domain_from_env(None) == 0                      # ROS 2's default
    monkeypatch.setenv("ROS_DOMAIN_ID", "42")
    assert domain_from_env(None) == 42 and domain_from_env(7) == 7
    for bad in ("x", "-1"):
        monkeypatch.setenv("ROS_DOMAIN_ID", bad)
        with pytest.raises(ConfigError, match="ROS_DOMAIN_ID"):
            domain_from_env(None)
    with pytest.raises(ConfigError, match="0..232"):
        domain_from_env(233)
    # Fast DDS' (vendor 1.15) type information is ignored: its endpoints match fgloc's by type name, as
    # rmw_cyclonedds_cpp's (which send none) do; else Cyclone cannot resolve Fast DDS' type objects and never
    # matches them (tools/interop_ros2.py: a rclpy node on rmw_fastrtps_cpp)
    monkeypatch.delenv("CYCLONEDDS_URI", raising=False)
    ignore = "<Compatibility><IgnoreTypeInformation>1.15</IgnoreTypeInformation></Compatibility>"
    assert ignore in (cyclone_config(None) or "")
    assert '<NetworkInterface name="lo"/>' in (cyclone_config("lo") or "") and ignore in (cyclone_config("lo") or "")
    assert '<NetworkInterface address="192.0.2.7"/>' in (cyclone_config("192.0.2.7") or "")
    monkeypatch.setenv("CYCLONEDDS_URI", "file:///etc/cyclonedds.xml")
    assert cyclone_config(None) is None  # the user's own configuration, as it is


def test_cli_refusals_are_one_line(capsys: pytest.CaptureFixture[str], tmp_path) -> None:
    from fgloc.cli import main

    assert main(["replay", str(tmp_path / "x.mcap")]) == 2
    assert "give --ros2" in capsys.readouterr().err
    assert main(["live", "--ros2", "--serial", "loop://"]) == 2
    assert "leave out --serial" in capsys.readouterr().err


def test_odom_frame_interpolates_and_extrapolates_a_little() -> None:
    from fgloc.ros2.node import OdomFrame, map_to_odom
    from fgloc.types import Odometry

    f = OdomFrame("odom")
    for k in range(5):  # 1 m/s along x, turning 0.1 rad/s
        f.add_odometry(Odometry(float(k) * 0.1, np.zeros(3), pose=np.array([0.1 * k, 0.0, 0.01 * k])))
    np.testing.assert_allclose(f.at(0.25), [0.25, 0.0, 0.025])
    np.testing.assert_allclose(f.at(0.45), [0.45, 0.0, 0.045])   # past the newest: extrapolated
    assert f.at(0.9) is None and f.at(-0.5) is None               # too far from what was received
    f.add_odometry(Odometry(0.5, np.zeros(3), frame_id="other", pose=np.array([9.0, 9.0, 0.0])))
    np.testing.assert_allclose(f.at(0.4), [0.4, 0.0, 0.04])       # another frame's odometry is not this one
    # map -> odom -> base is the map pose
    from fgloc.geometry import compose

    mb, ob = np.array([3.0, 1.0, 0.5]), np.array([0.4, -0.2, -0.3])
    np.testing.assert_allclose(compose(map_to_odom(mb, ob), ob), mb, atol=1e-12)


def test_pose_at_match_weighs_the_fix_against_the_prediction() -> None:
    from fgloc.ros2.node import pose_at_match
    from fgloc.types import PoseFix

    pred = np.array([1.0, 2.0, math.pi - 0.01])
    p = np.diag([0.02**2, 0.02**2, 0.01**2])
    fix = PoseFix(0.0, np.array([1.1, 2.0, -math.pi + 0.01]), np.diag([0.02**2, 0.06**2, 0.01**2]), 1.0, "native")
    out = pose_at_match(pred, p, fix)
    # equal variances in x and yaw: halfway (across +-pi); y: the fix 9x less sure, so 1/10 of the way
    np.testing.assert_allclose(out[:2], [1.05, 2.0], atol=1e-12)
    assert abs(abs(out[2]) - math.pi) < 1e-12
    fix_y = PoseFix(0.0, np.array([1.0, 2.1, pred[2]]), fix.cov, 1.0, "native")
    assert abs(pose_at_match(pred, p, fix_y)[1] - 2.01) < 1e-12
    np.testing.assert_array_equal(pose_at_match(pred, p, None), pred)  # no fix taken: the prediction
