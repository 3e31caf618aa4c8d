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
               start_pause_s: float = 1.0, end_pause_s: float = 1.0, initial_yaw: float | None = None,
               turn_radii_m: float | list[float] | None = None,
               strafe_legs: list[int] | tuple[int, ...] = ()) -> Plan:
    """Motion through ``waypoints`` ``(K, 2)`` sampled at ``rate_hz``.

    By default stop-turn-go: each leg driven facing its direction, a stop and an in-place turn
    at every waypoint.  ``turn_radii_m`` (one value, or one per inner waypoint; 0 = stop and
    turn in place) rounds a corner into an arc of that radius driven without stopping (yaw rate
    ``v / R``; the run's speed is capped so that ``v / R <= yaw_rate_radps``).  A leg whose
    index is in ``strafe_legs`` is driven sideways / diagonally keeping the heading it starts
    with (a mecanum or omni base; body ``vy`` != 0), without turning before it.
    """
    wp = np.asarray(waypoints, dtype=float)
    legs = np.diff(wp, axis=0)
    n_corners = max(len(legs) - 1, 0)
    if turn_radii_m is None:
        radii = np.zeros(n_corners)
    elif np.ndim(turn_radii_m) == 0:
        radii = np.full(n_corners, float(turn_radii_m))  # type: ignore[arg-type]
    else:
        radii = np.asarray(turn_radii_m, dtype=float).reshape(-1)
        if len(radii) != n_corners:
            raise ValueError(f"turn_radii_m has {len(radii)} values for {n_corners} corners")
    strafe = {int(i) for i in strafe_legs}
    for i in strafe:  # a strafed leg has no arc at either end
        if i - 1 >= 0 and i - 1 < n_corners:
            radii[i - 1] = 0.0
        if i < n_corners:
            radii[i] = 0.0
    dt = 1.0 / rate_hz
    seg_t: list = []
    seg_p: list = []
    seg_v: list = []
    t0 = 0.0
    yaw = float(np.arctan2(legs[0, 1], legs[0, 0])) if initial_yaw is None else float(initial_yaw)
    if 0 in strafe and initial_yaw is None:
        yaw = 0.0
    pos = wp[0].copy()

    def hold(duration: float) -> None:
        nonlocal t0
        n = max(int(round(duration * rate_hz)), 1)
        tt = t0 + np.arange(n) * dt
        seg_t.append(tt)
        seg_p.append(np.tile([pos[0], pos[1], yaw], (n, 1)))
        seg_v.append(np.zeros((n, 3)))
        t0 = tt[-1] + dt

    def turn_to(target: float) -> None:
        nonlocal t0, yaw
        dyaw = float(wrap_angle(target - yaw))
        if abs(dyaw) <= 1e-9:
            return
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

    hold(start_pause_s)
    i = 0
    while i < len(legs):
        # a run: legs joined by arcs (radius > 0) from one stop to the next
        j = i
        while j < n_corners and radii[j] > 0:
            j += 1
        run_legs = list(range(i, j + 1))
        if i in strafe:
            _drive_strafe(legs[i], pos, yaw, speed_mps, accel_mps2, rate_hz, t0, seg_t, seg_p, seg_v)
            t0 = seg_t[-1][-1] + dt
            pos = pos + legs[i]
            i += 1
            continue
        turn_to(float(np.arctan2(legs[i, 1], legs[i, 0])))
        pieces = _run_pieces(wp, legs, radii, run_legs)
        vmax = speed_mps
        for kind, *rest in pieces:
            if kind == "arc":
                vmax = min(vmax, yaw_rate_radps * rest[3])
        length = float(sum(pc[-1] for pc in pieces))
        _, _, dur = trapezoid(length, vmax, accel_mps2, np.zeros(1))
        n = int(np.ceil(dur * rate_hz))
        tl = np.arange(n) * dt
        s, v, _ = trapezoid(length, vmax, accel_mps2, tl)
        p, curv = _along(pieces, s)
        seg_t.append(t0 + tl)
        seg_p.append(p)
        seg_v.append(np.column_stack([v, np.zeros(n), v * curv]).astype(np.float64))
        t0 += n * dt
        pos = wp[j + 1].copy()
        yaw = float(np.arctan2(legs[j, 1], legs[j, 0]))
        i = j + 1
    hold(end_pause_s)
    return Plan(np.concatenate(seg_t), np.vstack(seg_p), np.vstack(seg_v))


