"""``geometry_msgs/PoseStamped`` topics (a motion-capture system's, as vrpn_client_ros publishes them) as
trajectories for ``fgloc eval`` and ``fgloc export``: ROS 1 bags and rosbag2 folders, written here with
rosbags.  A real Jackal's runs with such a reference (scans and the motion capture, nothing else) could
be mapped but not evaluated: the topic was "not nav_msgs/Odometry or PoseWithCovarianceStamped"."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fgloc.cli import main
from fgloc.eval.trajectories import read_trajectory
from fgloc.geometry import yaw_to_quaternion

TOPIC = "/vrpn_client_node/jackal/pose"
N = 40
T0 = 1_700_000_000


def _poses() -> list[tuple[int, float, float, float]]:
    """(ns, x, y, yaw) of a slow arc."""
    return [(T0 * 10**9 + i * 50_000_000, 0.1 * i, 0.02 * i * i, math.atan2(math.sin(0.1 * i), math.cos(0.1 * i)))
            for i in range(N)]


def _write(path, ros2: bool) -> None:
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE if ros2 else Stores.ROS1_NOETIC)
    T = ts.types
    Time, Header = T["builtin_interfaces/msg/Time"], T["std_msgs/msg/Header"]
    Q, P = T["geometry_msgs/msg/Quaternion"], T["geometry_msgs/msg/Point"]
    if ros2:
        from rosbags.rosbag2 import Writer
        writer = Writer(path, version=8)
    else:
        from rosbags.rosbag1 import Writer  # type: ignore[assignment]
        writer = Writer(path)
    with writer as w:
        c = w.add_connection(TOPIC, "geometry_msgs/msg/PoseStamped", typestore=ts)
        for ns, x, y, yaw in _poses():
            q = yaw_to_quaternion(yaw)
            hdr = Header(stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id="world") if ros2 else \
                Header(seq=0, stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id="world")
            msg = T["geometry_msgs/msg/PoseStamped"](header=hdr, pose=T["geometry_msgs/msg/Pose"](
                position=P(x=x, y=y, z=0.3), orientation=Q(x=q[0], y=q[1], z=q[2], w=q[3])))
            w.write(c, ns, ts.serialize_cdr(msg, msg.__msgtype__) if ros2 else ts.serialize_ros1(msg, msg.__msgtype__))


@pytest.mark.parametrize("ros2", [False, True], ids=["ros1", "rosbag2"])
def test_a_pose_stamped_topic_is_a_trajectory(tmp_path, ros2, capsys):
    log = tmp_path / ("mocap" if ros2 else "mocap.bag")
    _write(log, ros2)
    tr, where = read_trajectory(f"{log}:{TOPIC}")
    want = np.array([[x, y, yaw] for _, x, y, yaw in _poses()])
    assert len(tr) == N and where.topic == TOPIC and tr.frame_id == "world"
    assert np.allclose(tr.stamps, [ns * 1e-9 for ns, *_ in _poses()], atol=1e-6, rtol=0)
    assert np.allclose(tr.poses, want, atol=1e-9, rtol=0)
    # the log's only pose topic is taken without being named; export writes it as TUM
    assert len(read_trajectory(log)[0]) == N
    out = tmp_path / "mocap.tum"
    assert main(["export", f"{log}:{TOPIC}", "-o", str(out)]) == 0
    assert f"{N} poses" in capsys.readouterr().out
    assert len(out.read_text().splitlines()) >= N
