"""How well a scan agrees with the map at a pose: the mean Gaussian likelihood of its beam endpoints on the
map's distance field (:func:`scan_agreement`), at many poses (:func:`agreements`), the poses around a
prediction as far as its covariance allows (:func:`neighbourhood`), and the distance scale
(:func:`agreement_sigma`).  The jump gate (:mod:`fgloc.localization.gate`) and the consistency monitor judge
by it.  Core maths only: no I/O."""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from fgloc.gridmath import njit
from fgloc.maps import OccupancyMap
from fgloc.types import LaserScan, StaticTransform

FloatArray = np.ndarray

#: beams whose endpoint the map's distance field does not cover (off the grid) count as this far (m)
OFF_GRID_M = 10.0


def scan_agreement(occ_map: OccupancyMap, laser_mount: StaticTransform, scan: LaserScan, pose: FloatArray,
                   sigma_m: float, points: FloatArray | None = None, max_beams: int | None = None,
                   min_beams: int = 1) -> float:
    """How well ``scan`` agrees with the map at ``base_link`` pose ``pose``: the mean over its valid
    beams of ``exp(-d^2 / 2 sigma^2)``, ``d`` the distance from the beam's endpoint to the nearest
    occupied cell (bilinear on the map's distance field).  1: every endpoint on a mapped wall; 0: none
    near one.  NaN for a scan with fewer than ``min_beams`` valid beams.  ``points``: the scan's
    endpoints in the laser frame when the caller has them (``scan.points()``).

    ``max_beams`` (what a monitor measuring every few scans needs, at a quarter of the cost): at most
    that many beams, evenly spread (every ``ceil(n / max_beams)``-th, the valid ones of those), and the
    field at each endpoint's cell, not interpolated (a pose wrong by more than a cell, not a fix a few
    centimetres off); ``points`` is then not used."""
    if max_beams is not None:  # one pose: no arrays of poses
        beams = _sampled_beams(scan, int(max_beams))
        if beams[4] < min_beams:
            return math.nan
        return _nearest_agreement(occ_map, laser_mount, beams, np.asarray(pose, dtype=float).reshape(3).tolist(),
                                  sigma_m)
    return float(agreements(occ_map, laser_mount, scan, np.asarray(pose, dtype=float).reshape(1, 3), sigma_m,
                            points, min_beams)[0])


def agreements(occ_map: OccupancyMap, laser_mount: StaticTransform, scan: LaserScan, poses: FloatArray,
               sigma_m: float, points: FloatArray | None = None, min_beams: int = 1) -> FloatArray:
    """:func:`scan_agreement` at each of ``poses`` ``(K, 3)`` (every valid beam, bilinear)."""
    poses = np.asarray(poses, dtype=float).reshape(-1, 3)
    pts = scan.points() if points is None else points
    if len(pts) < max(min_beams, 1):
        return np.full(len(poses), np.nan)
    return np.asarray(np.mean(beam_agreements(occ_map, laser_mount, poses, sigma_m, pts), axis=1), dtype=float)


def beam_agreements(occ_map: OccupancyMap, laser_mount: StaticTransform, poses: FloatArray, sigma_m: float,
                    pts: FloatArray) -> FloatArray:
    """Each beam's share of :func:`agreements`: ``exp(-d^2 / 2 sigma^2)`` of the endpoints ``pts`` (the scan's
    valid ones in the laser frame, ``(N, 2)``) at each of ``poses`` ``(K, 3)``, ``(K, N)``."""
    poses = np.asarray(poses, dtype=float).reshape(-1, 3)
    m = np.asarray(laser_mount.pose, dtype=float)
    cb, sb = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    ox = poses[:, 0] + cb * m[0] - sb * m[1]  # the laser in the map frame, per pose
    oy = poses[:, 1] + sb * m[0] + cb * m[1]
    yaw = poses[:, 2] + m[2]
    origin = occ_map.origin
    d = _endpoint_distances(ox, oy, np.cos(yaw), np.sin(yaw), np.ascontiguousarray(pts, dtype=float),
                            occ_map.distance_field, float(origin[0]), float(origin[1]), float(np.cos(origin[2])),
                            float(np.sin(origin[2])), float(occ_map.resolution), OFF_GRID_M)
    return np.exp(-0.5 * (d / sigma_m) ** 2)