def _drive_strafe(leg: FloatArray, pos: FloatArray, yaw: float, speed: float, accel: float, rate_hz: float,
                  t0: float, seg_t: list, seg_p: list, seg_v: list) -> None:
    dt = 1.0 / rate_hz
    dist = float(np.hypot(*leg))
    _, _, dur = trapezoid(dist, speed, accel, np.zeros(1))
    n = int(np.ceil(dur * rate_hz))
    tl = np.arange(n) * dt
    s, v, _ = trapezoid(dist, speed, accel, tl)
    u = leg / dist
    c, sn = np.cos(yaw), np.sin(yaw)
    ub = np.array([c * u[0] + sn * u[1], -sn * u[0] + c * u[1]])  # direction in the body frame
    seg_t.append(t0 + tl)
    seg_p.append(np.column_stack([pos[0] + s * u[0], pos[1] + s * u[1], np.full(n, yaw)]))
    seg_v.append(np.column_stack([v * ub[0], v * ub[1], np.zeros(n)]))


def _run_pieces(wp: FloatArray, legs: FloatArray, radii: FloatArray, run_legs: list[int]) -> list[tuple]:
    """Lines and arcs of one run: ``("line", start_xy, heading, length)``,
    ``("arc", start_xy, heading0, radius, signed_angle, length)``."""
    pieces: list[tuple] = []
    start = wp[run_legs[0]].copy()
    for k in run_legs:
        h = float(np.arctan2(legs[k, 1], legs[k, 0]))
        end = wp[k + 1].copy()
        cut_in = 0.0
        if k - 1 in run_legs:
            h_prev = float(np.arctan2(legs[k - 1, 1], legs[k - 1, 0]))
            cut_in = radii[k - 1] * abs(np.tan(float(wrap_angle(h - h_prev)) / 2))
        cut_out = 0.0
        if k + 1 in run_legs:
            h_next = float(np.arctan2(legs[k + 1, 1], legs[k + 1, 0]))
            d = float(wrap_angle(h_next - h))
            cut_out = radii[k] * abs(np.tan(d / 2))
        u = np.array([np.cos(h), np.sin(h)])
        length = float(np.hypot(*legs[k])) - cut_in - cut_out
        if length < -1e-9:
            raise ValueError(f"turn radius too large for leg {k}")
        a = wp[k] + u * cut_in
        pieces.append(("line", a, h, max(length, 0.0)))
        if k + 1 in run_legs:
            h_next = float(np.arctan2(legs[k + 1, 1], legs[k + 1, 0]))
            d = float(wrap_angle(h_next - h))
            pieces.append(("arc", end - u * cut_out, h, float(radii[k]), d, float(radii[k]) * abs(d)))
    del start
    return pieces


def _along(pieces: list[tuple], s: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Poses ``(N, 3)`` and path curvature ``(N,)`` at arc lengths ``s`` along ``pieces``."""
    out = np.zeros((len(s), 3))
    curv = np.zeros(len(s))
    s0 = 0.0
    for idx, pc in enumerate(pieces):
        length = pc[-1]
        last = idx == len(pieces) - 1
        m = (s >= s0) & ((s < s0 + length) | last)
        ds = np.clip(s[m] - s0, 0.0, length)
        if pc[0] == "line":
            _, a, h, _ = pc
            out[m] = np.column_stack([a[0] + ds * np.cos(h), a[1] + ds * np.sin(h), np.full(len(ds), h)])
        else:
            _, a, h0, r, d, _ = pc
            sg = np.sign(d)
            ctr = a + r * sg * np.array([-np.sin(h0), np.cos(h0)])
            phi = h0 + sg * ds / r
            out[m] = np.column_stack([ctr[0] + r * sg * np.sin(phi), ctr[1] - r * sg * np.cos(phi),
                                      wrap_angle(phi)])
            curv[m] = sg / r
        s0 += length
    return out, curv
