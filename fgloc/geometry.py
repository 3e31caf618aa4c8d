"""SE(2) helpers on plain numpy arrays.

A pose is a 1-D array ``[x_m, y_m, yaw_rad]`` (index constants ``X, Y, YAW``);
arrays of poses have shape ``(N, 3)``.  All functions broadcast over leading
dimensions.  Angles are radians, wrapped to ``[-pi, pi)``.

Frames follow REP 103 (x forward, y left, z up, yaw counter-clockwise).
``compose(a, b)`` is ``a (+) b``: the pose ``b`` expressed in frame ``a``
mapped to the parent frame of ``a``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

X, Y, YAW = 0, 1, 2

FloatArray = NDArray[np.float64]


def wrap_angle(a: ArrayLike) -> FloatArray | float:
    """Wrap angle(s) in radians to ``[-pi, pi)``."""
    w = (np.asarray(a, dtype=float) + np.pi) % (2.0 * np.pi) - np.pi
    return float(w) if np.ndim(w) == 0 else w


def compose(a: ArrayLike, b: ArrayLike) -> FloatArray:
    """``a (+) b`` for SE(2) poses ``[x, y, yaw]`` (broadcasting)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    c, s = np.cos(a[..., YAW]), np.sin(a[..., YAW])
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., X] = a[..., X] + c * b[..., X] - s * b[..., Y]
    out[..., Y] = a[..., Y] + s * b[..., X] + c * b[..., Y]
    out[..., YAW] = wrap_angle(a[..., YAW] + b[..., YAW])
    return out


def inverse(a: ArrayLike) -> FloatArray:
    """Inverse of SE(2) pose(s)."""
    a = np.asarray(a, dtype=float)
    c, s = np.cos(a[..., YAW]), np.sin(a[..., YAW])
    out = np.empty_like(a)
    out[..., X] = -c * a[..., X] - s * a[..., Y]
    out[..., Y] = s * a[..., X] - c * a[..., Y]
    out[..., YAW] = wrap_angle(-a[..., YAW])
    return out


def between(a: ArrayLike, b: ArrayLike) -> FloatArray:
    """Relative pose ``a^-1 (+) b`` (b expressed in the frame of a)."""
    return compose(inverse(a), b)


