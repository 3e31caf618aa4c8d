"""An IMU mounted upside down or on its side in a log without its mount (no /tf_static: a driver's own
recording, fuse's TurtleBot3 tutorial bag): its readings say where up is, and that rotation is used
as its mount, said in a warning (:mod:`fgloc.app.imutilt`).  Without it the gyro's yaw rate has the
wrong axis or sign and the run is a wrong answer with every pose ``ok``."""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest

from fgloc.frames.imu import levelling_quaternion, up_direction
from fgloc.types import Imu

T0 = 1_700_000_000
V, W = 0.5, 0.3  # m/s, rad/s: a circle of 1.67 m radius


def _rot(rpy_deg):
    from scipy.spatial.transform import Rotation

    return Rotation.from_euler("xyz", rpy_deg, degrees=True)


@pytest.mark.parametrize("rpy", [(180, 0, 0), (90, 0, -90), (0, -90, 0), (20, 0, 0)])
def test_up_and_the_levelling_rotation(rpy):
    from scipy.spatial.transform import Rotation

    mount = _rot(rpy)
    msgs = []
    for yaw in np.linspace(0.0, 3.0, 20):
        q = (Rotation.from_euler("z", yaw) * mount).as_quat()
        acc = mount.inv().apply([0.0, 0.0, 9.81])
        msgs.append(Imu(0.0, q, np.zeros(3), linear_acceleration_mps2=acc))
    up = up_direction(msgs)
    assert up == pytest.approx(mount.inv().apply([0.0, 0.0, 1.0]), abs=1e-9)
    level = Rotation.from_quat(levelling_quaternion(up))
    assert level.apply(up) == pytest.approx([0.0, 0.0, 1.0], abs=1e-9)
    # without an orientation, the accelerometer says the same
    bare = [Imu(0.0, None, np.zeros(3), linear_acceleration_mps2=m.linear_acceleration_mps2) for m in msgs]
    assert up_direction(bare) == pytest.approx(up, abs=1e-9)


