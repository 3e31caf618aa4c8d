"""An IMU as an IMU: ``sensor_msgs/Imu`` rotated through its mount into ``base_link``.

REP 145: the message's orientation is the sensor frame's orientation in the IMU's own world
frame (ENU, referenced to magnetic north or to wherever its yaw started), its angular
velocity is about the sensor's own axes, and its covariances are expressed in the sensor
frame.  With ``R_bi`` the mount rotation (``/tf_static`` ``base_link -> imu_link``: a vector in
the IMU frame is ``R_bi @ v`` in base_link)::

    R_world_base = R_world_imu @ R_bi^T          (the base's orientation)
    w_base       = R_bi @ w_imu                  (body rates in base_link)
    C_base       = R_bi @ C_imu @ R_bi^T         (each covariance, as robot_localization does)

and the planar back-ends take the base's yaw (``atan2(R[1, 0], R[0, 0])``) and yaw rate
(``w_base[2]``) with the zz elements of the rotated covariances.  Any 3-D mount works: yawed,
upside down, turned 90 deg about x (the IMU's y axis then measures the base's yaw rate).

Bad input is never an exception: a quaternion of zeros or not of unit length (beyond
``QUATERNION_NORM_TOLERANCE``) drops the orientation, a covariance with a NaN or negative
diagonal drops its field, and :func:`imu_in_base` says why.  An IMU whose mount nobody gave:
:func:`up_direction` (where gravity says up is in its axes) and :func:`levelling_quaternion` (the
mount that levels it; ``fgloc.app.imutilt`` uses them when a log lacks the mount).  Core maths
only: no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fgloc.geometry import quaternion_matrix
from fgloc.types import Imu, StaticTransform

FloatArray = NDArray[np.float64]

#: |‖q‖ - 1| above this: the quaternion is not a rotation (a driver bug), the orientation is skipped
QUATERNION_NORM_TOLERANCE = 0.01


@dataclass
class BaseImu:
    """One IMU reading in ``base_link``: yaw (IMU world frame) and yaw rate, either may be None.

    Variances are NaN when the message did not say ("unknown": the back-end's default applies).
    """

    stamp: float
    yaw_rad: float | None
    yaw_var: float
    yaw_rate_radps: float | None
    yaw_rate_var: float
    #: the base's roll and pitch (rad, ZYX Euler angles of base_link in the IMU's world frame),
    #: None without a usable orientation
    roll_pitch_rad: tuple[float, float] | None = None
    #: the heading's rate (rad/s) when tilted: ``(sin(roll) w_y + cos(roll) w_z) / cos(pitch)``
    #: (the ZYX Euler yaw rate; ``w_z`` on level ground), None without orientation and rates
    heading_rate_radps: float | None = None
    #: the base's roll and pitch variances (rad^2: ``R_bi C R_bi^T``'s first two diagonal entries of the
    #: orientation covariance), None without an orientation covariance or a usable orientation
    roll_pitch_var: tuple[float, float] | None = None


def _unit_floats(v: object, n: int) -> list[float] | None:
    """``v``'s ``n`` elements as floats, None when it does not have ``n``."""
    a = v if isinstance(v, np.ndarray) else np.asarray(v, dtype=float)
    return a.ravel().tolist() if a.size == n else None


def mount_rotation(tf: StaticTransform | None) -> FloatArray:
    """``R_bi`` (3x3) of a ``base_link -> imu`` transform; identity when there is none.

    A :class:`~fgloc.types.Transform3D` gives its whole rotation; a planar
    :class:`~fgloc.types.StaticTransform` its yaw only.
    """
    if tf is None:
        return np.eye(3)
    q = getattr(tf, "rotation_xyzw", None)
    if q is not None:
        qa = np.asarray(q, dtype=float).reshape(4).tolist()
        n = math.sqrt(qa[0] * qa[0] + qa[1] * qa[1] + qa[2] * qa[2] + qa[3] * qa[3])
        if math.isfinite(n) and n > 1e-9:
            return np.array(quaternion_matrix(*(v / n for v in qa))).reshape(3, 3)
    h = 0.5 * float(tf.pose[2])
    return np.array(quaternion_matrix(0.0, 0.0, math.sin(h), math.cos(h))).reshape(3, 3)


def _cov_values(c: FloatArray | None) -> list[float] | None:
    """A 3x3 covariance's 9 entries (row by row) as floats, None when absent (one ``tolist`` per
    covariance: :func:`_cov_ok` and :func:`_zz` read the same list)."""
    if c is None:
        return None
    return (c.ravel() if isinstance(c, np.ndarray) and c.size == 9 else np.asarray(c, dtype=float).reshape(9)).tolist()


def _cov_ok(a: list[float] | None) -> str | None:
    """None if the covariance (:func:`_cov_values`) is usable (or absent), else why not."""
    if a is None:
        return None
    d0, d1, d2 = a[0], a[4], a[8]
    if not (math.isfinite(d0) and math.isfinite(d1) and math.isfinite(d2)):
        return "covariance with a NaN/inf diagonal"
    if d0 < 0 or d1 < 0 or d2 < 0:
        return "covariance with a negative diagonal"
    return None


def _zz(r: tuple[float, float, float], a: list[float]) -> float:
    """``(R C R^T)[2, 2]`` for ``R``'s last row ``r`` and ``C``'s entries ``a`` (:func:`_cov_values`):
    a 3x3 covariance's variance about base z."""
    r0, r1, r2 = r
    return ((r0 * a[0] + r1 * a[3] + r2 * a[6]) * r0 + (r0 * a[1] + r1 * a[4] + r2 * a[7]) * r1
            + (r0 * a[2] + r1 * a[5] + r2 * a[8]) * r2)


def imu_in_base(msg: Imu, R_bi: FloatArray | list[float]) -> tuple[BaseImu, list[str]]:
    """The reading rotated into base_link, and the reasons for every part that was dropped
    (scalar maths: every IMU message passes here).  ``R_bi``: the 3x3 mount rotation, or its 9
    entries row by row as a list of floats (a caller that keeps them: no conversion per message)."""
    problems: list[str] = []
    yaw: float | None = None
    yaw_var = math.nan
    tilt: tuple[float, float] | None = None
    tilt_var: tuple[float, float] | None = None
    b = R_bi if isinstance(R_bi, list) else np.asarray(R_bi, dtype=float).ravel().tolist()   # R_bi row-major
    b0, b1, b2, b3, b4, b5, b6, b7, b8 = b
    planar = b2 == 0.0 and b5 == 0.0 and b6 == 0.0 and b7 == 0.0 and b8 == 1.0  # a yaw-only mount (or none)
    q = msg.orientation_xyzw
    if q is not None:
        qa = _unit_floats(q, 4)
        n = math.sqrt(qa[0] * qa[0] + qa[1] * qa[1] + qa[2] * qa[2] + qa[3] * qa[3]) if qa is not None \
            else math.nan
        oc = _cov_values(msg.orientation_cov)
        why = None if oc is None else _cov_ok(oc)
        if not math.isfinite(n) or n < 1e-9:
            problems.append("imu: orientation quaternion all zeros / not finite")
        elif abs(n - 1.0) > QUATERNION_NORM_TOLERANCE:
            problems.append("imu: orientation quaternion not unit length")
        elif why is not None:
            problems.append(f"imu: orientation {why}")
        else:
            assert qa is not None
            w00, w01, w02, w10, w11, w12, w20, w21, w22 = quaternion_matrix(qa[0] / n, qa[1] / n, qa[2] / n,
                                                                            qa[3] / n)
            # R_wb = R_wi @ R_bi^T: the first column and the last row (a planar mount's zeros left out, but in
            # r20, whose zero's sign the pitch keeps)
            if planar:
                r00, r10, r20 = w00 * b0 + w01 * b1, w10 * b0 + w11 * b1, w20 * b0 + w21 * b1 + w22 * b2
                r21, r22 = w20 * b3 + w21 * b4, w22
            else:
                r00 = w00 * b0 + w01 * b1 + w02 * b2
                r10 = w10 * b0 + w11 * b1 + w12 * b2
                r20 = w20 * b0 + w21 * b1 + w22 * b2
                r21 = w20 * b3 + w21 * b4 + w22 * b5
                r22 = w20 * b6 + w21 * b7 + w22 * b8
            yaw = math.atan2(r10, r00)
            tilt = (math.atan2(r21, r22), math.asin(max(-1.0, min(1.0, -r20))))
            if oc is not None:
                yaw_var = _zz((b6, b7, b8), oc)
                if not yaw_var > 0:
                    yaw_var = math.nan
                tilt_var = (_zz((b0, b1, b2), oc), _zz((b3, b4, b5), oc))
    rate: float | None = None
    rate_var = math.nan
    heading_rate: float | None = None
    w = msg.angular_velocity_radps
    if w is not None:
        wa = _unit_floats(w, 3)
        wc = _cov_values(msg.angular_velocity_cov)
        why = None if wc is None else _cov_ok(wc)
        if wa is None or not (math.isfinite(wa[0]) and math.isfinite(wa[1]) and math.isfinite(wa[2])):
            problems.append("imu: angular velocity not finite")
        elif why is not None:
            problems.append(f"imu: angular velocity {why}")
        else:
            if planar:
                wb1, wb2 = b3 * wa[0] + b4 * wa[1], wa[2]
            else:
                wb1 = b3 * wa[0] + b4 * wa[1] + b5 * wa[2]
                wb2 = b6 * wa[0] + b7 * wa[1] + b8 * wa[2]
            rate = wb2
            if tilt is not None:
                cp = math.cos(tilt[1])
                if cp > 0.1:
                    heading_rate = (math.sin(tilt[0]) * wb1 + math.cos(tilt[0]) * wb2) / cp
            if wc is not None:
                rate_var = _zz((b6, b7, b8), wc)
                if not rate_var > 0:
                    rate_var = math.nan
    return BaseImu(float(msg.stamp), yaw, yaw_var, rate, rate_var, tilt, heading_rate, tilt_var), problems


def imu_message(stamp: float, R_world_base: FloatArray, w_base: FloatArray, R_bi: FloatArray,
                orientation_cov_base: FloatArray | None, angular_velocity_cov_base: FloatArray | None,
                frame_id: str = "imu_link", with_orientation: bool = True) -> Imu:
    """The :class:`Imu` message a sensor mounted with ``R_bi`` publishes for a base state
    (the inverse of :func:`imu_in_base`; the simulator uses it)."""
    from scipy.spatial.transform import Rotation  # (the simulator's path; run time never imports scipy's)

    R_wi = np.asarray(R_world_base, dtype=float) @ R_bi
    q = Rotation.from_matrix(R_wi).as_quat() if with_orientation else None
    w_imu = R_bi.T @ np.asarray(w_base, dtype=float)
    oc = None if orientation_cov_base is None else R_bi.T @ np.asarray(orientation_cov_base) @ R_bi
    wc = None if angular_velocity_cov_base is None else R_bi.T @ np.asarray(angular_velocity_cov_base) @ R_bi
    return Imu(float(stamp), None if q is None else np.asarray(q, dtype=float), w_imu,
               None if q is None else oc, wc, frame_id=frame_id)

#: deg: a median up direction further than this from an IMU's z axis is a mount, not a slope
#: (:func:`up_direction`; no ground robot drives on such a slope)
TILT_DEG = 30.0


def up_direction(messages: list[Imu]) -> FloatArray | None:
    """The median (normalised) up direction in the sensor's frame of ``messages``
    (:class:`~fgloc.types.Imu`): from their orientation where they carry one, else from their linear
    acceleration; None when neither gives one, or when the two disagree by more than
    :data:`TILT_DEG` (an orientation referenced to another world frame than the axes it rotates, NED
    over FLU: no telling which is the sensor's)."""
    by_orientation, by_gravity = [], []
    for m in messages:
        q = getattr(m, "orientation_xyzw", None)
        if q is not None:
            qa = np.asarray(q, dtype=float).reshape(-1)
            n = float(np.linalg.norm(qa)) if qa.shape == (4,) else 0.0
            if math.isfinite(n) and abs(n - 1.0) < 0.1:
                r = np.array(quaternion_matrix(*(qa / n))).reshape(3, 3)  # sensor -> world
                by_orientation.append(r[2, :])  # the world's z axis in the sensor's axes
        a = getattr(m, "linear_acceleration_mps2", None)
        if a is not None:
            v = np.asarray(a, dtype=float).reshape(-1)
            n = float(np.linalg.norm(v)) if v.shape == (3,) else 0.0
            if math.isfinite(n) and 5.0 < n < 15.0:  # about g: a reading, not zeros or a shock
                by_gravity.append(v / n)
    medians = [_median_unit(u) for u in (by_orientation, by_gravity)
               if len(u) >= max(3, len(messages) // 2)]
    ups = [u for u in medians if u is not None]
    if len(ups) == 2 and float(ups[0] @ ups[1]) < math.cos(math.radians(TILT_DEG)):
        return None
    return ups[0] if ups else None


def _median_unit(vectors: list[FloatArray]) -> FloatArray | None:
    med = np.median(np.asarray(vectors), axis=0)
    n = float(np.linalg.norm(med))
    return med / n if n > 1e-6 else None


def levelling_quaternion(up: FloatArray) -> list[float]:
    """``[qx, qy, qz, qw]`` of the smallest rotation taking the sensor's ``up`` onto z (the mount
    ``base -> sensor``: a vector in the sensor's axes turned into the base's); upside down (up along
    -z): a roll of 180 deg."""
    u = np.asarray(up, dtype=float)
    axis = np.cross(u, [0.0, 0.0, 1.0])
    s, c = float(np.linalg.norm(axis)), float(u[2])
    if s < 1e-9:
        return [0.0, 0.0, 0.0, 1.0] if c > 0 else [1.0, 0.0, 0.0, 0.0]
    angle = math.atan2(s, c)
    k = axis / s * math.sin(angle / 2)
    return [float(k[0]), float(k[1]), float(k[2]), math.cos(angle / 2)]
