"""Factor-graph building blocks shared by the fixed-lag and the batch smoother.

* :func:`integrate_twist` - body twists ``[vx, vy, wz]`` integrated between two
  keyframes into a relative ``Pose2`` with its covariance propagated in GTSAM's
  right-perturbation (body) tangent space; works for differential drive (``vy``
  measured as 0 with a small variance: the non-holonomic constraint) and mecanum
  alike.  It becomes a plain C++ ``BetweenFactorPose2``.
* :func:`compass_factor` - a ``CustomFactor`` on (``Pose2`` keyframe, ``Rot2``
  compass-to-map offset): ``e = wrap(theta + offset - z_compass)``, analytic
  Jacobians ``[0, 0, 1]`` and ``[1]``.  GTSAM has no C++ factor tying a
  ``Pose2`` heading to a separate rotation variable, hence the custom factor.
* :func:`fix_factor` - the front-end's map fix as a C++ ``PriorFactorPose2`` whose
  Gaussian is the fix covariance rotated into the body frame, wrapped in a robust
  kernel (Huber or Cauchy) so one wrong fix cannot drag the trajectory.

Conventions: GTSAM's ``Pose2`` tangent vector is ``[dx, dy, dtheta]`` in the body
frame, ``retract(xi) = pose * Expmap(xi)``.
"""

from __future__ import annotations

import math

import gtsam
import numpy as np
from numpy.typing import NDArray

from fgloc.geometry import wrap_scalar

FloatArray = NDArray[np.float64]


# ---------------------------------------------------------------------- twist integration
def integrate_twist(stamps: FloatArray, twists: FloatArray, covs: FloatArray, t0: float, t1: float,
                    q_slip: FloatArray | None = None) -> tuple[FloatArray, FloatArray]:
    """Relative pose ``[x, y, yaw]`` (in the frame of the pose at ``t0``) and its 3x3 covariance.

    ``stamps`` (N,), ``twists`` (N, 3) ``[vx_mps, vy_mps, wz_radps]``, ``covs`` (N, 3, 3).
    A wheel-encoder twist stamped ``t_i`` is the mean velocity over ``(t_{i-1}, t_i]``, so it
    is held backwards over that interval; after the last sample the last twist is held.
    Each step of length ``dt`` adds ``Sigma_u dt^2 + q_slip dt`` (``q_slip`` a 3-vector of
    spectral densities for wheel slip / model error), propagated as
    ``Sigma <- Ad(d^-1) Sigma Ad(d^-1)^T + Sigma_step``.
    """
    if t1 <= t0 or len(stamps) == 0:
        return np.zeros(3), np.zeros((3, 3))
    qx, qy, qt = (0.0, 0.0, 0.0) if q_slip is None else (float(q_slip[0]), float(q_slip[1]), float(q_slip[2]))
    # index of the first sample with stamp > t0 (its twist covers t0)
    i = int(np.searchsorted(stamps, t0, side="right"))
    n = len(stamps)
    t = t0
    x = y = th = 0.0
    # covariance entries (symmetric 3x3, scalar maths: ~10x faster than numpy for 3x3)
    p00 = p01 = p02 = p11 = p12 = p22 = 0.0
    while t < t1 - 1e-12:
        j = min(i, n - 1)
        t_next = min(float(stamps[i]), t1) if i < n else t1
        dt = t_next - t
        if dt > 0:
            u = twists[j]
            vx, vy, w = float(u[0]) * dt, float(u[1]) * dt, float(u[2]) * dt
            if abs(w) < 1e-9:
                a, b = 1.0 - w * w / 6.0, w / 2.0
            else:
                a, b = math.sin(w) / w, (1.0 - math.cos(w)) / w
            dx, dy = a * vx - b * vy, b * vx + a * vy
            c, s = math.cos(w), math.sin(w)
            # A = Ad(d^-1) = [[c, s, iy], [-s, c, -ix], [0, 0, 1]], d^-1 = (ix, iy, -w)
            ix, iy = -c * dx - s * dy, s * dx - c * dy
            # B = A P
            b00 = c * p00 + s * p01 + iy * p02
            b01 = c * p01 + s * p11 + iy * p12
            b02 = c * p02 + s * p12 + iy * p22
            b10 = -s * p00 + c * p01 - ix * p02
            b11 = -s * p01 + c * p11 - ix * p12
            b12 = -s * p02 + c * p12 - ix * p22
            # P' = B A^T + Sigma_u dt^2 + q dt
            cu = covs[j]
            dt2 = dt * dt
            n00 = b00 * c + b01 * s + b02 * iy
            n01 = -b00 * s + b01 * c - b02 * ix
            n11 = -b10 * s + b11 * c - b12 * ix
            p00 = n00 + float(cu[0, 0]) * dt2 + qx * dt
            p01 = n01 + float(cu[0, 1]) * dt2
            p02 = b02 + float(cu[0, 2]) * dt2
            p11 = n11 + float(cu[1, 1]) * dt2 + qy * dt
            p12 = b12 + float(cu[1, 2]) * dt2
            p22 = p22 + float(cu[2, 2]) * dt2 + qt * dt
            ct, st = math.cos(th), math.sin(th)
            x, y, th = x + ct * dx - st * dy, y + st * dx + ct * dy, th + w
        t = t_next
        i += 1
    cov = np.array([[p00, p01, p02], [p01, p11, p12], [p02, p12, p22]])
    return np.array([x, y, wrap_scalar(th)]), cov


