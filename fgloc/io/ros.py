"""ROS 2 messages <-> fgloc types: the conversion rules of every reader and writer.

Conventions (both directions):

* stamps: ``header.stamp`` <-> ``stamp`` seconds (nanosecond exact); the MCAP log time of a
  message fgloc writes is its stamp.
* 3x3 covariances over ``[x, y, yaw]`` / ``[vx, vy, wz]`` are the ``(0, 1, 5)`` rows and
  columns of the ROS 6x6 ones; an all-zero 6x6 means "unknown" (-> None).  An Odometry
  whose ``pose`` is None is written with ``pose.covariance[0] = -1`` and read back as None.
* Imu -> the whole :class:`~fgloc.types.Imu` (orientation quaternion, angular velocity, linear
  acceleration, their 3x3 covariances, frame, stamp), values as the message has them (a zero or
  non-unit quaternion, a NaN covariance are the consumer's to count and skip:
  :mod:`fgloc.localization.sources`).  REP 145: a field whose covariance element ``[0]`` is
  ``-1`` is absent -> None (its covariance too); an all-zero covariance is "unknown" -> None.
  Written back the same way (an absent field: identity quaternion / zero vector, covariance
  ``[-1, 0, ...]``).  :meth:`fgloc.types.Imu.heading` is the yaw-only view
  (:class:`~fgloc.types.CompassHeading`), which fgloc's own sensors and the simulator produce:
  ``compass_to_ros`` writes it (variance in element ``[8]``, zz, of each covariance).
* TFMessage: each transform -> :class:`~fgloc.types.Transform3D` (x, y, yaw of the quaternion,
  z, and the whole rotation ``rotation_xyzw``: an IMU mounted upside down or turned about x);
  written back with that rotation (a plain ``StaticTransform``: its yaw);
  :func:`tf_flips` tells which ones turn the child's z axis down (an upside-down scanner).
* PoseWithCovarianceStamped: only stamp, frame, pose and covariance survive (``quality`` /
  ``source`` of a :class:`PoseFix` have no field; read back as 1.0 / the topic name).

``*_to_ros`` build the plain dicts a generic CDR encoder takes; ``*_from_ros`` take a decoded
message object (mcap_ros2 or rosbags, attribute access).  :mod:`fgloc.io.fastcdr` does the
same for raw CDR bytes without the generic codec.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from fgloc.geometry import quaternion_to_yaw, yaw_to_quaternion
from fgloc.io.topics import IMU, LASER_SCAN, MULTI_ECHO_SCAN, ODOMETRY, POSE_COV_STAMPED, TF_MESSAGE, TWIST_COV_STAMPED
from fgloc.types import CompassHeading, Imu, LaserScan, Odometry, PoseFix, StaticTransform, Transform3D, Twist

COV_IDX = (0, 1, 5)  # x, y, yaw (or vx, vy, wz) inside a ROS 6x6 covariance
COV_IDX9 = np.array([0, 1, 5, 6, 7, 11, 30, 31, 35])  # the same rows/columns of the 6x6, flattened


# stamps
def stamp_to_sec_nsec(stamp: float) -> tuple[int, int]:
    """Seconds -> ``(sec, nanosec)`` rounded to the nearest nanosecond."""
    sec = math.floor(stamp)
    nsec = round((stamp - sec) * 1e9)
    if nsec >= 1_000_000_000:
        sec, nsec = sec + 1, nsec - 1_000_000_000
    return int(sec), int(nsec)


def sec_nsec_to_stamp(sec: int, nsec: int) -> float:
    return float(sec) + float(nsec) * 1e-9


def stamp_to_ns(stamp: float) -> int:
    sec, nsec = stamp_to_sec_nsec(stamp)
    return sec * 1_000_000_000 + nsec


def ros_header(stamp: float, frame_id: str) -> dict:
    sec, nsec = stamp_to_sec_nsec(stamp)
    return {"stamp": {"sec": sec, "nanosec": nsec}, "frame_id": frame_id}


def header_stamp(header: Any) -> float:
    return sec_nsec_to_stamp(header.stamp.sec, header.stamp.nanosec)


# --------------------------------------------------------------------------------------------
# fgloc -> ROS 2 dicts
def yaw_quaternion(yaw: float) -> dict:
    q = yaw_to_quaternion(yaw)
    return {"x": float(q[0]), "y": float(q[1]), "z": float(q[2]), "w": float(q[3])}


def cov6_of(cov3: np.ndarray | None) -> list[float]:
    c6 = np.zeros(36)
    if cov3 is not None:
        c6[COV_IDX9] = np.asarray(cov3, dtype=float).reshape(9)
    return c6.tolist()  # type: ignore[no-any-return]


def cov3_of(cov36: Any) -> np.ndarray | None:
    c6 = np.asarray(cov36, dtype=float).reshape(6, 6)
    if not np.any(c6):
        return None
    return c6[np.ix_(COV_IDX, COV_IDX)].copy()


def scan_to_ros(m: LaserScan, stamp: float) -> dict:
    n = len(m.ranges)
    return {
        "header": ros_header(stamp, m.frame_id),
        "angle_min": m.angle_min,
        "angle_max": m.angle_min + m.angle_increment * max(n - 1, 0),
        "angle_increment": m.angle_increment,
        "time_increment": m.time_increment,
        "scan_time": m.scan_time,
        "range_min": m.range_min,
        "range_max": m.range_max,
        "ranges": np.asarray(m.ranges, dtype=np.float32).tolist(),
        "intensities": [] if m.intensities is None else np.asarray(m.intensities, dtype=np.float32).tolist(),
    }


def odom_to_ros(m: Odometry, stamp: float) -> dict:
    pose = np.zeros(3) if m.pose is None else np.asarray(m.pose, dtype=float)
    pcov = cov6_of(m.pose_cov)
    if m.pose is None:
        pcov[0] = -1.0
    tw = np.asarray(m.twist, dtype=float)
    return {
        "header": ros_header(stamp, m.frame_id),
        "child_frame_id": m.child_frame_id,
        "pose": {
            "pose": {"position": {"x": float(pose[0]), "y": float(pose[1]), "z": 0.0},
                     "orientation": yaw_quaternion(float(pose[2]))},
            "covariance": pcov,
        },
        "twist": {
            "twist": {"linear": {"x": float(tw[0]), "y": float(tw[1]), "z": 0.0},
                      "angular": {"x": 0.0, "y": 0.0, "z": float(tw[2])}},
            "covariance": cov6_of(m.twist_cov),
        },
    }


def cov9_of(var: float, absent: bool) -> list[float]:
    c = [0.0] * 9
    if absent:
        c[0] = -1.0
    elif not math.isnan(var):
        c[8] = float(var)
    return c


def compass_to_ros(m: CompassHeading, stamp: float) -> dict:
    return {
        "header": ros_header(stamp, m.frame_id),
        "orientation": yaw_quaternion(0.0 if m.yaw_rad is None else float(m.yaw_rad)),
        "orientation_covariance": cov9_of(m.yaw_var, m.yaw_rad is None),
        "angular_velocity": {"x": 0.0, "y": 0.0,
                             "z": 0.0 if m.yaw_rate_radps is None else float(m.yaw_rate_radps)},
        "angular_velocity_covariance": cov9_of(m.yaw_rate_var, m.yaw_rate_radps is None),
        "linear_acceleration": {"x": 0.0, "y": 0.0, "z": 0.0},
        "linear_acceleration_covariance": cov9_of(float("nan"), True),
    }


def _vec3(v: Any) -> dict:
    a = [0.0, 0.0, 0.0] if v is None else [float(x) for x in np.asarray(v, dtype=float).reshape(3)]
    return {"x": a[0], "y": a[1], "z": a[2]}


def cov9_full(cov: Any, absent: bool) -> list[float]:
    """A whole 3x3 covariance as the message's 9 values; ``[-1, 0, ...]`` for an absent field
    (REP 145), zeros for unknown (None)."""
    if absent:
        return [-1.0] + [0.0] * 8
    if cov is None:
        return [0.0] * 9
    return [float(x) for x in np.asarray(cov, dtype=float).reshape(9)]


def imu_to_ros(m: Imu, stamp: float) -> dict:
    q = m.orientation_xyzw
    qa = [0.0, 0.0, 0.0, 1.0] if q is None else [float(x) for x in np.asarray(q, dtype=float).reshape(4)]
    return {
        "header": ros_header(stamp, m.frame_id),
        "orientation": {"x": qa[0], "y": qa[1], "z": qa[2], "w": qa[3]},
        "orientation_covariance": cov9_full(m.orientation_cov, q is None),
        "angular_velocity": _vec3(m.angular_velocity_radps),
        "angular_velocity_covariance": cov9_full(m.angular_velocity_cov, m.angular_velocity_radps is None),
        "linear_acceleration": _vec3(m.linear_acceleration_mps2),
        "linear_acceleration_covariance": cov9_full(m.linear_acceleration_cov, m.linear_acceleration_mps2 is None),
    }


def fix_to_ros(m: PoseFix, stamp: float) -> dict:
    p = np.asarray(m.pose, dtype=float)
    return {
        "header": ros_header(stamp, m.frame_id),
        "pose": {
            "pose": {"position": {"x": float(p[0]), "y": float(p[1]), "z": 0.0},
                     "orientation": yaw_quaternion(float(p[2]))},
            "covariance": cov6_of(m.cov),
        },
    }


def _rotation(t: StaticTransform) -> dict:
    """A transform's quaternion: a :class:`Transform3D`'s whole rotation, else its yaw's."""
    q = getattr(t, "rotation_xyzw", None)
    if q is None:
        return yaw_quaternion(float(t.pose[2]))
    qa = np.asarray(q, dtype=float).reshape(4)
    return {"x": float(qa[0]), "y": float(qa[1]), "z": float(qa[2]), "w": float(qa[3])}


