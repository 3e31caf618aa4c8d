"""Stamped measurement types and the trajectory type.

Every stamp is seconds (float, the ROS ``header.stamp`` as ``sec + nanosec*1e-9``).
Frames follow REP 105: ``map`` (global, fixed), ``odom`` (continuous, drifting),
``base_link`` (robot body), ``laser`` (the scanner).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fgloc.geometry import interpolate_poses, quaternion_to_yaw, wrap_angle

FloatArray = NDArray[np.float64]

# Indices into a body twist vector.
VX, VY, WZ = 0, 1, 2



def all_finite(*arrays: ArrayLike) -> bool:
    """Every entry of the (small) arrays finite: a pose, a covariance.  In scalar maths: numpy's
    ``isfinite`` and its reduction cost several times as much on arrays this small."""
    for a in arrays:
        if not all(map(math.isfinite, np.asarray(a, dtype=float).ravel().tolist())):
            return False
    return True

@dataclass
class Odometry:
    """Wheel odometry (``nav_msgs/Odometry``).

    ``twist`` is the body-frame twist ``[vx_mps, vy_mps, wz_radps]`` in ``child_frame``
    (``base_link``); ``twist_cov`` its 3x3 covariance (None if unknown).
    ``pose`` is the dead-reckoned pose ``[x, y, yaw]`` in the ``odom`` frame when the
    source provides one (CARMEN, most ROS drivers), else None.
    """

    stamp: float
    twist: FloatArray
    twist_cov: FloatArray | None = None
    pose: FloatArray | None = None
    pose_cov: FloatArray | None = None
    frame_id: str = "odom"
    child_frame_id: str = "base_link"


@dataclass
class Twist:
    """A body twist with its covariance (``geometry_msgs/TwistWithCovarianceStamped``), planar.

    ``twist`` is ``[vx_mps, vy_mps, wz_radps]`` in ``frame_id`` (the frame the sensor reports
    it in, usually ``base_link``); ``twist_cov`` its 3x3 covariance (None if unknown).
    """

    stamp: float
    twist: FloatArray
    twist_cov: FloatArray | None = None
    frame_id: str = "base_link"


@dataclass
class CompassHeading:
    """Absolute heading from a compass / IMU (``sensor_msgs/Imu``).

    ``yaw_rad`` is the orientation yaw in the sensor's own north-referenced frame
    (which may be offset from ``map``); ``yaw_rate_radps`` the z angular velocity.
    Variances of NaN mean "not provided"; per REP 145 a ``-1`` first covariance
    element in the message means the field is absent: readers turn that into None.
    """

    stamp: float
    yaw_rad: float | None
    yaw_rate_radps: float | None = None
    yaw_var: float = float("nan")
    yaw_rate_var: float = float("nan")
    frame_id: str = "base_link"  # a compass reads the base's heading (no mount to look up)


@dataclass
class Imu:
    """A whole ``sensor_msgs/Imu`` in its own frame ``frame_id`` (REP 145), nothing dropped.

    ``orientation_xyzw`` ``(4,)`` is the sensor frame's orientation in the IMU's world frame
    (ENU, north-referenced: offset from ``map``), ``angular_velocity_radps`` ``(3,)`` the body
    rates about the sensor's own x, y, z axes, ``linear_acceleration_mps2`` ``(3,)``.  Each
    ``*_cov`` is the message's 3x3 covariance, or None when all zero ("unknown").  A field the
    sensor does not provide (covariance element 0 == -1) is None.  The mount (``/tf_static``
    ``base_link -> frame_id``) rotates both into ``base_link``.
    """

    stamp: float
    orientation_xyzw: FloatArray | None
    angular_velocity_radps: FloatArray | None
    orientation_cov: FloatArray | None = None
    angular_velocity_cov: FloatArray | None = None
    linear_acceleration_mps2: FloatArray | None = None
    linear_acceleration_cov: FloatArray | None = None
    frame_id: str = "imu_link"

    def heading(self) -> CompassHeading:
        """The yaw-only view of this message in its own frame (what fgloc's readers gave before
        they kept the whole Imu): the quaternion's yaw (None without orientation or with a zero
        quaternion), the z angular velocity, and the zz elements of their covariances (NaN when
        unknown).  The mount is not applied."""
        q = self.orientation_xyzw
        yaw = None
        if q is not None:
            qa = np.asarray(q, dtype=float).reshape(-1)
            if qa.shape == (4,) and not float(qa @ qa) < 1e-12:  # zero quaternion: none (NaN kept)
                yaw = float(quaternion_to_yaw(qa[0], qa[1], qa[2], qa[3]))
        w = self.angular_velocity_radps
        rate = None if w is None else float(np.asarray(w, dtype=float).reshape(-1)[2])
        return CompassHeading(self.stamp, yaw, rate, _zz(self.orientation_cov) if yaw is not None else float("nan"),
                              _zz(self.angular_velocity_cov) if rate is not None else float("nan"), self.frame_id)


def _zz(cov: FloatArray | None) -> float:
    return float("nan") if cov is None else float(np.asarray(cov, dtype=float).reshape(9)[8])


@dataclass
class LaserScan:
    """A planar scan (``sensor_msgs/LaserScan``), REP 117 conventions.

    ``ranges`` are metres, float32; ``+inf`` = no return within range_max,
    ``-inf`` = too close, NaN = invalid measurement.  Beam ``i`` is at angle
    ``angle_min + i * angle_increment`` in ``frame_id`` and was measured at
    ``stamp + i * time_increment``.
    """

    stamp: float
    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float
    ranges: NDArray[np.float32]
    time_increment: float = 0.0
    scan_time: float = 0.0
    intensities: NDArray[np.float32] | None = None
    frame_id: str = "laser"

    @property
    def angles(self) -> FloatArray:
        return np.asarray(self.angle_min + self.angle_increment * np.arange(len(self.ranges)), dtype=np.float64)

    def valid_mask(self) -> NDArray[np.bool_]:
        """Beams with a finite return inside ``[range_min, range_max]``."""
        r = np.asarray(self.ranges, dtype=float)
        with np.errstate(invalid="ignore"):
            return np.isfinite(r) & (r >= self.range_min) & (r <= self.range_max) & (r > 0)

    def points(self) -> FloatArray:
        """Valid returns as ``(N, 2)`` points in the laser frame."""
        m = self.valid_mask()
        r = np.asarray(self.ranges, dtype=float)[m]
        a = self.angles[m]
        return np.column_stack([r * np.cos(a), r * np.sin(a)])


@dataclass
class PoseFix:
    """A pose with covariance (``geometry_msgs/PoseWithCovarianceStamped``) in ``frame_id``.

    ``cov`` is 3x3 over ``[x, y, yaw]``.  ``quality`` is a front-end score in [0, 1].  ``status``:
    a fused pose's (``ok``, ``degraded``, ``suspect``, ``lost``; :mod:`fgloc.localization.monitor`).
    """

    stamp: float
    pose: FloatArray
    cov: FloatArray
    quality: float = 1.0
    source: str = ""
    frame_id: str = "map"
    status: str = ""


@dataclass
class StaticTransform:
    """A 2-D static transform ``parent -> child`` (e.g. ``base_link -> laser``), ``[x, y, yaw]``."""

    parent: str
    child: str
    pose: FloatArray
    z: float = 0.0


@dataclass
class Transform3D(StaticTransform):
    """A static transform with its whole 3-D rotation ``rotation_xyzw`` ``[qx, qy, qz, qw]``.

    Still a :class:`StaticTransform` (``pose`` holds ``[x, y, yaw]`` of the same rotation,
    ``z`` the height), so code that knows only the planar transform keeps working; an IMU
    mounted upside down or turned about x needs the whole rotation.
    """

    rotation_xyzw: FloatArray | None = None


@dataclass
class Trajectory:
    """Timestamped SE(2) poses; timestamps are required and strictly increasing.

    ``stamps`` shape ``(N,)`` seconds; ``poses`` shape ``(N, 3)`` ``[x, y, yaw]``.
    """

    stamps: FloatArray
    poses: FloatArray
    frame_id: str = "map"
    covs: FloatArray | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        self.stamps = np.asarray(self.stamps, dtype=float).reshape(-1)
        self.poses = np.asarray(self.poses, dtype=float).reshape(-1, 3)
        if len(self.stamps) != len(self.poses):
            raise ValueError(f"trajectory has {len(self.stamps)} stamps but {len(self.poses)} poses")
        if len(self.stamps) > 1 and not np.all(np.diff(self.stamps) > 0):
            raise ValueError("trajectory timestamps must be strictly increasing")
        if not np.all(np.isfinite(self.poses)) or not np.all(np.isfinite(self.stamps)):
            raise ValueError("trajectory contains non-finite values")
        self.poses = self.poses.copy()
        self.poses[:, 2] = wrap_angle(self.poses[:, 2])

    def __len__(self) -> int:
        return len(self.stamps)

    @property
    def duration(self) -> float:
        return float(self.stamps[-1] - self.stamps[0]) if len(self) else 0.0

    def interpolate(self, t: NDArray[np.float64] | float) -> FloatArray:
        """Poses at times ``t`` by linear interpolation (clamped at the ends)."""
        return interpolate_poses(self.stamps, self.poses, t)

    def path_length(self) -> float:
        return float(np.sum(np.linalg.norm(np.diff(self.poses[:, :2], axis=0), axis=1)))

    @staticmethod
    def from_unsorted(stamps: NDArray[np.float64], poses: NDArray[np.float64], frame_id: str = "map") -> Trajectory:
        """Sort by time and drop duplicate stamps (keeping the last)."""
        stamps = np.asarray(stamps, dtype=float)
        poses = np.asarray(poses, dtype=float).reshape(-1, 3)
        order = np.argsort(stamps, kind="stable")
        s, p = stamps[order], poses[order]
        keep = np.ones(len(s), dtype=bool)
        keep[:-1] = np.diff(s) > 0
        return Trajectory(s[keep], p[keep], frame_id)