def wrap_scalar(a: float) -> float:
    """Wrap one angle in radians to ``[-pi, pi)`` (scalar maths: fast on hot paths): :func:`wrap_angle`'s
    value bit for bit (Python's float ``%`` is numpy's remainder), NaN for an angle that is not finite."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def compose1(a: Any, b: Any) -> FloatArray:
    """``a (+) b`` for single poses (scalar maths: fast for per-message hot paths)."""
    return np.array(compose_values(a, b))


def compose_values(a: Any, b: Any) -> tuple[float, float, float]:
    """:func:`compose1` as a tuple of floats (no array: a pose carried on per message)."""
    a0, a1, a2 = float(a[0]), float(a[1]), float(a[2])
    b0, b1, b2 = float(b[0]), float(b[1]), float(b[2])
    c, s = math.cos(a2), math.sin(a2)
    return a0 + c * b0 - s * b1, a1 + s * b0 + c * b1, wrap_scalar(a2 + b2)


def inverse1(p: Any) -> tuple[float, float, float]:
    """:func:`inverse` of one pose in scalar maths, as a tuple (the same operations, the same bits;
    numpy on a 3-vector costs ~10 us per call)."""
    x, y, yaw = float(p[0]), float(p[1]), float(p[2])
    c, s = math.cos(yaw), math.sin(yaw)
    return -c * x - s * y, s * x - c * y, (-yaw + math.pi) % (2.0 * math.pi) - math.pi


def between_values(a: Any, b: Any) -> tuple[float, float, float]:
    """:func:`between` (``a^-1 (+) b``) of two single poses in scalar maths, as a tuple: the same
    operations in the same order (the same bits where numpy's and libm's cos / sin agree)."""
    a0, a1, a2 = float(a[0]), float(a[1]), float(a[2])
    b0, b1, b2 = float(b[0]), float(b[1]), float(b[2])
    c, s = math.cos(a2), math.sin(a2)
    i0 = -c * a0 - s * a1
    i1 = s * a0 - c * a1
    i2 = (-a2 + math.pi) % (2.0 * math.pi) - math.pi
    c, s = math.cos(i2), math.sin(i2)
    return i0 + c * b0 - s * b1, i1 + s * b0 + c * b1, (i2 + b2 + math.pi) % (2.0 * math.pi) - math.pi


def between1(a: Any, b: Any) -> FloatArray:
    """:func:`between_values` as an array (the array :func:`between` costs ~15 us per call)."""
    return np.array(between_values(a, b))


def exp_values(twist: Any, dt: float) -> tuple[float, float, float]:
    """:func:`exp` of ``twist * dt`` (a body twist held for ``dt``) in scalar maths, as a tuple: the
    same operations on the same values (numpy's element-wise product is the float product)."""
    vx, vy, w = float(twist[0]) * dt, float(twist[1]) * dt, float(twist[2]) * dt
    c, s = exp_coefficients(w)
    return c * vx - s * vy, s * vx + c * vy, w


def with_rotation(delta: FloatArray, rotation: float, speed_gain: float = 1.0) -> FloatArray:
    """An SE(2) increment of a constant twist, its rotation replaced by ``rotation`` (rad) and its
    translation speed times ``speed_gain`` (the arc keeps its shape as a constant twist)."""
    u = log(np.asarray(delta, dtype=float))
    u[:2] *= speed_gain
    u[2] = rotation
    return exp(u)


def exp(xi: FloatArray) -> FloatArray:
    """SE(2) exponential of a tangent vector ``[vx dt, vy dt, w dt]`` -> pose ``[x, y, yaw]``.

    The pose reached by holding a constant body twist for ``dt`` (GTSAM's ``Pose2.Expmap``).
    """
    vx, vy, w = float(xi[0]), float(xi[1]), float(xi[2])
    c, s = exp_coefficients(w)
    return np.array([c * vx - s * vy, s * vx + c * vy, w])


def exp_coefficients(w: float) -> tuple[float, float]:
    """``sin(w) / w`` and ``(1 - cos(w)) / w``: the exponential's ``V = [[a, -b], [b, a]]`` that
    turns a body displacement held while turning by ``w`` into the translation (second order
    below ``|w| = 1e-9``).  For scalar loops that integrate twists step by step."""
    if abs(w) < 1e-9:
        return 1.0 - w * w / 6.0, w / 2.0
    return math.sin(w) / w, (1.0 - math.cos(w)) / w


def log(p: FloatArray) -> FloatArray:
    """SE(2) logarithm of a pose ``[x, y, yaw]`` -> tangent ``[vx dt, vy dt, w dt]`` (inverse of :func:`exp`)."""
    x, y = float(p[0]), float(p[1])
    w = math.atan2(math.sin(float(p[2])), math.cos(float(p[2])))
    c, s = exp_coefficients(w)
    det = c * c + s * s
    return np.array([(c * x + s * y) / det, (-s * x + c * y) / det, w])


def exp_along(twist: ArrayLike, tau: ArrayLike) -> FloatArray:
    """Poses ``(N, 3)`` reached after times ``tau`` (N,) at the constant body twist ``[vx, vy, w]``."""
    tw = np.asarray(twist, dtype=float)
    tau = np.asarray(tau, dtype=float)
    vx, vy, w = float(tw[0]), float(tw[1]), float(tw[2])
    th = w * tau
    out = np.empty((len(tau), 3))
    if abs(w) < 1e-12:
        out[:, 0] = vx * tau
        out[:, 1] = vy * tau
    else:
        s, c1 = np.sin(th), 1.0 - np.cos(th)
        out[:, 0] = (vx * s - vy * c1) / w
        out[:, 1] = (vx * c1 + vy * s) / w
    out[:, 2] = th
    return out


def adjoint(p: ArrayLike) -> FloatArray:
    """Adjoint map of pose ``p`` (``Ad_p xi = Log(p Exp(xi) p^-1)`` to first order), as GTSAM's."""
    p = np.asarray(p, dtype=float)
    c, s = np.cos(p[2]), np.sin(p[2])
    return np.array([[c, -s, p[1]], [s, c, -p[0]], [0.0, 0.0, 1.0]])


def transform_points(pose: ArrayLike, points: ArrayLike) -> FloatArray:
    """Map points ``(N, 2)`` from the frame of ``pose`` into its parent frame."""
    pose = np.asarray(pose, dtype=float)
    pts = np.asarray(points, dtype=float)
    c, s = np.cos(pose[YAW]), np.sin(pose[YAW])
    out = np.empty_like(pts)
    out[:, 0] = pose[X] + c * pts[:, 0] - s * pts[:, 1]
    out[:, 1] = pose[Y] + s * pts[:, 0] + c * pts[:, 1]
    return out


def rot2(yaw: float) -> FloatArray:
    """2x2 rotation matrix."""
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s], [s, c]])


