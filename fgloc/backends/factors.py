"""Factor-graph building blocks shared by the fixed-lag and the batch smoother.

* :func:`between_factor` - the odometry increment between two keyframes
  (:func:`fgloc.backends.integration.integrate_twist`) as a plain C++ ``BetweenFactorPose2``
  (:func:`scaled_between_factor`: with the odometry's speed and yaw-rate scales estimated).
* :func:`compass_factor` - the compass heading on a ``Pose2`` keyframe against the
  compass-to-map offset, ``e = wrap(theta + offset - z_compass)``: the offset variable is the
  compass frame's pose ``Pose2(0, 0, -offset)``, the factor a C++ ``BetweenFactorPose2`` from it
  to the keyframe that measures the heading only (the gyro's :func:`yaw_increment_factor` too).
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


def pose2(v: FloatArray) -> gtsam.Pose2:
    """``gtsam.Pose2`` of ``[x, y, yaw]`` from Python floats (numpy scalars cost pybind11's overload
    resolution ~2 us more per pose, several per keyframe)."""
    return gtsam.Pose2(float(v[0]), float(v[1]), float(v[2]))


def between_factor(k0: int, k1: int, delta: FloatArray, cov: FloatArray, min_sigma: float = 1e-4,
                   kernel: str = "none", k: float = 1.345) -> gtsam.BetweenFactorPose2:
    """Integrated-twist factor (C++ ``BetweenFactorPose2``), optionally robust (wheel slip)."""
    c = np.asarray(cov, dtype=float) + _floor(min_sigma)
    noise = robust(gtsam.noiseModel.Gaussian.Covariance(c), kernel, k)
    return gtsam.BetweenFactorPose2(k0, k1, pose2(delta), noise)


_FLOORS: dict[float, FloatArray] = {}
_KERNELS: dict[tuple[str, float], gtsam.noiseModel.mEstimator.Base] = {}
#: kernels kept at most: the configured scales are the first asked for and stay; a scale computed per
#: factor (the compass's, from its innovation variance) is made for that factor only
KERNELS_KEPT = 32


def _floor(min_sigma: float) -> FloatArray:
    """``np.eye(3) * min_sigma**2``, made once per sigma (every factor adds it)."""
    f = _FLOORS.get(min_sigma)
    if f is None:
        f = _FLOORS[min_sigma] = np.eye(3) * min_sigma**2
        f.flags.writeable = False
    return f


_HEADING_NOISE: dict[float, gtsam.noiseModel.Diagonal] = {}
#: heading noise models kept at most (a compass's sigma takes a few values: its reading's, averaged
#: over one or two readings per keyframe; a sigma computed per factor is made for that factor only)
HEADING_NOISE_KEPT = 32


def heading_noise(sigma: float) -> gtsam.noiseModel.Diagonal:
    """The diagonal noise ``[inf, inf, sigma]`` of a heading-only ``Pose2`` factor (its translation rows
    weigh nothing), made once per sigma (noise models are immutable: factors share them), the first
    :data:`HEADING_NOISE_KEPT` sigmas kept."""
    sigma = float(sigma)
    m = _HEADING_NOISE.get(sigma)
    if m is None:
        m = gtsam.noiseModel.Diagonal.Sigmas(np.array([np.inf, np.inf, sigma]))
        if len(_HEADING_NOISE) < HEADING_NOISE_KEPT:
            _HEADING_NOISE[sigma] = m
    return m


def kernels_cached() -> int:
    """How many robust kernels :func:`robust` keeps (at most :data:`KERNELS_KEPT`)."""
    return len(_KERNELS)


def robust(base: gtsam.noiseModel.Base, kernel: str, k: float) -> gtsam.noiseModel.Base:
    """``base`` behind a Huber / Cauchy kernel of scale ``k`` (``none``: as it is); the kernel
    objects (stateless) are shared per scale, the first :data:`KERNELS_KEPT` scales kept."""
    if kernel not in ("huber", "cauchy"):
        return base
    m = _KERNELS.get((kernel, k))
    if m is None:
        est = gtsam.noiseModel.mEstimator.Huber if kernel == "huber" else gtsam.noiseModel.mEstimator.Cauchy
        m = est.Create(k)
        if len(_KERNELS) < KERNELS_KEPT:
            _KERNELS[(kernel, k)] = m
    return gtsam.noiseModel.Robust.Create(m, base)


def body_covariance(pose: FloatArray, cov_map: FloatArray) -> FloatArray:
    """A map-frame ``[x, y, yaw]`` covariance expressed in the body frame of ``pose``."""
    c, s = math.cos(float(pose[2])), math.sin(float(pose[2]))
    a = np.asarray(cov_map, dtype=float).reshape(9).tolist()
    # Rt = [[c, s, 0], [-s, c, 0], [0, 0, 1]]: M = Rt C (rows), out = M Rt^T (scalar maths: per fix)
    m0 = (c * a[0] + s * a[3], c * a[1] + s * a[4], c * a[2] + s * a[5])
    m1 = (-s * a[0] + c * a[3], -s * a[1] + c * a[4], -s * a[2] + c * a[5])
    m2 = (a[6], a[7], a[8])
    o00 = c * m0[0] + s * m0[1]
    o01 = -s * m0[0] + c * m0[1]
    o02 = m0[2]
    o10 = c * m1[0] + s * m1[1]
    o11 = -s * m1[0] + c * m1[1]
    o12 = m1[2]
    o20 = c * m2[0] + s * m2[1]
    o21 = -s * m2[0] + c * m2[1]
    o22 = m2[2]
    return np.fromiter((o00, 0.5 * (o01 + o10), 0.5 * (o02 + o20),
                        0.5 * (o10 + o01), o11, 0.5 * (o12 + o21),
                        0.5 * (o20 + o02), 0.5 * (o21 + o12), o22), float, 9).reshape(3, 3)


def fix_factor(key: int, pose: FloatArray, cov_map: FloatArray, kernel: str = "huber",
               k: float = 1.345) -> gtsam.PriorFactorPose2:
    """Scan-to-map fix as a robust ``PriorFactorPose2``."""
    base = gtsam.noiseModel.Gaussian.Covariance(body_covariance(pose, cov_map))
    return gtsam.PriorFactorPose2(key, pose2(pose), robust(base, kernel, k))


def offset_pose(offset: float) -> gtsam.Pose2:
    """The compass-offset variable's value for ``offset`` (``compass_yaw = map_yaw + offset``):
    the compass frame's pose in the map, ``(0, 0, -offset)`` (see :func:`compass_factor`)."""
    return gtsam.Pose2(0.0, 0.0, -float(offset))


