"""Body twists integrated between two stamps: the odometry's increment between keyframes.

:func:`integrate_twist` - body twists ``[vx, vy, wz]`` integrated into a relative pose with its
covariance propagated in GTSAM's right-perturbation (body) tangent space; works for differential
drive (``vy`` measured as 0 with a small variance: the non-holonomic constraint) and mecanum alike.
:func:`integrate_twist_lists` is the same on plain lists, resumable (the smoother's hot path);
:func:`integrate_heading` the heading change alone; :func:`rate_integral` a gyro's rate readings integrated
between two stamps, :func:`chord_step` one odometry step of a chord turned by another source's rotation.
Core maths only.
"""

from __future__ import annotations

import math
from bisect import bisect_left, bisect_right
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from fgloc.geometry import exp_coefficients, wrap_scalar

FloatArray = NDArray[np.float64]


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
    ts = np.asarray(stamps, dtype=float).tolist()
    us = np.asarray(twists, dtype=float).reshape(-1, 3).tolist()
    cs = [upper6(c) for c in np.asarray(covs, dtype=float).reshape(-1, 3, 3)]
    return integrate_twist_lists(ts, us, cs, 0, len(ts), t0, t1, q_slip)


def upper6(c: FloatArray) -> tuple[float, float, float, float, float, float]:
    """A 3x3 covariance's upper triangle ``(c00, c01, c02, c11, c12, c22)`` as floats (what
    :func:`integrate_twist_lists` reads of it)."""
    r = np.asarray(c, dtype=float).reshape(9).tolist()
    return r[0], r[1], r[2], r[4], r[5], r[8]


#: :func:`integrate_twist_values`' answer: ``(x, y, yaw, p00, p01, p02, p11, p12, p22)``
TwistValues = tuple[float, float, float, float, float, float, float, float, float]
_NO_MOTION: TwistValues = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


def integrate_twist_lists(ts: Sequence[float], us: Sequence[Sequence[float]],
                          cs: Sequence[tuple[float, float, float, float, float, float]], lo: int, hi: int,
                          t0: float, t1: float, q_slip: FloatArray | None = None,
                          mark: list[float] | None = None) -> tuple[FloatArray, FloatArray]:
    """:func:`integrate_twist` over the samples ``lo:hi`` of plain lists (stamps, ``(vx, vy, w)``
    twists, :func:`upper6` covariances): the same arithmetic, without numpy's per-element
    overhead (the smoother integrates its odometry several times per keyframe); ``mark`` as
    :func:`integrate_twist_values`'."""
    return twist_arrays(integrate_twist_values(ts, us, cs, lo, hi, t0, t1, q_slip, mark))


def twist_arrays(v: TwistValues) -> tuple[FloatArray, FloatArray]:
    """:func:`integrate_twist_values`' answer as :func:`integrate_twist`'s: the increment and its 3x3 covariance."""
    return np.array(v[:3]), twist_covariance_array(v)


def twist_covariance_array(v: TwistValues) -> FloatArray:
    """The 3x3 covariance of :func:`integrate_twist_values`' answer."""
    _, _, _, p00, p01, p02, p11, p12, p22 = v
    # (a flat fromiter, reshaped: a nested list costs numpy's shape discovery, ~4x the time)
    return np.fromiter((p00, p01, p02, p01, p11, p12, p02, p12, p22), float, 9).reshape(3, 3)