def to_matrix(pose: ArrayLike) -> FloatArray:
    """3x3 homogeneous matrix of a pose."""
    p = np.asarray(pose, dtype=float)
    m = np.eye(3)
    m[:2, :2] = rot2(p[YAW])
    m[:2, 2] = p[:2]
    return m


def to_matrix4(pose: ArrayLike) -> FloatArray:
    """4x4 homogeneous matrix of a planar pose (z = 0, rotation about z)."""
    p = np.asarray(pose, dtype=float)
    m = np.eye(4)
    c, s = math.cos(float(p[YAW])), math.sin(float(p[YAW]))
    m[:2, :2] = [[c, -s], [s, c]]
    m[0, 3], m[1, 3] = p[X], p[Y]
    return m


def from_matrix(m: ArrayLike) -> FloatArray:
    """Pose ``[x, y, yaw]`` from a 3x3 (or 4x4, z ignored) homogeneous matrix."""
    m = np.asarray(m, dtype=float)
    return np.array([m[0, -1], m[1, -1], np.arctan2(m[1, 0], m[0, 0])])


def yaw_to_quaternion(yaw: ArrayLike) -> FloatArray:
    """Quaternion ``[qx, qy, qz, qw]`` of a rotation about z."""
    yaw = np.asarray(yaw, dtype=float)
    return np.stack(
        [np.zeros_like(yaw), np.zeros_like(yaw), np.sin(yaw / 2), np.cos(yaw / 2)], axis=-1
    )


def quaternion_to_yaw(qx: ArrayLike, qy: ArrayLike, qz: ArrayLike, qw: ArrayLike) -> FloatArray | float:
    """Yaw (rotation about z) of a quaternion, as ROS tf2 ``getYaw`` does."""
    qx, qy, qz, qw = (np.asarray(v, dtype=float) for v in (qx, qy, qz, qw))
    y = np.arctan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
    return float(y) if np.ndim(y) == 0 else y


# ---------------------------------------------------------------------- 3-D rotations in scalar maths
# (scipy's Rotation costs ~15 us per object, and this is every IMU message's path: 47 us per
# message before; these are its formulas, equal to it to the last bits)
def quaternion_matrix(x: float, y: float, z: float, w: float) -> tuple[float, ...]:
    """The rotation matrix (row-major 9-tuple) of the unit quaternion ``(x, y, z, w)``."""
    x2, y2, z2, w2 = x * x, y * y, z * z, w * w
    xy, zw, xz, yw, yz, xw = x * y, z * w, x * z, y * w, y * z, x * w
    return (x2 - y2 - z2 + w2, 2.0 * (xy - zw), 2.0 * (xz + yw),
            2.0 * (xy + zw), -x2 + y2 - z2 + w2, 2.0 * (yz - xw),
            2.0 * (xz - yw), 2.0 * (yz + xw), -x2 - y2 + z2 + w2)


def matrix_quaternion(R: FloatArray) -> FloatArray:
    """The unit quaternion ``[x, y, z, w]`` of a rotation matrix (3x3; Shepperd's method, as scipy's
    ``Rotation.from_matrix``: the largest of the trace and the diagonal picks the stable formula)."""
    m = np.asarray(R, dtype=float).reshape(3, 3).tolist()
    tr = m[0][0] + m[1][1] + m[2][2]
    diag = (m[0][0], m[1][1], m[2][2])
    q = [0.0, 0.0, 0.0, 0.0]
    i = max(range(3), key=lambda a: diag[a])
    if diag[i] >= tr:
        j, k = (i + 1) % 3, (i + 2) % 3
        q[i] = 1.0 - tr + 2.0 * m[i][i]
        q[j] = m[j][i] + m[i][j]
        q[k] = m[k][i] + m[i][k]
        q[3] = m[k][j] - m[j][k]
    else:
        q = [m[2][1] - m[1][2], m[0][2] - m[2][0], m[1][0] - m[0][1], 1.0 + tr]
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return np.array([v / n for v in q])