def pose_offset(p: gtsam.Pose2) -> float:
    """The compass-to-map offset (rad) of a compass-offset variable (:func:`offset_pose`)."""
    return -float(p.theta())


def compass_factor(pose_key: int, offset_key: int, z_compass: float, sigma: float,
                   kernel: str = "huber", k: float = 1.345) -> gtsam.BetweenFactorPose2:
    """Compass heading on a ``Pose2`` keyframe against the compass-to-map offset, error
    ``wrap(theta + offset - z)`` with Jacobians ``[0, 0, 1]`` (keyframe) and ``-1`` (the offset
    variable's heading).

    The offset variable is the compass frame's pose in the map, ``Pose2(0, 0, -offset)``
    (:func:`offset_pose`; its position is held at 0 by its prior and random walk and enters no
    other factor): the keyframe seen from it, ``o^-1 x``, has the heading ``theta + offset`` the
    compass reports, so the factor is a C++ ``BetweenFactorPose2`` from ``o`` to ``x`` measuring
    ``(0, 0, z)`` whose translation rows have infinite sigmas (they weigh nothing).  (A Python
    ``CustomFactor`` on a ``Rot2`` offset cost ~11 us per linearization.)"""
    noise = robust(heading_noise(sigma), kernel, k)
    return gtsam.BetweenFactorPose2(int(offset_key), int(pose_key), gtsam.Pose2(0.0, 0.0, float(z_compass)), noise)


def heading_factor(pose_key: int, z_yaw: float, sigma: float, kernel: str = "huber",
                   k: float = 1.345) -> gtsam.PriorFactorPose2:
    """A heading in the map frame on a ``Pose2`` keyframe, error ``wrap(theta - z)`` (a compass
    whose offset to the map is known): a C++ ``PriorFactorPose2`` on ``(0, 0, z)`` whose translation
    rows have infinite sigmas (the rotation row of its error is the heading difference alone)."""
    noise = robust(heading_noise(sigma), kernel, k)
    return gtsam.PriorFactorPose2(int(pose_key), gtsam.Pose2(0.0, 0.0, float(z_yaw)), noise)


def relative_yaw_error(theta: float, offset: float, z: float) -> float:
    """Residual ``wrap(theta + offset - z)`` (radians) of :func:`relative_yaw_factor`."""
    return wrap_scalar(theta + offset - z)


