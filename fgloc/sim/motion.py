"""Route planning for the simulator: stop-turn-go along waypoints with trapezoidal profiles.

The robot drives each leg facing its direction of travel at ``speed_mps`` with
acceleration ``accel_mps2``, stops at each waypoint and turns in place to the
next leg's heading (yaw rate ``yaw_rate_radps``, yaw acceleration
``yaw_accel_radps2``): what a mecanum or differential robot does on the paper's
rectangle, where the heading changes at the corners.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fgloc.geometry import wrap_angle

FloatArray = NDArray[np.float64]


def trapezoid(
    distance: float, vmax: float, amax: float, t: NDArray[np.floating]
) -> tuple[FloatArray, FloatArray, float]:
    """Position and speed along a rest-to-rest trapezoidal (or triangular) profile; returns (s, v, duration)."""
    distance = abs(distance)
    if distance <= 0:
        return np.zeros_like(t), np.zeros_like(t), 0.0
    ta = vmax / amax
    if amax * ta * ta >= distance:  # triangular
        ta = np.sqrt(distance / amax)
        vpk = amax * ta
        tc = 0.0
    else:
        vpk = vmax
        tc = (distance - amax * ta * ta) / vmax
    total = 2 * ta + tc
    tt = np.clip(t, 0, total)
    s = np.where(
        tt < ta,
        0.5 * amax * tt**2,
        np.where(tt < ta + tc, 0.5 * amax * ta**2 + vpk * (tt - ta),
                 distance - 0.5 * amax * (total - tt) ** 2),
    )
    v = np.where(tt < ta, amax * tt, np.where(tt < ta + tc, vpk, amax * (total - tt)))
    v = np.where((t < 0) | (t > total), 0.0, v)
    return s, v, float(total)


@dataclass
class Plan:
    """Dense ground-truth motion: stamps (s), poses ``(N, 3)`` and body twist ``(N, 3)``."""

    t: FloatArray
    poses: FloatArray
    twist: FloatArray


def plan_route(waypoints: FloatArray, speed_mps: float = 0.8, accel_mps2: float = 0.5,
               yaw_rate_radps: float = 0.8, yaw_accel_radps2: float = 1.5, rate_hz: float = 500.0,
               start_pause_s: float = 1.0, end_pause_s: float = 1.0, initial_yaw: float | None = None) -> Plan:
    """Stop-turn-go motion through ``waypoints`` ``(K, 2)`` sampled at ``rate_hz``."""
    wp = np.asarray(waypoints, dtype=float)
    dt = 1.0 / rate_hz
    seg_t, seg_p, seg_v = [], [], []
    t0 = 0.0
    legs = np.diff(wp, axis=0)
    yaw = float(np.arctan2(legs[0, 1], legs[0, 0])) if initial_yaw is None else float(initial_yaw)
    pos = wp[0].copy()

    def hold(duration: float) -> None:
        nonlocal t0
        n = max(int(round(duration * rate_hz)), 1)
        tt = t0 + np.arange(n) * dt
        seg_t.append(tt)
        seg_p.append(np.tile([pos[0], pos[1], yaw], (n, 1)))
        seg_v.append(np.zeros((n, 3)))
        t0 = tt[-1] + dt

    hold(start_pause_s)
    for leg in legs:
        target = float(np.arctan2(leg[1], leg[0]))
        dyaw = float(wrap_angle(target - yaw))
        if abs(dyaw) > 1e-9:
            _, _, dur = trapezoid(dyaw, yaw_rate_radps, yaw_accel_radps2, np.zeros(1))
            n = int(np.ceil(dur * rate_hz))
            tl = np.arange(n) * dt
            s, v, _ = trapezoid(dyaw, yaw_rate_radps, yaw_accel_radps2, tl)
            sgn = np.sign(dyaw)
            seg_t.append(t0 + tl)
            seg_p.append(np.column_stack([np.full(n, pos[0]), np.full(n, pos[1]), wrap_angle(yaw + sgn * s)]))
            seg_v.append(np.column_stack([np.zeros(n), np.zeros(n), sgn * v]))
            t0 += n * dt
            yaw = target
        dist = float(np.hypot(*leg))
        _, _, dur = trapezoid(dist, speed_mps, accel_mps2, np.zeros(1))
        n = int(np.ceil(dur * rate_hz))
        tl = np.arange(n) * dt
        s, v, _ = trapezoid(dist, speed_mps, accel_mps2, tl)
        u = leg / dist
        seg_t.append(t0 + tl)
        seg_p.append(np.column_stack([pos[0] + s * u[0], pos[1] + s * u[1], np.full(n, yaw)]))
        seg_v.append(np.column_stack([v, np.zeros(n), np.zeros(n)]))
        t0 += n * dt
        pos = pos + leg
    hold(end_pause_s)
    return Plan(np.concatenate(seg_t), np.vstack(seg_p), np.vstack(seg_v))