@njit(cache=True)
def _endpoint_distances(ox, oy, c, s, pts, df, x0, y0, co, so, res, outside):  # pragma: no cover - compiled
    """The distance field at the endpoints ``pts`` ``(N, 2)`` of a laser at ``(ox[k], oy[k])`` looking along
    ``(c[k], s[k])``, ``(K, N)``: :meth:`OccupancyMap.distance_at` (bilinear between cell centres, the grid's
    origin ``(x0, y0)`` turned by ``(co, so)``, ``res`` m per cell), ``outside`` off the grid or where the field
    is not finite; the same operations in the same order, the same bits."""
    h, w = df.shape
    cmax = w - 2 if w > 1 else 0
    rmax = h - 2 if h > 1 else 0
    n = pts.shape[0]
    px, py = np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1])
    gu, gv = np.empty(n), np.empty(n)
    out = np.empty((ox.shape[0], n))
    for k in range(ox.shape[0]):
        oxk, oyk, ck, sk = ox[k], oy[k], c[k], s[k]
        for j in range(n):  # the grid coordinates first: a loop without branches the compiler vectorizes
            dx = oxk + ck * px[j] - sk * py[j] - x0
            dy = oyk + sk * px[j] + ck * py[j] - y0
            gu[j] = (co * dx + so * dy) / res - 0.5
            gv[j] = (-so * dx + co * dy) / res - 0.5
        for j in range(n):
            u, v = gu[j], gv[j]
            d = outside
            if u >= 0 and v >= 0 and u <= w - 1 and v <= h - 1:
                c0 = min(int(u), cmax)  # u >= 0: truncation is the floor
                r0 = min(int(v), rmax)
                c1 = min(c0 + 1, w - 1)
                r1 = min(r0 + 1, h - 1)
                fu, fv = u - c0, v - r0
                d = (df[r0, c0] * (1 - fu) * (1 - fv) + df[r0, c1] * fu * (1 - fv) + df[r1, c0] * (1 - fu) * fv
                     + df[r1, c1] * fu * fv)
                if not math.isfinite(d):
                    d = outside
            out[k, j] = d
    return out


@lru_cache(maxsize=16)
def _beam_directions(n: int, angle_min: float, angle_increment: float, step: int) -> tuple[FloatArray, ...]:
    """The indices, cosines and sines of every ``step``-th of ``n`` beams (read-only)."""
    idx = np.arange(0, n, step)
    a = angle_min + angle_increment * idx
    out = (idx, np.cos(a), np.sin(a))
    for v in out:
        v.flags.writeable = False
    return out