def relative_yaw_factor(pose_key: int, offset_key: int, z_yaw: float, sigma: float,
                        kernel: str = "huber", k: float = 1.345) -> gtsam.CustomFactor:
    """A differential orientation source's yaw ``z`` (robot_localization's ``imuN_differential``:
    an AHRS or a visual odometer whose heading frame is its own) on a ``Pose2`` keyframe against
    the source's own offset ``c`` (a ``Vector1`` chain, not the compass's ``Rot2``): ``z = theta + c``,
    error ``wrap(theta + c - z)``, Jacobians ``[0, 0, 1]`` and ``[1]``.  With ``c`` free (a loose
    prior at the first reading, a random walk after) only the source's increments inform the
    headings, whatever its stamps' jitter."""
    z = float(z_yaw)
    kp, ko = int(pose_key), int(offset_key)
    h0, h1 = np.array([[0.0, 0.0, 1.0]]), np.array([[1.0]])  # constant (GTSAM copies them)

    def error(this: gtsam.CustomFactor, values: gtsam.Values, H: list | None) -> FloatArray:
        e = relative_yaw_error(values.atPose2(kp).theta(), float(values.atVector(ko)[0]), z)
        if H is not None:
            H[0] = h0
            H[1] = h1
        return np.array([e])

    noise = robust(gtsam.noiseModel.Isotropic.Sigma(1, max(float(sigma), 1e-6)), kernel, k)
    return gtsam.CustomFactor(noise, [kp, ko], error)


# ---------------------------------------------------------------------- calibration factors
_ZERO32 = np.zeros((3, 2))
_ZERO32.flags.writeable = False


def _sinc(x: float) -> float:
    return 1.0 - x * x / 6.0 if abs(x) < 1e-4 else math.sin(x) / x


def _dsinc(x: float) -> float:
    return -x / 3.0 if abs(x) < 1e-4 else (x * math.cos(x) - math.sin(x)) / (x * x)


def scaled_delta(delta: FloatArray, gains: FloatArray | tuple[float, float],
                 jacobian: bool = True) -> tuple[FloatArray, FloatArray]:
    """The relative pose an odometry increment ``delta`` means once corrected by ``gains``.

    ``gains = [g_v, g_w]``: the true speed is ``g_v`` times the reported one, the true yaw rate
    ``g_w`` times (a wheel that reports ``s`` times the motion has gain ``1 / s``).  Exact for a
    constant twist over the interval (the chord of an arc: length ``v T sinc(wT/2)``, direction
    ``wT/2``), first order otherwise.  Returns the pose ``[x, y, yaw]`` and ``J`` (3x2), its
    derivative with respect to the gains in the pose's body tangent space (``jacobian=False``:
    not computed, returned as zeros).
    """
    dx, dy, th0 = float(delta[0]), float(delta[1]), float(delta[2])
    gv, gw = float(gains[0]), float(gains[1])
    tx, ty, th, h0, s0, rho, c, s = _scaled_parts(dx, dy, th0, gv, gw)
    if not jacobian:
        return np.array([tx, ty, th]), _ZERO32
    # d t / d g_v = t / g_v;  d t / d g_w = (d rho/d g_w) R t0 + rho R' t0 h0
    drho = gv * _dsinc(gw * h0) * h0 / s0
    r0x, r0y = c * dx - s * dy, s * dx + c * dy          # R(phi) t0
    dtw_x = drho * r0x - rho * h0 * r0y
    dtw_y = drho * r0y + rho * h0 * r0x
    ct, st = math.cos(th), math.sin(th)
    J = np.array([[ct * (tx / gv) + st * (ty / gv), ct * dtw_x + st * dtw_y],
                  [-st * (tx / gv) + ct * (ty / gv), -st * dtw_x + ct * dtw_y],
                  [0.0, th0]]) if gv != 0 else np.zeros((3, 2))
    return np.array([tx, ty, th]), J


def scaled_delta_values(dx: float, dy: float, th0: float, gv: float, gw: float) -> tuple[float, float, float]:
    """:func:`scaled_delta`'s pose ``(x, y, yaw)`` of the increment ``(dx, dy, th0)`` under the gains
    ``(gv, gw)``, as floats (no array, no Jacobian: the smoother corrects every prediction with it)."""
    return _scaled_parts(dx, dy, th0, gv, gw)[:3]


def _scaled_parts(dx: float, dy: float, th0: float, gv: float, gw: float
                  ) -> tuple[float, float, float, float, float, float, float, float]:
    """:func:`scaled_delta`'s pose ``(x, y, yaw)`` and the terms its Jacobian reuses: the half
    angle, its sinc, the chord's length ratio and the cosine and sine of its turn."""
    h0 = 0.5 * th0
    s0 = _sinc(h0)
    rho = gv * _sinc(gw * h0) / s0
    phi = (gw - 1.0) * h0
    c, s = math.cos(phi), math.sin(phi)
    return rho * (c * dx - s * dy), rho * (s * dx + c * dy), gw * th0, h0, s0, rho, c, s