def tf_to_ros(m: list[StaticTransform], stamp: float) -> dict:
    return {
        "transforms": [
            {
                "header": ros_header(stamp, t.parent),
                "child_frame_id": t.child,
                "transform": {
                    "translation": {"x": float(t.pose[0]), "y": float(t.pose[1]), "z": float(t.z)},
                    "rotation": _rotation(t),
                },
            }
            for t in m
        ]
    }


# --------------------------------------------------------------------------------------------
# ROS 2 decoded messages -> fgloc
def quaternion_yaw(q: Any) -> float:
    return float(quaternion_to_yaw(q.x, q.y, q.z, q.w))


def _laser_scan(m: Any, ranges: np.ndarray, intensities: np.ndarray | None) -> LaserScan:
    """A ``LaserScan`` with a decoded scan message's header and geometry, and these beams."""
    return LaserScan(
        stamp=header_stamp(m.header),
        angle_min=float(m.angle_min),
        angle_increment=float(m.angle_increment),
        range_min=float(m.range_min),
        range_max=float(m.range_max),
        ranges=ranges,
        time_increment=float(m.time_increment),
        scan_time=float(m.scan_time),
        intensities=intensities,
        frame_id=m.header.frame_id,
    )


def scan_from_ros(m: Any, topic: str) -> LaserScan:
    inten = np.asarray(m.intensities, dtype=np.float32)
    return _laser_scan(m, np.asarray(m.ranges, dtype=np.float32), inten if len(inten) else None)


