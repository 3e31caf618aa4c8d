"""ROS 2 messages built with ``rosbags``' type store, as the tests write them into rosbag2 folders: one
odometry message and one laser scan of a robot driving straight along x."""

from __future__ import annotations

from typing import Any


def odometry(types: Any, ns: int, x: float, vx: float = 0.2) -> Any:
    """A ``nav_msgs/msg/Odometry`` stamped ``ns`` (ns): the robot at ``(x, 0)`` facing +x in ``odom``,
    driving ``vx`` m/s, all covariances zero; ``types``: a type store's ``types``."""
    import numpy as np

    T = types
    V3, Q = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]
    return T["nav_msgs/msg/Odometry"](
        header=header(T, ns, "odom"), child_frame_id="base_footprint",
        pose=T["geometry_msgs/msg/PoseWithCovariance"](
            pose=T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=x, y=0.0, z=0.0),
                                             orientation=Q(x=0.0, y=0.0, z=0.0, w=1.0)),
            covariance=np.zeros(36)),
        twist=T["geometry_msgs/msg/TwistWithCovariance"](
            twist=T["geometry_msgs/msg/Twist"](linear=V3(x=vx, y=0.0, z=0.0), angular=V3(x=0.0, y=0.0, z=0.0)),
            covariance=np.zeros(36)))


def laser_scan(types: Any, ns: int, rng: float) -> Any:
    """A ``sensor_msgs/msg/LaserScan`` stamped ``ns`` (ns) in ``base_scan``: 360 beams over a turn
    (a TurtleBot3's LDS: 0.12-3.5 m, 5 Hz), each ``rng`` m."""
    import numpy as np

    T = types
    return T["sensor_msgs/msg/LaserScan"](
        header=header(T, ns, "base_scan"), angle_min=0.0, angle_max=6.26, angle_increment=0.0175,
        time_increment=0.0, scan_time=0.2, range_min=0.12, range_max=3.5, ranges=np.full(360, rng, np.float32),
        intensities=np.zeros(0, np.float32))


def header(types: Any, ns: int, frame_id: str) -> Any:
    """A ``std_msgs/msg/Header`` stamped ``ns`` (ns)."""
    T = types
    return T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9),
                                    frame_id=frame_id)