def pose2_log_and_derivative(x: float, y: float, w: float) -> tuple[float, float, float, tuple]:
    """``Pose2.Logmap`` of ``(x, y, w)`` (``w`` wrapped) and ``Pose2.LogmapDerivative``'s 2x3 top rows,
    in scalar maths (GTSAM's formulas; its Python calls cost ~6 us each, this is the hot path of
    the odometry factors)."""
    if abs(w) < 1e-10:
        v1, v2 = x, y
    else:
        cw, sw = math.cos(w), math.sin(w)
        c1 = cw - 1.0
        f = w / (c1 * c1 + sw * sw)
        ux, uy = cw * x + sw * y - x, -sw * x + cw * y - y
        v1, v2 = -f * uy, f * ux
    if abs(w) > 1e-5:
        ai = 1.0 / w
        h = 0.5 * math.sin(w) / (1.0 - math.cos(w))
        rows = ((w * h, -0.5 * w, v1 * ai - v1 * h + 0.5 * v2), (0.5 * w, w * h, v2 * ai - 0.5 * v1 - v2 * h))
    else:
        rows = ((1.0, 0.0, 0.5 * v2), (0.0, 1.0, -0.5 * v1))
    return v1, v2, w, rows


def _log_against(rx: float, ry: float, rth: float, measured: FloatArray) -> tuple[FloatArray, tuple]:
    """``Log(m^-1 rep)`` for ``rep = (rx, ry, rth)`` and ``m = measured``, with ``d Log / d rep``'s
    left factor from :func:`pose2_log_and_derivative` (the tail shared by the between-factor errors)."""
    v1, v2, v3, jl = _log_against_m(rx, ry, rth, _measured(measured))
    return np.array([v1, v2, v3]), jl


def _measured(measured: FloatArray) -> tuple[float, float, float, float, float]:
    """A between factor's measurement ``(x, y, yaw)`` with ``cos(yaw)``, ``sin(yaw)`` as floats (once per factor)."""
    mx, my, mt = float(measured[0]), float(measured[1]), float(measured[2])
    return mx, my, mt, math.cos(mt), math.sin(mt)


def _log_against_m(rx: float, ry: float, rth: float, m: tuple[float, float, float, float, float]
                   ) -> tuple[float, float, float, tuple]:
    """:func:`_log_against` on a :func:`_measured` measurement, the log as three floats."""
    mx, my, mt, cm, sm = m
    dx, dy = rx - mx, ry - my
    ex, ey = cm * dx + sm * dy, -sm * dx + cm * dy
    return pose2_log_and_derivative(ex, ey, wrap_scalar(rth - mt))


def scaled_between_error(xi: gtsam.Pose2, xj: gtsam.Pose2, scales: FloatArray | tuple[float, float],
                         measured: FloatArray, want_jacobians: bool = True, bend: bool = True,
                         drift: FloatArray | tuple[float, float] | None = None) -> tuple[FloatArray, list[FloatArray]]:
    """Error of :func:`scaled_between_factor`: ``Log(m^-1 rep(xi^-1 xj, s))`` (the noise is on
    what the odometry reports, so a scale never buys a smaller residual by shrinking the motion)
    and its Jacobians (right perturbations of ``xi``, ``xj``; the scales as a plain vector).
    ``bend=False``: the reported translation was integrated along the true heading (a gyro's),
    so the yaw-rate scale does not bend its chord: ``rep = [s_v x, s_v y, s_w yaw]``.  Scalar
    maths (called at every relinearization: the numpy / GTSAM-call version cost ~45 us).
    ``drift = (l_y, l_yaw)``: the odometry also reports ``l_y`` m sideways and ``l_yaw`` rad of turn per
    metre driven forward (:func:`_scaled_between`); its Jacobian is the list's fourth entry (3x2)."""
    h = xi.between(xj)
    dr = None if drift is None else (float(drift[0]), float(drift[1]))
    e0, e1, e2, jac = _scaled_between(h.x(), h.y(), h.theta(), float(scales[0]), float(scales[1]),
                                      _measured(measured), want_jacobians, bend, dr)
    if jac is None:
        return np.array([e0, e1, e2]), []
    hi, hj, hv, hw = jac[:4]
    out = [np.array(hi).reshape(3, 3), np.array(hj).reshape(3, 3), np.array([hv, hw]).T.reshape(3, 2)]
    if dr is not None:
        out.append(np.array(jac[4]).reshape(3, 2))
    return np.array([e0, e1, e2]), out