def _write(path, mount_rpy, with_tf: bool) -> None:
    """A ROS 1 bag: wheels driving a circle (20 Hz) and an IMU (50 Hz) mounted ``mount_rpy`` on the robot,
    its mount in /tf_static or not."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore
    from scipy.spatial.transform import Rotation

    ts = get_typestore(Stores.ROS1_NOETIC)
    if "tf2_msgs/msg/TFMessage" not in ts.types:
        ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
    T = ts.types
    mount = _rot(mount_rpy)

    def hdr(ns, frame):
        return T["std_msgs/msg/Header"](seq=0, stamp=T["builtin_interfaces/msg/Time"](sec=ns // 10**9,
                                        nanosec=ns % 10**9), frame_id=frame)

    vec, quat = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]
    with Writer(path) as w:
        co = w.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=ts)
        ci = w.add_connection("/imu", "sensor_msgs/msg/Imu", typestore=ts)
        if with_tf:
            ct = w.add_connection("/tf_static", "tf2_msgs/msg/TFMessage", typestore=ts, latching=1)
            q = mount.as_quat()
            tr = T["geometry_msgs/msg/TransformStamped"](
                header=hdr(T0 * 10**9, "base_link"), child_frame_id="imu_link",
                transform=T["geometry_msgs/msg/Transform"](translation=vec(x=0.0, y=0.0, z=0.1),
                                                           rotation=quat(x=q[0], y=q[1], z=q[2], w=q[3])))
            w.write(ct, T0 * 10**9, ts.serialize_ros1(T["tf2_msgs/msg/TFMessage"](transforms=[tr]),
                                                      "tf2_msgs/msg/TFMessage"))
        cov = np.diag([1e-3, 1e-3, 1e6, 1e6, 1e6, 1e-2]).ravel()
        for i in range(1, 50 * 20):
            ns = T0 * 10**9 + i * 20_000_000
            t = i * 0.02
            yaw = W * t
            qi = (Rotation.from_euler("z", yaw) * mount).as_quat()
            imu = T["sensor_msgs/msg/Imu"](
                header=hdr(ns, "imu_link"), orientation=quat(x=qi[0], y=qi[1], z=qi[2], w=qi[3]),
                orientation_covariance=np.diag([1e-3, 1e-3, 1e-3]).ravel(),
                angular_velocity=vec(**dict(zip("xyz", mount.inv().apply([0.0, 0.0, W]), strict=True))),
                angular_velocity_covariance=np.diag([1e-4, 1e-4, 1e-4]).ravel(),
                linear_acceleration=vec(**dict(zip("xyz", mount.inv().apply([0.0, 0.0, 9.81]), strict=True))),
                linear_acceleration_covariance=np.diag([1e-2, 1e-2, 1e-2]).ravel())
            w.write(ci, ns, ts.serialize_ros1(imu, "sensor_msgs/msg/Imu"))
            if i % 2 == 0:  # the wheels: a yaw rate 20 % short (skid), the IMU's is the truth
                r = V / W
                pose = T["geometry_msgs/msg/Pose"](
                    position=T["geometry_msgs/msg/Point"](x=r * math.sin(yaw), y=r * (1 - math.cos(yaw)), z=0.0),
                    orientation=quat(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)))
                twist = T["geometry_msgs/msg/Twist"](linear=vec(x=V, y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=W))
                msg = T["nav_msgs/msg/Odometry"](
                    header=hdr(ns, "odom"), child_frame_id="base_link",
                    pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=cov),
                    twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=cov))
                w.write(co, ns, ts.serialize_ros1(msg, "nav_msgs/msg/Odometry"))


def _run(log, out, caplog, backend="ekf") -> tuple[np.ndarray, str]:
    from fgloc.cli import main

    with caplog.at_level(logging.WARNING):
        rc = main(["run", str(log), "-o", str(out), "-q", "--backend", backend])
    assert rc == 0, caplog.text
    return np.loadtxt(out / "trajectory.tum"), caplog.text


@pytest.mark.parametrize(("rpy", "how"), [((180, 0, 0), "upside down"), ((90, 0, -90), "on its side")])
@pytest.mark.parametrize("backend", ["ekf", "smoother"])
def test_a_tilted_imu_without_its_mount_is_levelled(tmp_path, caplog, rpy, how, backend):
    log = tmp_path / "tilted.bag"
    _write(log, rpy, with_tf=False)
    tr, said = _run(log, tmp_path / "o", caplog, backend)
    t = tr[:, 0] - T0
    r = V / W
    truth = np.c_[r * np.sin(W * t), r * (1 - np.cos(W * t))] - [r * math.sin(W * t[0]), r * (1 - math.cos(W * t[0]))]
    yaw0 = 2 * math.atan2(tr[0, 6], tr[0, 7])  # the run's frame may take the IMU's heading: align the start
    c, s = math.cos(-yaw0), math.sin(-yaw0)
    rel = (tr[:, 1:3] - tr[0, 1:3]) @ np.array([[c, s], [-s, c]])
    err = np.hypot(*(rel - truth).T)
    assert err.max() < 0.05, err.max()
    assert "no mount of the IMU frame imu_link in the log" in said and how in said


def test_a_mount_in_the_log_or_a_level_imu_is_left_alone(tmp_path, caplog):
    _write(tmp_path / "mounted.bag", (180, 0, 0), with_tf=True)
    _write(tmp_path / "level.bag", (0, 0, 30), with_tf=False)
    for name in ("mounted.bag", "level.bag"):
        caplog.clear()
        _tr, said = _run(tmp_path / name, tmp_path / name.replace(".bag", ""), caplog)
        assert "no mount of the IMU frame" not in said


def test_an_orientation_that_disagrees_with_gravity_is_no_mount():
    """NED orientation over FLU axes (the accelerometer says up is +z, the orientation -z): no telling
    which is the sensor's, so no mount is guessed."""
    from scipy.spatial.transform import Rotation

    msgs = [Imu(0.0, (Rotation.from_euler("z", y) * _rot((180, 0, 0))).as_quat(), np.zeros(3),
                linear_acceleration_mps2=np.array([0.0, 0.0, 9.81])) for y in np.linspace(0.0, 1.0, 10)]
    assert up_direction(msgs) is None