def multi_echo_scan_from_ros(m: Any, topic: str) -> LaserScan:
    """A ``sensor_msgs/MultiEchoLaserScan`` as the scan of its first echoes (what cartographer and
    laser_proc's ``first`` echo filter take); a beam without an echo is a no-return (+inf, REP 117),
    and intensities are kept only when every beam has one."""
    ranges = np.array([e.echoes[0] if len(e.echoes) else np.inf for e in m.ranges], dtype=np.float32)
    inten = [e.echoes[0] if len(e.echoes) else np.nan for e in m.intensities]
    keep = len(inten) == len(ranges) and ranges.size
    return _laser_scan(m, ranges, np.asarray(inten, dtype=np.float32) if keep else None)


def odom_from_ros(m: Any, topic: str) -> Odometry:
    pcov = m.pose.covariance
    p = m.pose.pose
    pose = None if pcov[0] == -1 else np.array([p.position.x, p.position.y, quaternion_yaw(p.orientation)])
    tw = m.twist.twist
    return Odometry(
        stamp=header_stamp(m.header),
        twist=np.array([tw.linear.x, tw.linear.y, tw.angular.z], dtype=float),
        twist_cov=cov3_of(m.twist.covariance),
        pose=pose,
        pose_cov=None if pose is None else cov3_of(pcov),
        frame_id=m.header.frame_id,
        child_frame_id=m.child_frame_id,
    )