def _scaled_between(cx: float, cy: float, cth: float, sv: float, sw: float,
                    m: tuple[float, float, float, float, float], want_jacobians: bool, bend: bool,
                    drift: tuple[float, float] | None = None) -> tuple[float, float, float, tuple | None]:
    """:func:`scaled_between_error` on ``c = xi^-1 xj = (cx, cy, cth)``, a :func:`_measured`
    measurement ``m``, in floats: the error's three entries and (``want_jacobians``) the
    Jacobians as flat row-major tuples ``(Hi 3x3, Hj 3x3, Hs_v 3x1, Hs_w 3x1)`` (with ``drift``, and
    ``Hd 3x2`` after them), or None.  ``drift = (l_y, l_yaw)``: the increment the scales apply to is
    ``c`` with ``l_y cx`` added to its sideways part and ``l_yaw cx`` to its turn (a mecanum base's
    unequal wheel radii, a differential drive's unequal wheels: a sideways creep and a turn that
    follow the forward distance).  Unrolled scalar maths without temporary arrays (the factor's
    Python callback runs at every linearization)."""
    c_x, c_y, c_th = cx, cy, cth
    if drift is not None:
        cy, cth = cy + drift[0] * cx, cth + drift[1] * cx
    u_th = cth
    if not bend:
        rth = sw * cth
        rx, ry = sv * cx, sv * cy
        # Jc = [Rt @ [[sv, 0, 0], [0, sv, 0]]; [0, 0, sw]], Js = [Rt @ [[tx, 0], [ty, 0]]; [0, th]]
        ct, st = math.cos(rth), math.sin(rth)
        c00, c01, c02, c10, c11, c12 = ct * sv, st * sv, 0.0, -st * sv, ct * sv, 0.0
        s00, s01, s10, s11 = ct * cx + st * cy, 0.0, -st * cx + ct * cy, 0.0
    else:
        hh = 0.5 * cth
        s0 = _sinc(hh)
        s1 = _sinc(sw * hh)
        rho = sv * s1 / s0
        phi = (sw - 1.0) * hh
        cp, sp = math.cos(phi), math.sin(phi)
        r0x, r0y = cp * cx - sp * cy, sp * cx + cp * cy
        rx, ry, rth = rho * r0x, rho * r0y, sw * cth
        drho_dth = sv * (_dsinc(sw * hh) * 0.5 * sw * s0 - s1 * _dsinc(hh) * 0.5) / (s0 * s0)
        drho_dsw = sv * _dsinc(sw * hh) * hh / s0
        dphi_dth = 0.5 * (sw - 1.0)
        d00, d01, d02 = rho * cp, -rho * sp, drho_dth * r0x - rho * dphi_dth * r0y
        d10, d11, d12 = rho * sp, rho * cp, drho_dth * r0y + rho * dphi_dth * r0x
        e00, e01 = r0x * s1 / s0, drho_dsw * r0x - rho * hh * r0y
        e10, e11 = r0y * s1 / s0, drho_dsw * r0y + rho * hh * r0x
        ct, st = math.cos(rth), math.sin(rth)
        c00, c01, c02 = ct * d00 + st * d10, ct * d01 + st * d11, ct * d02 + st * d12
        c10, c11, c12 = -st * d00 + ct * d10, -st * d01 + ct * d11, -st * d02 + ct * d12
        s00, s01, s10, s11 = ct * e00 + st * e10, ct * e01 + st * e11, -st * e00 + ct * e10, -st * e01 + ct * e11
    # E = m^-1 rep
    v1, v2, v3, jl = _log_against_m(rx, ry, rth, m)
    if not want_jacobians:
        return v1, v2, v3, None
    # Jl @ Jc (Jc's last row [0, 0, sw], Jl's last row [0, 0, 1]), unrolled (the same sums)
    (l00, l01, l02), (l10, l11, l12) = jl
    a00, a01, a02 = l00 * c00 + l01 * c10, l00 * c01 + l01 * c11, l00 * c02 + l01 * c12 + l02 * sw
    a10, a11, a12 = l10 * c00 + l11 * c10, l10 * c01 + l11 * c11, l10 * c02 + l11 * c12 + l12 * sw
    a20 = a21 = 0.0
    hd = None
    if drift is not None:
        # the drifted increment's derivative: d E / d c = A D, D = [[1, 0, 0], [l_y, 1, 0], [l_yaw, 0, 1]]
        # (A's last row [0, 0, sw]); d E / d (l_y, l_yaw) = A's second and third columns times c_x
        hd = (a01 * c_x, a02 * c_x, a11 * c_x, a12 * c_x, 0.0, sw * c_x)
        a00 += drift[0] * a01 + drift[1] * a02
        a10 += drift[0] * a11 + drift[1] * a12
        a20 = drift[1] * sw
        cx, cy, cth = c_x, c_y, c_th
    # d c / d xj = [[ch, -sh, 0], [sh, ch, 0], [0, 0, 1]], d c / d xi = [[-1, 0, cy], [0, -1, -cx], [0, 0, -1]]
    ch, sh = math.cos(cth), math.sin(cth)
    hj = (a00 * ch + a01 * sh, -a00 * sh + a01 * ch, a02,
          a10 * ch + a11 * sh, -a10 * sh + a11 * ch, a12,
          a20 * ch + a21 * sh, -a20 * sh + a21 * ch, sw)
    hi = (-a00, -a01, a00 * cy - a01 * cx - a02,
          -a10, -a11, a10 * cy - a11 * cx - a12,
          -a20, -a21, a20 * cy - a21 * cx - sw)
    hv = (l00 * s00 + l01 * s10, l10 * s00 + l11 * s10, 0.0)
    hw = (l00 * s01 + l01 * s11 + l02 * u_th, l10 * s01 + l11 * s11 + l12 * u_th, u_th)
    if hd is not None:
        return v1, v2, v3, (hi, hj, hv, hw, hd)
    return v1, v2, v3, (hi, hj, hv, hw)