def rpy_quaternion(roll: float, pitch: float, yaw: float) -> FloatArray:
    """``[x, y, z, w]`` of roll, pitch, yaw (rad) about the fixed x, y, z axes (REP 103; scipy's
    ``Rotation.from_euler("xyz", ...)``): ``q = q_z(yaw) q_y(pitch) q_x(roll)``."""
    cr, sr = math.cos(0.5 * roll), math.sin(0.5 * roll)
    cp, sp = math.cos(0.5 * pitch), math.sin(0.5 * pitch)
    cy, sy = math.cos(0.5 * yaw), math.sin(0.5 * yaw)
    return np.array([sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
                     cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy])


def rotate_covariance(cov: ArrayLike, yaw: float) -> FloatArray:
    """Rotate a 3x3 ``[x, y, yaw]`` covariance by ``yaw`` (the xy block only)."""
    r = np.eye(3)
    r[:2, :2] = rot2(yaw)
    c = np.asarray(cov, dtype=float)
    return r @ c @ r.T


def mahalanobis2_2x2(e0: float, e1: float, s00: float, s01: float, s10: float, s11: float) -> float:
    """``e^T S^-1 e`` for ``e = (e0, e1)``, ``S = [[s00, s01], [s10, s11]]``; inf when ``S`` is singular
    or the result is not a finite non-negative number."""
    det = s00 * s11 - s01 * s10
    if det == 0.0 or not math.isfinite(det):
        return math.inf
    d2 = (e0 * (s11 * e0 - s01 * e1) + e1 * (s00 * e1 - s10 * e0)) / det
    return d2 if math.isfinite(d2) and d2 >= 0 else math.inf


def mahalanobis2_3x3(e0: float, e1: float, e2: float, s: list[float]) -> float:
    """``e^T S^-1 e`` for the 3x3 matrix ``S`` (its 9 entries row by row) by its adjugate, in scalars (a
    gate per keyframe: ``np.linalg.solve`` costs ~10 us of overhead); inf when ``S`` is singular."""
    a0, a1, a2, a3, a4, a5, a6, a7, a8 = s
    c00, c01, c02 = a4 * a8 - a5 * a7, a2 * a7 - a1 * a8, a1 * a5 - a2 * a4
    c10, c11, c12 = a5 * a6 - a3 * a8, a0 * a8 - a2 * a6, a2 * a3 - a0 * a5
    c20, c21, c22 = a3 * a7 - a4 * a6, a1 * a6 - a0 * a7, a0 * a4 - a1 * a3
    det = a0 * c00 + a1 * c10 + a2 * c20
    if det == 0.0 or not math.isfinite(det):
        return math.inf
    return (e0 * (c00 * e0 + c01 * e1 + c02 * e2) + e1 * (c10 * e0 + c11 * e1 + c12 * e2)
            + e2 * (c20 * e0 + c21 * e1 + c22 * e2)) / det


def interpolate_poses(stamps: ArrayLike, poses: ArrayLike, t: ArrayLike) -> FloatArray:
    """Linear interpolation of poses at times ``t`` (yaw interpolated on the circle).

    ``stamps`` must be increasing; ``t`` outside ``[stamps[0], stamps[-1]]`` is clamped.
    """
    stamps = np.asarray(stamps, dtype=float)
    poses = np.asarray(poses, dtype=float)
    t = np.atleast_1d(np.asarray(t, dtype=float))
    tc = np.clip(t, stamps[0], stamps[-1])
    i1 = np.clip(np.searchsorted(stamps, tc, side="right"), 1, len(stamps) - 1)
    i0 = i1 - 1
    dt = stamps[i1] - stamps[i0]
    f = np.where(dt > 0, (tc - stamps[i0]) / np.where(dt > 0, dt, 1.0), 0.0)
    out = np.empty((len(t), 3))
    out[:, :2] = poses[i0, :2] + f[:, None] * (poses[i1, :2] - poses[i0, :2])
    dyaw = wrap_angle(poses[i1, YAW] - poses[i0, YAW])
    out[:, YAW] = wrap_angle(poses[i0, YAW] + f * dyaw)
    return out