def cov33_of(cov9: Any) -> np.ndarray | None:
    """A message's 9-element covariance as 3x3, None when all zero ("unknown")."""
    c = np.asarray(cov9, dtype=float).reshape(3, 3)
    return c if np.any(c) else None


def imu_from_ros(m: Any, topic: str) -> Imu:
    """The whole sensor_msgs/Imu (see the module doc: REP 145 absent fields -> None)."""
    ocov, wcov, acov = m.orientation_covariance, m.angular_velocity_covariance, m.linear_acceleration_covariance
    q, w, a = m.orientation, m.angular_velocity, m.linear_acceleration
    no_q, no_w, no_a = ocov[0] == -1, wcov[0] == -1, acov[0] == -1
    return Imu(
        stamp=header_stamp(m.header),
        orientation_xyzw=None if no_q else np.array([q.x, q.y, q.z, q.w], dtype=float),
        angular_velocity_radps=None if no_w else np.array([w.x, w.y, w.z], dtype=float),
        orientation_cov=None if no_q else cov33_of(ocov),
        angular_velocity_cov=None if no_w else cov33_of(wcov),
        linear_acceleration_mps2=None if no_a else np.array([a.x, a.y, a.z], dtype=float),
        linear_acceleration_cov=None if no_a else cov33_of(acov),
        frame_id=m.header.frame_id,
    )


def fix_from_ros(m: Any, topic: str) -> PoseFix:
    p = m.pose.pose
    cov = cov3_of(m.pose.covariance)
    return PoseFix(
        stamp=header_stamp(m.header),
        pose=np.array([p.position.x, p.position.y, quaternion_yaw(p.orientation)]),
        cov=np.zeros((3, 3)) if cov is None else cov,
        source=topic,
        frame_id=m.header.frame_id,
    )


def twist_from_ros(m: Any, topic: str) -> Twist:
    tw = m.twist.twist
    return Twist(stamp=header_stamp(m.header), twist=np.array([tw.linear.x, tw.linear.y, tw.angular.z], dtype=float),
                 twist_cov=cov3_of(m.twist.covariance), frame_id=m.header.frame_id)


def tf_from_ros(m: Any, topic: str) -> list[StaticTransform]:
    out: list[StaticTransform] = []
    for t in m.transforms:
        tr = t.transform
        r = tr.rotation
        out.append(
            Transform3D(
                parent=t.header.frame_id.lstrip("/"),
                child=t.child_frame_id.lstrip("/"),
                pose=np.array([tr.translation.x, tr.translation.y, quaternion_yaw(r)]),
                z=float(tr.translation.z),
                rotation_xyzw=np.array([r.x, r.y, r.z, r.w], dtype=float),
            )
        )
    return out


def tf_flips(m: Any) -> list[bool]:
    """Per transform of a decoded TFMessage: is the child's z axis pointing down (a scanner
    mounted upside down, rolled or pitched by pi)?  Its rotation is then ``Rz(yaw) Rx(pi)``
    with ``yaw`` as :func:`yaw` gives it."""
    out = []
    for t in m.transforms:
        q = t.transform.rotation
        n = q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w
        out.append(n > 0 and 1.0 - 2.0 * (q.x * q.x + q.y * q.y) / n < 0.0)
    return out


def mirror_scan(scan: LaserScan) -> LaserScan:
    """The scan of an upside-down scanner as an upright one sees it: angles negated (timing kept)."""
    scan.angle_min = -scan.angle_min
    scan.angle_increment = -scan.angle_increment
    return scan


FROM_ROS: dict[str, Callable[[Any, str], object]] = {
    LASER_SCAN: scan_from_ros,
    MULTI_ECHO_SCAN: multi_echo_scan_from_ros,
    ODOMETRY: odom_from_ros,
    IMU: imu_from_ros,
    TF_MESSAGE: tf_from_ros,
    POSE_COV_STAMPED: fix_from_ros,
    TWIST_COV_STAMPED: twist_from_ros,
}