#: the yaw-rate scale (reported / true) used in the odometry's factor stays in the EKF's bounds
YAW_SCALE_MIN, YAW_SCALE_MAX = 0.1, 10.0


def scaled_between_factor(ki: int, kj: int, ks_v: int | None, ks_w: int | None, delta: FloatArray,
                          cov: FloatArray, fixed_scales: tuple[float, float] = (1.0, 1.0), min_sigma: float = 1e-4,
                          kernel: str = "none", k: float = 1.345, bend: bool = True,
                          kd: int | None = None, lateral: bool = True) -> gtsam.NonlinearFactor:
    """Integrated-odometry factor between ``x_i`` and ``x_j`` whose speed scale ``s_v`` and yaw-rate
    scale ``s_w`` (reported / true, each a ``Vector1`` variable, or None: held at ``fixed_scales``)
    are estimated: the odometry's calibration.  ``delta`` / ``cov`` are the reported increment
    and its covariance.  Without a scale variable this is a plain ``BetweenFactorPose2`` on the
    corrected increment.  ``bend=False``: ``delta``'s translation was integrated along a gyro's
    heading (the yaw-rate scale applies to its yaw only).  ``kd``: the odometry's drift per metre
    driven forward (a ``Vector2`` ``(l_y, l_yaw)``, :func:`_scaled_between`) estimated too;
    ``lateral=False``: its sideways part is held at 0 here (an odometry that reports no sideways motion
    cannot creep sideways per metre: the variable's prior alone holds that part)."""
    d = np.asarray(delta, dtype=float).copy()
    c = np.asarray(cov, dtype=float) + _floor(min_sigma)
    if ks_v is None and ks_w is None and kd is None and fixed_scales == (1.0, 1.0):
        return between_factor(ki, kj, d, cov, min_sigma, kernel, k)
    noise = robust(gtsam.noiseModel.Gaussian.Covariance(c), kernel, k)
    keys = [ki, kj] + [kk for kk in (ks_v, ks_w, kd) if kk is not None]
    sv0, sw0 = float(fixed_scales[0]), float(fixed_scales[1])
    kv = int(ks_v) if ks_v is not None else None
    kw = int(ks_w) if ks_w is not None else None
    kdr = int(kd) if kd is not None else None
    k0, k1 = int(ki), int(kj)
    m = _measured(d)

    def error(this: gtsam.CustomFactor, values: gtsam.Values, H: list | None) -> FloatArray:
        sv = float(values.atVector(kv)[0]) if kv is not None else sv0
        sw = float(values.atVector(kw)[0]) if kw is not None else sw0
        sw_held = kw is not None and not (YAW_SCALE_MIN <= sw <= YAW_SCALE_MAX)
        if sw_held:
            # held at the bound, its gradient zero: wheels that report the turn reversed otherwise run
            # the scale away (to 7-12 beside a differential heading and the turn per metre)
            sw = min(max(sw, YAW_SCALE_MIN), YAW_SCALE_MAX)
        dr = None
        if kdr is not None:
            vd = values.atVector(kdr)
            dr = (float(vd[0]) if lateral else 0.0, float(vd[1]))
        h = values.atPose2(k0).between(values.atPose2(k1))
        e0, e1, e2, jac = _scaled_between(h.x(), h.y(), h.theta(), sv, sw, m, H is not None, bend, dr)
        if H is not None and jac is not None:
            hi, hj, hv, hw = jac[:4]
            H[0] = np.array(hi).reshape(3, 3)
            H[1] = np.array(hj).reshape(3, 3)
            n = 2
            if kv is not None:
                H[n] = np.array(hv).reshape(3, 1)
                n += 1
            if kw is not None:
                H[n] = np.zeros((3, 1)) if sw_held else np.array(hw).reshape(3, 1)
                n += 1
            if kdr is not None:
                hd = np.array(jac[4]).reshape(3, 2)
                if not lateral:
                    hd[:, 0] = 0.0
                H[n] = hd
        return np.array([e0, e1, e2])

    return gtsam.CustomFactor(noise, keys, error)