def integrate_heading(stamps: FloatArray, twists: FloatArray, t0: float, t1: float) -> float:
    """Heading change (rad, unwrapped) from ``t0`` to ``t1``, same hold as :func:`integrate_twist`."""
    if t1 <= t0 or len(stamps) == 0:
        return 0.0
    i = int(np.searchsorted(stamps, t0, side="right"))
    n = len(stamps)
    t, th = t0, 0.0
    while t < t1 - 1e-12:
        j = min(i, n - 1)
        t_next = min(float(stamps[i]), t1) if i < n else t1
        th += float(twists[j][2]) * (t_next - t)
        t = t_next
        i += 1
    return th


# ---------------------------------------------------------------------- factors
def between_factor(k0: int, k1: int, delta: FloatArray, cov: FloatArray, min_sigma: float = 1e-4,
                   kernel: str = "none", k: float = 1.345) -> gtsam.BetweenFactorPose2:
    """Integrated-twist factor (C++ ``BetweenFactorPose2``), optionally robust (wheel slip)."""
    c = np.asarray(cov, dtype=float) + np.eye(3) * min_sigma**2
    noise = robust(gtsam.noiseModel.Gaussian.Covariance(c), kernel, k)
    return gtsam.BetweenFactorPose2(k0, k1, gtsam.Pose2(*delta), noise)


def robust(base: gtsam.noiseModel.Base, kernel: str, k: float) -> gtsam.noiseModel.Base:
    if kernel == "huber":
        return gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Huber.Create(k), base)
    if kernel == "cauchy":
        return gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Cauchy.Create(k), base)
    return base


def body_covariance(pose: FloatArray, cov_map: FloatArray) -> FloatArray:
    """A map-frame ``[x, y, yaw]`` covariance expressed in the body frame of ``pose``."""
    c, s = np.cos(pose[2]), np.sin(pose[2])
    Rt = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    out = Rt @ np.asarray(cov_map, dtype=float) @ Rt.T
    return 0.5 * (out + out.T)


def fix_factor(key: int, pose: FloatArray, cov_map: FloatArray, kernel: str = "huber",
               k: float = 1.345) -> gtsam.PriorFactorPose2:
    """Scan-to-map fix as a robust ``PriorFactorPose2``."""
    base = gtsam.noiseModel.Gaussian.Covariance(body_covariance(pose, cov_map))
    return gtsam.PriorFactorPose2(key, gtsam.Pose2(*pose), robust(base, kernel, k))


def compass_error(theta: float, offset: float, z: float) -> float:
    """Compass residual ``wrap(theta + offset - z)`` (radians)."""
    return wrap_scalar(theta + offset - z)


def compass_factor(pose_key: int, offset_key: int, z_compass: float, sigma: float,
                   kernel: str = "huber", k: float = 1.345) -> gtsam.CustomFactor:
    """Compass heading on a ``Pose2`` keyframe against a ``Rot2`` compass-to-map offset."""
    z = float(z_compass)

    def error(this: gtsam.CustomFactor, values: gtsam.Values, H: list | None) -> FloatArray:
        pose = values.atPose2(this.keys()[0])
        off = values.atRot2(this.keys()[1])
        e = compass_error(pose.theta(), off.theta(), z)
        if H is not None:
            H[0] = np.array([[0.0, 0.0, 1.0]])
            H[1] = np.array([[1.0]])
        return np.array([e])

    noise = robust(gtsam.noiseModel.Isotropic.Sigma(1, sigma), kernel, k)
    return gtsam.CustomFactor(noise, [pose_key, offset_key], error)