def integrate_twist_values(ts: Sequence[float], us: Sequence[Sequence[float]],
                           cs: Sequence[tuple[float, float, float, float, float, float]], lo: int, hi: int,
                           t0: float, t1: float, q_slip: FloatArray | None = None,
                           mark: list[float] | None = None) -> TwistValues:
    """:func:`integrate_twist_lists` as floats: the increment ``(x, y, yaw)`` (yaw wrapped) and its
    covariance's upper triangle (no arrays: the smoother's predictions read them as floats).

    ``mark``: a list that receives the integration's state after its last step that ended on a
    sample's stamp (``[t, x, y, yaw, p00, p01, p02, p11, p12, p22]``: those steps depend on no
    later sample), and from which a later call with the same ``t0`` (the caller keeps one mark per
    ``t0``) and samples only appended since resumes when it is at or before ``t1``: the same steps,
    the same numbers, without integrating the prefix again."""
    if t1 <= t0 or hi <= lo:
        return _NO_MOTION
    qx, qy, qt = (0.0, 0.0, 0.0) if q_slip is None else (float(q_slip[0]), float(q_slip[1]), float(q_slip[2]))
    if mark and mark[0] <= t1:
        t, x, y, th, p00, p01, p02, p11, p12, p22 = mark
        i = bisect_right(ts, t, lo, hi)   # the sample after the one the mark ended on
    else:
        # index of the first sample with stamp > t0 (its twist covers t0)
        i = bisect_right(ts, t0, lo, hi)
        t = t0
        x = y = th = 0.0
        # covariance entries (symmetric 3x3, scalar maths: ~10x faster than numpy for 3x3)
        p00 = p01 = p02 = p11 = p12 = p22 = 0.0
    last = hi - 1
    done = None   # the state after the last step that ended on a sample's stamp (for ``mark``)
    while t < t1 - 1e-12:
        j = i if i < last else last
        t_next = (ts[i] if ts[i] < t1 else t1) if i < hi else t1
        dt = t_next - t
        if dt > 0:
            u = us[j]
            vx, vy, w = u[0] * dt, u[1] * dt, u[2] * dt
            a, b = exp_coefficients(w)
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
            c00, c01, c02, c11, c12, c22 = cs[j]
            dt2 = dt * dt
            n00 = b00 * c + b01 * s + b02 * iy
            n01 = -b00 * s + b01 * c - b02 * ix
            n11 = -b10 * s + b11 * c - b12 * ix
            p00 = n00 + c00 * dt2 + qx * dt
            p01 = n01 + c01 * dt2
            p02 = b02 + c02 * dt2
            p11 = n11 + c11 * dt2 + qy * dt
            p12 = b12 + c12 * dt2
            p22 = p22 + c22 * dt2 + qt * dt
            ct, st = math.cos(th), math.sin(th)
            x, y, th = x + ct * dx - st * dy, y + st * dx + ct * dy, th + w
        if mark is not None and i < hi and ts[i] <= t1:   # this step ended on sample i's stamp
            done = (t_next, x, y, th, p00, p01, p02, p11, p12, p22)
        t = t_next
        i += 1
    if done is not None:
        mark[:] = done  # type: ignore[index]
    return x, y, wrap_scalar(th), p00, p01, p02, p11, p12, p22


def integrate_heading(ts: Sequence[float], us: Sequence[Sequence[float]], lo: int, hi: int, t0: float,
                      t1: float) -> float:
    """Heading change (rad, unwrapped) from ``t0`` to ``t1`` over the samples ``lo:hi`` of plain lists
    (stamps, ``(vx, vy, w)`` twists), the same hold as :func:`integrate_twist` (scalar maths: the
    smoother's predictions ask for it several times per keyframe)."""
    if t1 <= t0 or hi <= lo:
        return 0.0
    i = bisect_right(ts, t0, lo, hi)
    last = hi - 1
    t, th = t0, 0.0
    while t < t1 - 1e-12:
        j = i if i < last else last
        t_next = (ts[i] if ts[i] < t1 else t1) if i < hi else t1
        th += float(us[j][2]) * (t_next - t)
        t = t_next
        i += 1
    return th