def aligned_between_error(xi: gtsam.Pose2, xj: gtsam.Pose2, ab: FloatArray | tuple[float, float],
                          measured: FloatArray, want_jacobians: bool = True) -> tuple[FloatArray, list[FloatArray]]:
    """Error of :func:`aligned_between_factor`: ``Log(m^-1 rep(xi^-1 xj))`` with
    ``rep = [M t, yaw]``, ``M = [[a, -b], [b, a]]`` (the source reports its translation scaled by
    ``s = |(a, b)|`` and turned by ``atan2(b, a)``: a camera's scale and its yaw misalignment on
    the base), and its Jacobians (right perturbations of ``xi``, ``xj``; ``(a, b)`` as a plain
    vector).  Scalar maths, as :func:`scaled_between_error`'s."""
    h = xi.between(xj)
    cx, cy, cth = h.x(), h.y(), h.theta()
    a_, b_ = float(ab[0]), float(ab[1])
    rx, ry, rth = a_ * cx - b_ * cy, b_ * cx + a_ * cy, cth
    e, jl = _log_against(rx, ry, rth, measured)
    if not want_jacobians:
        return e, []
    # rep's body tangent: Rt(rth) [M | 0] on c's translation, 1 on its yaw; Rt(rth) [[cx, -cy], [cy, cx]] on (a, b)
    ct, st = math.cos(rth), math.sin(rth)
    jc = ((ct * a_ + st * b_, -ct * b_ + st * a_, 0.0), (-st * a_ + ct * b_, st * b_ + ct * a_, 0.0))
    js = ((ct * cx + st * cy, -ct * cy + st * cx), (-st * cx + ct * cy, st * cy + ct * cx))
    a = [[jl[r][0] * jc[0][k] + jl[r][1] * jc[1][k] for k in range(3)] for r in range(2)]
    a[0][2] += jl[0][2]
    a[1][2] += jl[1][2]
    a.append([0.0, 0.0, 1.0])
    ch, sh = math.cos(cth), math.sin(cth)
    Hj = [[r[0] * ch + r[1] * sh, -r[0] * sh + r[1] * ch, r[2]] for r in a]
    Hi = [[-r[0], -r[1], r[0] * cy - r[1] * cx - r[2]] for r in a]
    Hs = [[jl[r][0] * js[0][k] + jl[r][1] * js[1][k] for k in range(2)] for r in range(2)]
    Hs.append([0.0, 0.0])
    return e, [np.array(Hi), np.array(Hj), np.array(Hs)]


def aligned_between_factor(ki: int, kj: int, kab: int, delta: FloatArray, cov: FloatArray, min_sigma: float = 1e-4,
                           kernel: str = "none", k: float = 1.345) -> gtsam.CustomFactor:
    """Integrated-odometry factor between ``x_i`` and ``x_j`` of a further twist source whose
    translation is calibrated by ``kab`` (a ``Vector2`` ``(a, b)``: scale and yaw misalignment,
    :func:`aligned_between_error`) against the graph (the first source, fixes); its yaw as
    reported.  ``delta`` / ``cov``: the reported increment and its covariance."""
    d = np.asarray(delta, dtype=float).copy()
    c = np.asarray(cov, dtype=float) + _floor(min_sigma)
    noise = robust(gtsam.noiseModel.Gaussian.Covariance(c), kernel, k)
    k0, k1, k2 = int(ki), int(kj), int(kab)

    def error(this: gtsam.CustomFactor, values: gtsam.Values, H: list | None) -> FloatArray:
        e, Hs = aligned_between_error(values.atPose2(k0), values.atPose2(k1), values.atVector(k2), d, H is not None)
        if H is not None:
            H[0], H[1], H[2] = Hs
        return e

    return gtsam.CustomFactor(noise, [k0, k1, k2], error)