def _sampled_beams(scan: LaserScan, max_beams: int) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, int]:
    """``(r, cos, sin, valid, n_valid)`` of every ``ceil(n / max_beams)``-th beam of ``scan``: its range (0
    where the beam is not valid: outside ``[range_min, range_max]``, NaN), direction, validity, and how
    many are valid."""
    n = len(scan.ranges)
    idx, ca, sa = _beam_directions(n, scan.angle_min, scan.angle_increment, max(1, -(-n // max(max_beams, 1))))
    r = np.asarray(scan.ranges, dtype=float)[idx]
    ok = (r >= max(float(scan.range_min), 1e-9)) & (r <= float(scan.range_max))  # NaN (and inf) compare false
    return np.where(ok, r, 0.0), ca, sa, ok, int(np.count_nonzero(ok))


def _nearest_agreement(occ_map: OccupancyMap, laser_mount: StaticTransform,
                       beams: tuple[FloatArray, FloatArray, FloatArray, FloatArray, int], pose: list[float],
                       sigma_m: float) -> float:
    """:func:`scan_agreement` of the valid ones of ``beams`` (:func:`_sampled_beams`) at ``pose``, the
    distance field at each endpoint's cell (scalar maths for the pose: one pose costs ~15 array ops)."""
    r, ca, sa, ok, n_ok = beams
    df = occ_map.distance_field
    h, w = df.shape
    x, y, yaw = pose
    mx, my, myaw = np.asarray(laser_mount.pose, dtype=float).reshape(3).tolist()
    cb, sb = math.cos(yaw), math.sin(yaw)
    # the laser in the grid's frame (cells as units): the map's origin may be rotated
    ox, oy, oyaw = np.asarray(occ_map.origin[:3], dtype=float).reshape(3).tolist()
    dx, dy = x + cb * mx - sb * my - ox, y + sb * mx + cb * my - oy
    co, so, inv = math.cos(oyaw), math.sin(oyaw), 1.0 / float(occ_map.resolution)
    gx, gy = (co * dx + so * dy) * inv, (co * dy - so * dx) * inv
    th = yaw + myaw - oyaw
    c, s = math.cos(th) * inv, math.sin(th) * inv
    z = _cell_exponents(df, gx, gy, c, s, r, ca, sa, -0.5 / sigma_m**2, OFF_GRID_M)
    return float(np.dot(np.exp(z), ok)) / n_ok


@njit(cache=True)
def _cell_exponents(df, gx, gy, c, s, r, ca, sa, k, outside):  # pragma: no cover - compiled
    """``d * d * k`` of the distance field ``df`` at the cell of each endpoint ``(gx + r (c ca - s sa), gy + r (s ca
    + c sa))`` (grid units), ``d = outside`` off the grid: :func:`_nearest_agreement`'s exponents."""
    h, w = df.shape
    out = np.empty(r.shape[0])
    for i in range(r.shape[0]):
        col = np.floor(gx + r[i] * (c * ca[i] - s * sa[i]))
        row = np.floor(gy + r[i] * (s * ca[i] + c * sa[i]))
        d = outside
        if 0 <= col < w and 0 <= row < h:  # NaN compares false
            d = df[int(row), int(col)]
        out[i] = d * d * k
    return out


def neighbourhood(pose: FloatArray, cov: FloatArray, k: float, floor_m: float, floor_rad: float) -> FloatArray:
    """Poses around ``pose`` as far as ``cov`` allows: ``0, +-k sigma`` in x and y and ``0, +-k sigma / 2,
    +-k sigma`` in heading (each sigma at least its floor), ``(45, 3)``; ``pose`` itself the middle one."""
    sd = np.sqrt(np.maximum(np.diag(np.asarray(cov, dtype=float)), 0.0))
    sx, sy, sth = max(k * float(sd[0]), floor_m), max(k * float(sd[1]), floor_m), max(k * float(sd[2]), floor_rad)
    gx, gy, gth = np.meshgrid([-sx, 0.0, sx], [-sy, 0.0, sy], [-sth, -sth / 2, 0.0, sth / 2, sth], indexing="ij")
    out = np.column_stack([gx.ravel(), gy.ravel(), gth.ravel()]) + np.asarray(pose, dtype=float).reshape(1, 3)
    return np.asarray(out, dtype=float)


def finest_steps(sigma_m: float, pts: FloatArray) -> tuple[float, float]:
    """The finest steps :func:`scan_agreement` (distance scale ``sigma_m``) tells apart: half its distance
    scale, and the heading that moves the scan's median return (of its endpoints ``pts``) by it."""
    r_med = float(np.median(np.hypot(pts[:, 0], pts[:, 1]))) if len(pts) else 1.0
    return sigma_m / 2, sigma_m / max(r_med, sigma_m) / 2


def climb(occ_map: OccupancyMap, laser_mount: StaticTransform, start: FloatArray, reach_m: float, sigma_m: float,
          pts: FloatArray, steps: tuple[float, float], max_steps: int) -> FloatArray:
    """The pose the agreement of the scan's endpoints ``pts`` climbs to from ``start``: each step to the best
    of the neighbourhood ``steps`` (metres, radians: :func:`finest_steps`) around the last, at most
    ``max_steps``, its position within ``reach_m`` of ``start``'s."""
    here = np.asarray(start, dtype=float).reshape(3)
    a_here = float(np.mean(beam_agreements(occ_map, laser_mount, here, sigma_m, pts)))
    for _ in range(max_steps):
        cand = neighbourhood(here, np.zeros((3, 3)), 0.0, *steps)
        cand = cand[np.hypot(cand[:, 0] - start[0], cand[:, 1] - start[1]) <= reach_m]
        if not len(cand):
            break
        a = np.mean(beam_agreements(occ_map, laser_mount, cand, sigma_m, pts), axis=1)
        k = int(np.argmax(a))
        if not a[k] > a_here:
            break
        here, a_here = cand[k], float(a[k])
    return here


def tied_agreements(occ_map: OccupancyMap, laser_mount: StaticTransform, poses: FloatArray, other: FloatArray,
                    sigma_m: float, pts: FloatArray, sigmas: float) -> tuple[float, float, float]:
    """``(the best agreement of poses, the agreement at other, the tie)``: the tie is ``sigmas`` standard
    errors of the beams' mean difference between ``other`` and the best of ``poses`` (a difference within it
    the map cannot tell apart).  ``pts``: the scan's valid endpoints (at least 2)."""
    beams = beam_agreements(occ_map, laser_mount, np.vstack([poses, np.asarray(other, dtype=float)]), sigma_m, pts)
    a = np.mean(beams, axis=1)
    best = int(np.argmax(a[:-1]))
    diff = beams[-1] - beams[best]
    return float(a[best]), float(a[-1]), sigmas * float(np.std(diff, ddof=1)) / math.sqrt(len(diff))


def agreement_sigma(occ_map: OccupancyMap, configured_m: float | None) -> float:
    """The distance scale of :func:`scan_agreement`: the configured one, else the map's cell (a wall
    known to its cell) or its declared accuracy, whichever is larger."""
    if configured_m is not None:
        return float(configured_m)
    acc = getattr(occ_map, "accuracy_m", None)
    acc = float(acc) if acc is not None and math.isfinite(float(acc)) else 0.0
    return max(float(occ_map.resolution), acc)


__all__ = ["OFF_GRID_M", "agreement_sigma", "agreements", "beam_agreements", "climb", "finest_steps", "neighbourhood",
           "scan_agreement", "tied_agreements"]
