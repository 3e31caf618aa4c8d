"""Covariances as GTSAM can use them: priors made well-conditioned, bounded variances, and a pose
covariance carried along an odometry increment."""

from __future__ import annotations

import math

import numpy as np

from fgloc.backends.base import FloatArray
from fgloc.geometry import exp as se2_exp

#: a twist variance above this ((m/s)^2, (rad/s)^2) is "not measured" (a source's unused component,
#: robot_localization's 1e6): bounded to it, a weak prior, so the integrated odometry factor stays
#: a well-conditioned system (iSAM2 reports an indeterminate system with 1e6)
TWIST_VAR_MAX = 100.0


#: m^2, m^2, rad^2: the prior of a restart after a solver failure is the last marginal's diagonal,
#: at most this (a restart from the marginal inflated, or with its correlations, can fail again at
#: the next keyframe on a run without any heading source)
RESTART_VAR_MAX = np.array([1.0, 1.0, 1.0])


#: the prior of a start when none is given (m, m, rad)
DEFAULT_INITIAL_SIGMAS = np.array([0.1, 0.1, np.deg2rad(5.0)])


def carried_covariance(cov0_map: FloatArray, pose0: FloatArray, pose1: FloatArray, inc_cov: FloatArray) -> FloatArray:
    """The map-frame covariance of ``pose1 = pose0 (+) d``: ``cov0_map`` (``pose0``'s, map frame) carried
    along, its heading's uncertainty swept over the distance from ``pose0`` to ``pose1``, plus the
    increment's covariance ``inc_cov`` (frame of ``pose0``, as :func:`~fgloc.backends.factors.integrate_twist`
    gives it) rotated into the map."""
    c00, c01, c02, _, c11, c12, _, _, c22 = np.asarray(inc_cov, dtype=float).reshape(9).tolist()
    return carried_covariance_upper(cov0_map, pose0, pose1, c00, c01, c02, c11, c12, c22)


def carried_covariance_upper(cov0_map: FloatArray, pose0: FloatArray, pose1: FloatArray, c00: float, c01: float,
                             c02: float, c11: float, c12: float, c22: float) -> FloatArray:
    """:func:`carried_covariance` with the increment's covariance as its upper triangle (floats)."""
    # J P J^T (J = [[1, 0, -dy], [0, 1, dx], [0, 0, 1]]) plus R c R^T, in scalars (at every prediction)
    dx, dy = float(pose1[0]) - float(pose0[0]), float(pose1[1]) - float(pose0[1])
    p00, p01, p02, _, p11, p12, _, _, p22 = np.asarray(cov0_map, dtype=float).reshape(9).tolist()
    cs, sn = math.cos(float(pose0[2])), math.sin(float(pose0[2]))
    a00 = p00 - 2.0 * dy * p02 + dy * dy * p22 + cs * cs * c00 - 2.0 * cs * sn * c01 + sn * sn * c11
    a01 = p01 + dx * p02 - dy * p12 - dx * dy * p22 + cs * sn * (c00 - c11) + (cs * cs - sn * sn) * c01
    a02 = p02 - dy * p22 + cs * c02 - sn * c12
    a11 = p11 + 2.0 * dx * p12 + dx * dx * p22 + sn * sn * c00 + 2.0 * cs * sn * c01 + cs * cs * c11
    a12 = p12 + dx * p22 + sn * c02 + cs * c12
    a22 = p22 + c22
    return np.fromiter((a00, a01, a02, a01, a11, a12, a02, a12, a22), float, 9).reshape(3, 3)


def timing_covariance(var_s2: float, twist: FloatArray, yaw: float) -> FloatArray:
    """The covariance of a pose read ``dt`` off in time (``dt`` of variance ``var_s2``) while the robot
    moves with body ``twist`` ``(vx, vy, w)``: ``var_s2 * u u^T``, ``u`` the twist with its translation
    rotated by ``yaw`` into the frame the covariance is in."""
    vx, vy, w = float(twist[0]), float(twist[1]), float(twist[2])
    cs, sn = math.cos(yaw), math.sin(yaw)
    u = np.array([cs * vx - sn * vy, sn * vx + cs * vy, w])
    return var_s2 * np.outer(u, u)


