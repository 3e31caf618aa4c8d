"""``sensor_msgs/MultiEchoLaserScan`` (a multi-echo laser: urg_node's ``echoes``, cartographer's
``horizontal_laser_2d``) is read as the scan of its first echoes, in ROS 1 bags, rosbag2 folders
and MCAP alike; before, run said "topic '/scan' has type sensor_msgs/msg/MultiEchoLaserScan,
expected sensor_msgs/msg/LaserScan" and map "no laser scans".  The logs are written here, each
beam with two echoes (the second 0.5 m further) or none (a no-return)."""

from __future__ import annotations

import numpy as np
import pytest

from fgloc.cli import main
from fgloc.io import open_log
from fgloc.io.tum import read_tum
from fgloc.types import LaserScan

N = 12
T0 = 1_700_000_000
BEAMS = 181


def _first(i: int) -> np.ndarray:
    r = np.linspace(1.0, 4.0, BEAMS).astype(np.float32) + np.float32(0.01 * i)
    r[7] = np.nan  # marks the beam written without echoes
    return r


def _write(path, ros2: bool):
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE if ros2 else Stores.ROS1_NOETIC)
    T = ts.types
    Time, Header = T["builtin_interfaces/msg/Time"], T["std_msgs/msg/Header"]
    V3, Q, Echo = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"], T["sensor_msgs/msg/LaserEcho"]
    if ros2:
        from rosbags.rosbag2 import Writer

        w, ser, hdr_extra = Writer(path, version=8), ts.serialize_cdr, {}
    else:
        from rosbags.rosbag1 import Writer  # type: ignore[assignment]

        w, ser, hdr_extra = Writer(path), ts.serialize_ros1, {"seq": 0}
    with w:
        cs = w.add_connection("/scan", "sensor_msgs/msg/MultiEchoLaserScan", typestore=ts)
        co = w.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=ts)
        for i in range(N):
            ns = T0 * 10**9 + i * 100_000_000
            stamp = Time(sec=ns // 10**9, nanosec=ns % 10**9)
            odom = T["nav_msgs/msg/Odometry"](
                header=Header(stamp=stamp, frame_id="odom", **hdr_extra), child_frame_id="base_link",
                pose=T["geometry_msgs/msg/PoseWithCovariance"](
                    pose=T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=0.02 * i, y=0.0, z=0.0),
                                                     orientation=Q(x=0.0, y=0.0, z=0.0, w=1.0)),
                    covariance=np.zeros(36)),
                twist=T["geometry_msgs/msg/TwistWithCovariance"](
                    twist=T["geometry_msgs/msg/Twist"](linear=V3(x=0.2, y=0.0, z=0.0), angular=V3(x=0.0, y=0.0, z=0.0)),
                    covariance=np.zeros(36)))
            w.write(co, ns, ser(odom, odom.__msgtype__))
            r = _first(i)
            echoes = [Echo(echoes=np.zeros(0, np.float32) if np.isnan(v) else np.array([v, v + 0.5], np.float32))
                      for v in r]
            inten = [Echo(echoes=np.zeros(0, np.float32) if np.isnan(v) else np.array([900.0, 300.0], np.float32))
                     for v in r]
            scan = T["sensor_msgs/msg/MultiEchoLaserScan"](
                header=Header(stamp=stamp, frame_id="laser", **hdr_extra), angle_min=-1.57, angle_max=1.57,
                angle_increment=3.14 / (BEAMS - 1), time_increment=0.0, scan_time=0.1, range_min=0.1,
                range_max=30.0, ranges=echoes, intensities=inten)
            w.write(cs, ns + 1000, ser(scan, scan.__msgtype__))


@pytest.mark.parametrize("ros2", [True, False], ids=["rosbag2", "rosbag1"])
def test_multi_echo_scans_read_as_their_first_echoes(tmp_path, capsys, ros2):
    log = tmp_path / ("bag" if ros2 else "log.bag")
    _write(log, ros2)
    scans = [m for _, m in open_log(log).messages(["/scan"])]
    assert len(scans) == N and all(isinstance(s, LaserScan) for s in scans)
    for i, s in enumerate(scans):
        want = _first(i)
        want[7] = np.inf                           # no echo: no return (REP 117)
        np.testing.assert_array_equal(s.ranges, want)
        assert s.intensities is not None and s.intensities[0] == 900.0 and np.isnan(s.intensities[7])
        assert s.frame_id == "laser" and s.angle_min == pytest.approx(-1.57)
    out = tmp_path / "run"
    assert main(["run", str(log), "-o", str(out), "-q"]) == 0
    assert f"scans {N}, " in " ".join(capsys.readouterr().out.split())
    assert len(read_tum(out / "trajectory.tum")) > 0
    # what run recorded (a ROS 2 input's MultiEchoLaserScan copied as it is) reads back the same
    again = [m for _, m in open_log(out / "run.mcap").messages(["/scan"])]
    assert len(again) == N and np.array_equal(again[3].ranges, scans[3].ranges)