def chord_step(u: tuple[float, float, float], cv: tuple[float, float, float, float, float, float],
               dt: float, w: float, qx: float, qy: float,
               x: float, y: float, th: float, p00: float, p01: float, p11: float
               ) -> tuple[float, float, float, float, float, float]:
    """One odometry step of a chord: the twist ``u``'s (vx, vy) held for ``dt`` s while the chord
    turns by ``w`` rad, added to the chord ``(x, y, th)`` in the frame at its start; the step's (vx, vy)
    covariance (from ``cv``, the twist's upper6) * dt^2 plus the slip variances ``qx``, ``qy`` * dt,
    turned into that frame and added to ``(p00, p01, p11)``."""
    vx, vy = float(u[0]) * dt, float(u[1]) * dt
    a, b = exp_coefficients(w)
    dx, dy = a * vx - b * vy, b * vx + a * vy
    c, s_ = math.cos(th), math.sin(th)
    x, y, th = x + c * dx - s_ * dy, y + s_ * dx + c * dy, th + w
    dt2 = dt * dt
    s00, s01, s11 = cv[0] * dt2 + qx * dt, cv[1] * dt2, cv[3] * dt2 + qy * dt
    p00 += c * c * s00 - 2.0 * c * s_ * s01 + s_ * s_ * s11
    p01 += c * s_ * (s00 - s11) + (c * c - s_ * s_) * s01
    p11 += s_ * s_ * s00 + 2.0 * c * s_ * s01 + c * c * s11
    return x, y, th, p00, p01, p11


def covering(ts: Sequence[float], t0: float, t1: float) -> tuple[int, int]:
    """``(i0, i1)``: the samples of the sorted stamps ``ts`` that cover ``(t0, t1]``, ``ts[i0:i1]``: from
    the last one at or before ``t0`` to the first one at or after ``t1`` (as far as ``ts`` reaches)."""
    i0 = bisect_right(ts, t0) - 1
    i1 = bisect_left(ts, t1) + 1
    n = len(ts)
    return (0 if 0 > i0 else i0), (n if n < i1 else i1)   # max(i0, 0), min(i1, n) without the builtins' calls


def rate_integral(ts: list[float], rs: list[float], t0: float, t1: float, i: int, max_gap: float,
                  weights: dict[int, float] | None = None, mark: list[float] | None = None) -> float | None:
    """The integral over ``[t0, t1]`` of the rate readings ``rs`` at stamps ``ts``, linearly
    interpolated between them, from reading ``i`` on (the one at or before ``t0``); None where two
    readings the interval needs are more than ``max_gap`` apart.  ``weights``: each reading's
    weight in the integral is added there (for the variance of :meth:`SlidingWindowSmoother._gyro_increment`).

    ``mark`` (without ``weights``): a list that receives ``[t, d]`` after the last reading interval that
    ended inside ``[t0, t1]`` (``t`` its end stamp, ``d`` the sum up to it: those terms depend on no later
    reading), and from which a later call with the same ``t0`` (the caller keeps one mark per ``t0``)
    resumes when ``t`` is at or before ``t1`` and still a reading's stamp: the same terms added in the
    same order, without summing the prefix again."""
    d = 0.0
    n = len(ts)
    if mark and weights is None and mark[0] <= t1:
        j = bisect_left(ts, mark[0])
        if j < n and ts[j] == mark[0]:
            i, d = j, mark[1]
    done = None
    while i < n - 1 and ts[i] < t1:
        ta, tb = ts[i], ts[i + 1]
        a = t0 if t0 > ta else ta   # max(ta, t0), min(tb, t1) without the builtins' calls
        b = t1 if t1 < tb else tb
        if b > a:
            h = tb - ta
            if h > max_gap:
                return None
            fa, fb = (a - ta) / h, (b - ta) / h
            # weights of reading i and i+1 in the integral over [a, b]
            wi = (b - a) * (1.0 - 0.5 * (fa + fb))
            wj = (b - a) * 0.5 * (fa + fb)
            d += wi * rs[i] + wj * rs[i + 1]
            if weights is not None:
                weights[i] = weights.get(i, 0.0) + wi
                weights[i + 1] = weights.get(i + 1, 0.0) + wj
        if tb <= t1:
            done = tb, d
        i += 1
    if mark is not None and weights is None and done is not None:
        mark[:] = done
    return d


# ---------------------------------------------------------------------- factors