def prior_covariance(cov: FloatArray | None, var_max: FloatArray | None = None) -> FloatArray:
    """A prior covariance GTSAM can use: symmetric, finite, positive semi-definite (when it is not,
    its eigenvalues are raised to 1e-6 of the largest), each variance at most ``var_max``; the
    default start prior when ``cov`` is None or not finite.  (The prior factor adds 1e-9 to each
    variance.)"""
    if cov is None:
        return np.diag(DEFAULT_INITIAL_SIGMAS**2)
    c = np.asarray(cov, dtype=float).reshape(3, 3)
    if not np.all(np.isfinite(c)):
        return np.diag(DEFAULT_INITIAL_SIGMAS**2)
    c = 0.5 * (c + c.T)
    w, v = np.linalg.eigh(c)
    if w[0] < 0.0:
        c = (v * np.maximum(w, 1e-6 * max(float(w[-1]), 1e-9))) @ v.T
    return bounded_covariance(c, var_max) if var_max is not None else c


def bounded_covariance(c: FloatArray, var_max: float | FloatArray) -> FloatArray:
    """``c`` with each variance at most ``var_max`` (rows / columns scaled: stays positive definite)."""
    if isinstance(var_max, float) and c[0, 0] <= var_max and c[1, 1] <= var_max and c[2, 2] <= var_max:
        return c  # (the common case, without numpy's per-call overhead)
    d = np.diag(c)
    if np.all(d <= var_max):
        return c
    f = np.sqrt(np.minimum(1.0, np.asarray(var_max, dtype=float) / np.maximum(d, 1e-300)))
    return np.asarray(c, dtype=float) * np.outer(f, f)


def _psd3_upper(a: float, b: float, c: float, d: float, e: float, f: float) -> bool:
    """Whether the symmetric 3x3 matrix of upper triangle ``[[a, b, c], [., d, e], [., ., f]]`` is
    positive semi-definite: every principal minor >= 0 (scalar maths)."""
    if a < 0.0 or d < 0.0 or f < 0.0:
        return False
    if a * d - b * b < 0.0 or a * f - c * c < 0.0 or d * f - e * e < 0.0:
        return False
    return a * (d * f - e * e) - b * (b * f - e * c) + c * (b * e - d * c) >= 0.0


def covariance_bound(p: FloatArray, q: FloatArray) -> FloatArray:
    """A covariance at least as large as both ``p`` and ``q`` in every direction (``x^T B x >= max(x^T p x,
    x^T q x)``): the larger one when one holds the other (checked in scalars: the common case), else
    ``q`` whitened by ``p``'s Cholesky factor, its eigenvalues raised to at least 1, coloured back;
    ``q`` when ``p`` is not positive definite."""
    a = np.asarray(p, dtype=float).reshape(3, 3)
    b = np.asarray(q, dtype=float).reshape(3, 3)
    a0, a1, a2, _, a4, a5, _, _, a8 = a.ravel().tolist()
    b0, b1, b2, _, b4, b5, _, _, b8 = b.ravel().tolist()
    if _psd3_upper(a0 - b0, a1 - b1, a2 - b2, a4 - b4, a5 - b5, a8 - b8):
        return a
    if _psd3_upper(b0 - a0, b1 - a1, b2 - a2, b4 - a4, b5 - a5, b8 - a8):
        return b
    try:
        L = np.linalg.cholesky(0.5 * (a + a.T))
    except np.linalg.LinAlgError:
        return b.copy()
    Li = np.linalg.inv(L)
    w, v = np.linalg.eigh(Li @ (0.5 * (b + b.T)) @ Li.T)
    if w[-1] <= 1.0:
        return a
    M = L @ v
    return (M * np.maximum(w, 1.0)) @ M.T


def carried_motion(twist: tuple[FloatArray, FloatArray] | None, sigma: tuple[float, float, float], qv: float,
                   qw: float, dt: float) -> tuple[FloatArray, FloatArray]:
    """The motion over ``dt`` seconds without any odometry (scans on a map): ``twist`` (the body
    twist ``[vx, vy, w]`` the graph's keyframes moved with and its variances) carried on at constant
    velocity, its variance over the time plus a random walk of the velocity over it (``qv``
    (m/s)^2/s, ``qw`` (rad/s)^2/s); without a twist (the keyframes show none yet), none, with the
    sigmas ``sigma``."""
    if not dt > 0.0:
        return np.zeros(3), np.zeros((3, 3))
    if twist is None:
        tw, var = np.zeros(3), np.square(np.asarray(sigma, dtype=float))
    else:
        tw, var = twist
    return se2_exp(tw * dt), np.diag(var * dt * dt + np.array([qv, qv, qw]) * dt ** 3 / 3.0)