def gyro_error(theta_i: float, theta_j: float, bias: float, dtheta_gyro: float, dt: float) -> float:
    """Gyro residual ``wrap(theta_j - theta_i - (dtheta_gyro - bias * dt))`` (radians)."""
    return wrap_scalar(theta_j - theta_i - (dtheta_gyro - bias * dt))


def gyro_factor(ki: int, kj: int, kb: int, dtheta_gyro: float, dt: float, sigma: float,
                kernel: str = "none", k: float = 1.345) -> gtsam.CustomFactor:
    """Between-keyframe yaw increment from an integrated gyro with a bias variable ``kb``
    (``Vector1``, rad/s): analytic Jacobians ``[0, 0, -1]``, ``[0, 0, 1]``, ``[dt]``."""
    z, T = float(dtheta_gyro), float(dt)
    k0, k1, k2 = int(ki), int(kj), int(kb)
    h0, h1, h2 = np.array([[0.0, 0.0, -1.0]]), np.array([[0.0, 0.0, 1.0]]), np.array([[T]])  # constant

    def error(this: gtsam.CustomFactor, values: gtsam.Values, H: list | None) -> FloatArray:
        e = gyro_error(values.atPose2(k0).theta(), values.atPose2(k1).theta(), float(values.atVector(k2)[0]), z, T)
        if H is not None:
            H[0] = h0
            H[1] = h1
            H[2] = h2
        return np.array([e])

    noise = robust(gtsam.noiseModel.Isotropic.Sigma(1, max(float(sigma), 1e-6)), kernel, k)
    return gtsam.CustomFactor(noise, [ki, kj, kb], error)


def yaw_increment_factor(ki: int, kj: int, dtheta: float, sigma: float) -> gtsam.BetweenFactorPose2:
    """A measured yaw change ``theta_j - theta_i`` (a gyro's, its bias already removed): error
    ``wrap(theta_j - theta_i - dtheta)``, Jacobians ``[0, 0, -1]``, ``[0, 0, 1]``.

    A C++ ``BetweenFactorPose2`` with measurement ``(0, 0, dtheta)`` whose translation rows have
    infinite sigmas: its rotation row is exactly this error (``Log``'s rotation of
    ``m^-1 x_i^-1 x_j``) with these Jacobians, the other two rows weigh nothing.  (A Python
    ``CustomFactor`` cost ~11 us per linearization, this one ~2 us.)"""
    return gtsam.BetweenFactorPose2(int(ki), int(kj), gtsam.Pose2(0.0, 0.0, float(dtheta)),
                                    gtsam.noiseModel.Diagonal.Sigmas(np.array([np.inf, np.inf,
                                                                               max(float(sigma), 1e-6)])))


def latency_fix_error(x: gtsam.Pose2, latency_s: float, fix: gtsam.Pose2, twist: FloatArray,
                      want_jacobians: bool = True) -> tuple[FloatArray, list[FloatArray]]:
    """Error ``Log(fix^-1 x Exp(-u latency))`` of :func:`latency_fix_factor` and its Jacobians."""
    u = np.asarray(twist, dtype=float)
    xi = -u * float(latency_s)
    D = gtsam.Pose2.Expmap(xi)
    E = fix.between(x.compose(D))
    e = gtsam.Pose2.Logmap(E)
    if not want_jacobians:
        return e, []
    Jl = gtsam.Pose2.LogmapDerivative(E)
    Hx = Jl @ D.inverse().AdjointMap()
    Hd = Jl @ gtsam.Pose2.ExpmapDerivative(xi) @ (-u).reshape(3, 1)
    return e, [Hx, Hd]


def latency_fix_factor(key: int, latency_key: int, pose: FloatArray, cov_map: FloatArray, twist: FloatArray,
                       kernel: str = "huber", k: float = 1.345) -> gtsam.CustomFactor:
    """A scan-to-map fix stamped ``latency`` after it was measured: it is the keyframe's pose
    carried back by the body twist ``u`` over ``latency_key`` (a ``Vector1``, seconds):
    ``fix = x Exp(-u latency)``."""
    fix = gtsam.Pose2(*np.asarray(pose, dtype=float))
    u = np.asarray(twist, dtype=float).copy()
    noise = robust(gtsam.noiseModel.Gaussian.Covariance(body_covariance(pose, cov_map)), kernel, k)

    def error(this: gtsam.CustomFactor, values: gtsam.Values, H: list | None) -> FloatArray:
        keys = this.keys()
        e, Hs = latency_fix_error(values.atPose2(keys[0]), float(values.atVector(keys[1])[0]), fix, u,
                                  H is not None)
        if H is not None:
            H[0], H[1] = Hs
        return e

    return gtsam.CustomFactor(noise, [key, latency_key], error)
