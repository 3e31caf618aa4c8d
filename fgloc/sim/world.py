"""Continuous 2-D worlds for the simulator: solid polygons and circles.

Laser ranges are exact ray intersections with this geometry (not with the
rasterized map), so the map the robot localizes against is a discretization of
the world, as it is for a real robot.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from fgloc.maps import FREE, OCCUPIED, UNKNOWN, OccupancyMap

try:  # numba is a declared dependency (fgloc.maps uses it too); numpy is the fallback
    from numba import njit
except ImportError:  # pragma: no cover
    njit = None  # type: ignore[assignment]

FloatArray = NDArray[np.float64]


@dataclass
class World:
    """Solid obstacles: ``polygons`` (list of ``(K, 2)`` vertex arrays) and ``circles`` ``(M, 3)`` [x, y, r].

    ``bounds``: ``(xmin, ymin, xmax, ymax)`` of the free interior (for the map's free space).
    """

    polygons: list[FloatArray]
    circles: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    bounds: tuple[float, float, float, float] = (0.0, 0.0, 1.0, 1.0)
    interior: FloatArray | None = None  # polygon of the free interior (default: the bounds rectangle)

    def rotated(self, yaw: float, center: tuple[float, float]) -> World:
        """The same world rotated by ``yaw`` about ``center`` (bounds grow to hold it)."""
        c, s = np.cos(yaw), np.sin(yaw)
        R = np.array([[c, -s], [s, c]])
        ctr = np.asarray(center, dtype=float)

        def rot(p: FloatArray) -> FloatArray:
            return (np.asarray(p, dtype=float) - ctr) @ R.T + ctr

        xmin, ymin, xmax, ymax = self.bounds
        interior = rot(_rect(xmin, ymin, xmax, ymax) if self.interior is None else self.interior)
        circles = self.circles.copy()
        if len(circles):
            circles[:, :2] = rot(circles[:, :2])
        lo, hi = interior.min(axis=0), interior.max(axis=0)
        return World([rot(p) for p in self.polygons], circles, (lo[0], lo[1], hi[0], hi[1]), interior)

    def __post_init__(self) -> None:
        segs = []
        for poly in self.polygons:
            p = np.asarray(poly, dtype=float)
            segs.append(np.column_stack([p, np.roll(p, -1, axis=0)]))
        self.segments = np.vstack(segs) if segs else np.zeros((0, 4))
        self.circles = np.asarray(self.circles, dtype=float).reshape(-1, 3)

    def raycast(self, origins: FloatArray, angles: FloatArray, max_range: float,
                extra_circles: FloatArray | None = None) -> FloatArray:
        """Exact range from each origin ``(N, 2)`` along ``angles`` ``(N,)``; +inf when nothing within max_range."""
        circles = self.circles if extra_circles is None or len(extra_circles) == 0 else np.vstack(
            [self.circles, extra_circles])
        return raycast_geometry(origins, angles, self.segments, circles, max_range)

    def rasterize(self, resolution: float = 0.05, margin: float = 1.0) -> OccupancyMap:
        """The robot's occupancy map of this world.

        A cell is occupied when it *intersects* a solid (shares interior area with it:
        merely touching along an edge does not count), free when its centre is inside
        ``interior`` (or ``bounds``) and it is not occupied, unknown otherwise.  The grid's origin is a
        multiple of ``resolution``, so walls on multiples of 0.05 m coincide with cell
        boundaries.  Polygons must be convex (separating-axis test).
        """
        xmin, ymin, xmax, ymax = self.bounds
        x0 = np.floor((xmin - margin) / resolution) * resolution
        y0 = np.floor((ymin - margin) / resolution) * resolution
        w = int(np.ceil((xmax + margin - x0) / resolution))
        h = int(np.ceil((ymax + margin - y0) / resolution))
        occ = np.zeros((h, w), dtype=bool)
        half = resolution / 2
        eps = 1e-9

        def window(bx0: float, by0: float, bx1: float, by1: float):
            c0 = max(int(np.floor((bx0 - x0) / resolution)) - 1, 0)
            c1 = min(int(np.ceil((bx1 - x0) / resolution)) + 1, w)
            r0 = max(int(np.floor((by0 - y0) / resolution)) - 1, 0)
            r1 = min(int(np.ceil((by1 - y0) / resolution)) + 1, h)
            cx = x0 + (np.arange(c0, c1) + 0.5) * resolution
            cy = y0 + (np.arange(r0, r1) + 0.5) * resolution
            gx, gy = np.meshgrid(cx, cy)
            return (slice(r0, r1), slice(c0, c1)), gx, gy

        for poly in self.polygons:
            p = np.asarray(poly, dtype=float)
            sl, gx, gy = window(p[:, 0].min(), p[:, 1].min(), p[:, 0].max(), p[:, 1].max())
            # separating axes: x, y (the cell's) and each polygon edge normal
            hit = (gx + half > p[:, 0].min() + eps) & (gx - half < p[:, 0].max() - eps)
            hit &= (gy + half > p[:, 1].min() + eps) & (gy - half < p[:, 1].max() - eps)
            e = np.roll(p, -1, axis=0) - p
            for nx, ny in np.column_stack([-e[:, 1], e[:, 0]]):
                norm = np.hypot(nx, ny)
                if norm == 0:
                    continue
                nx, ny = nx / norm, ny / norm
                proj = p[:, 0] * nx + p[:, 1] * ny
                c = gx * nx + gy * ny
                rad = half * (abs(nx) + abs(ny))
                hit &= (c + rad > proj.min() + eps) & (c - rad < proj.max() - eps)
            occ[sl] |= hit
        for x, y, r in self.circles:
            sl, gx, gy = window(x - r, y - r, x + r, y + r)
            dx = np.maximum(np.abs(gx - x) - half, 0.0)
            dy = np.maximum(np.abs(gy - y) - half, 0.0)
            occ[sl] |= dx * dx + dy * dy < r * r - eps
        cx = x0 + (np.arange(w) + 0.5) * resolution
        cy = y0 + (np.arange(h) + 0.5) * resolution
        if self.interior is None:
            inside = ((cx[None, :] > xmin) & (cx[None, :] < xmax)) & ((cy[:, None] > ymin) & (cy[:, None] < ymax))
        else:
            gx, gy = np.meshgrid(cx, cy)
            inside = points_in_polygon(np.column_stack([gx.ravel(), gy.ravel()]),
                                       np.asarray(self.interior, dtype=float)).reshape(h, w)
        data = np.full((h, w), UNKNOWN, dtype=np.int16)
        data[inside] = FREE
        data[occ] = OCCUPIED
        return OccupancyMap(data, resolution, np.array([x0, y0, 0.0]))

    def is_free(self, points: FloatArray, clearance: float = 0.0) -> NDArray[np.bool_]:
        """True where points are inside the bounds, outside every solid and at least ``clearance`` from one."""
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        xmin, ymin, xmax, ymax = self.bounds
        ok = (p[:, 0] > xmin + clearance) & (p[:, 0] < xmax - clearance)
        ok &= (p[:, 1] > ymin + clearance) & (p[:, 1] < ymax - clearance)
        if self.interior is not None:
            ok &= points_in_polygon(p, np.asarray(self.interior, dtype=float))
        for poly in self.polygons:
            ok &= ~points_in_polygon(p, np.asarray(poly, dtype=float))
        if len(self.segments) and clearance > 0:
            ok &= _dist_to_segments(p, self.segments) >= clearance
        for x, y, r in self.circles:
            ok &= np.hypot(p[:, 0] - x, p[:, 1] - y) >= r + clearance
        return ok


def _dist_to_segments(p: FloatArray, segs: FloatArray) -> FloatArray:
    a = segs[None, :, :2]
    b = segs[None, :, 2:]
    ab = b - a
    ap = p[:, None, :] - a
    t = np.clip(np.sum(ap * ab, axis=2) / np.maximum(np.sum(ab * ab, axis=2), 1e-12), 0, 1)
    d = ap - t[..., None] * ab
    return np.sqrt(np.min(np.sum(d * d, axis=2), axis=1))


def points_in_polygon(pts: FloatArray, poly: FloatArray) -> NDArray[np.bool_]:
    """Even-odd rule, vectorized over points."""
    x, y = pts[:, 0], pts[:, 1]
    inside = np.zeros(len(pts), dtype=bool)
    n = len(poly)
    for i in range(n):
        x1, y1 = poly[i]
        x2, y2 = poly[(i + 1) % n]
        cond = (y1 > y) != (y2 > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            xint = x1 + (y - y1) * (x2 - x1) / (y2 - y1)
        inside ^= cond & (x < xint)
    return inside


def raycast_geometry(origins: FloatArray, angles: FloatArray, segments: FloatArray, circles: FloatArray,
                     max_range: float) -> FloatArray:
    """Exact ray casting against segments ``(S, 4)`` and circles ``(C, 3)`` (ray starts outside solids).

    Returns the distance to the first surface along each ray, ``+inf`` beyond ``max_range``.
    Compiled with numba (one pass over rays x surfaces); :func:`raycast_geometry_numpy`
    is the vectorized numpy reference implementation.
    """
    o = np.asarray(origins, dtype=float).reshape(-1, 2)
    a = np.asarray(angles, dtype=float).reshape(-1)
    if len(o) == 1 and len(a) > 1:
        o = np.broadcast_to(o, (len(a), 2))
    if njit is None:
        return raycast_geometry_numpy(o, a, segments, circles, max_range)
    return _raycast_nb(np.ascontiguousarray(o[:, 0]), np.ascontiguousarray(o[:, 1]), np.cos(a), np.sin(a),
                       np.ascontiguousarray(segments, dtype=float).reshape(-1, 4),
                       np.ascontiguousarray(circles, dtype=float).reshape(-1, 3), float(max_range))


def _raycast_kernel(ox, oy, dx, dy, segs, circles, max_range):  # pragma: no cover - compiled
    n = ox.shape[0]
    out = np.empty(n)
    for k in range(n):
        best = np.inf
        for j in range(segs.shape[0]):
            sx = segs[j, 2] - segs[j, 0]
            sy = segs[j, 3] - segs[j, 1]
            den = dx[k] * sy - dy[k] * sx
            if abs(den) <= 1e-12:
                continue
            qx = segs[j, 0] - ox[k]
            qy = segs[j, 1] - oy[k]
            t = (qx * sy - qy * sx) / den
            if t <= 1e-9 or t >= best:
                continue
            u = (qx * dy[k] - qy * dx[k]) / den
            if 0.0 <= u <= 1.0:
                best = t
        for j in range(circles.shape[0]):
            cx = circles[j, 0] - ox[k]
            cy = circles[j, 1] - oy[k]
            r = circles[j, 2]
            b = cx * dx[k] + cy * dy[k]
            disc = b * b - (cx * cx + cy * cy - r * r)
            if disc >= 0.0:
                t = b - np.sqrt(disc)
                if 1e-9 < t < best:
                    best = t
        out[k] = best if best <= max_range else np.inf
    return out


_raycast_nb = njit(cache=True, nogil=True)(_raycast_kernel) if njit is not None else _raycast_kernel


def raycast_geometry_numpy(origins: FloatArray, angles: FloatArray, segments: FloatArray, circles: FloatArray,
                           max_range: float) -> FloatArray:
    """Vectorized numpy ray casting (rays x surfaces matrices); same result as :func:`raycast_geometry`."""
    o = np.asarray(origins, dtype=float).reshape(-1, 2)
    a = np.asarray(angles, dtype=float).reshape(-1)
    if len(o) == 1 and len(a) > 1:
        o = np.broadcast_to(o, (len(a), 2))
    d = np.column_stack([np.cos(a), np.sin(a)])
    best = np.full(len(a), np.inf)
    if len(segments):
        p = segments[None, :, :2]
        s = segments[None, :, 2:] - segments[None, :, :2]
        q = p - o[:, None, :]
        den = d[:, None, 0] * s[..., 1] - d[:, None, 1] * s[..., 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (q[..., 0] * s[..., 1] - q[..., 1] * s[..., 0]) / den
            u = (q[..., 0] * d[:, None, 1] - q[..., 1] * d[:, None, 0]) / den
        ok = (np.abs(den) > 1e-12) & (t > 1e-9) & (u >= 0) & (u <= 1)
        t = np.where(ok, t, np.inf)
        best = np.minimum(best, t.min(axis=1))
    if len(circles):
        c = circles[None, :, :2] - o[:, None, :]
        r = circles[None, :, 2]
        b = c[..., 0] * d[:, None, 0] + c[..., 1] * d[:, None, 1]
        disc = b * b - (c[..., 0] ** 2 + c[..., 1] ** 2 - r * r)
        with np.errstate(invalid="ignore"):
            sq = np.sqrt(np.where(disc >= 0, disc, np.nan))
        t1 = b - sq
        t = np.where((disc >= 0) & (t1 > 1e-9), t1, np.inf)
        best = np.minimum(best, t.min(axis=1))
    best[best > max_range] = np.inf
    return best


def _rect(x0: float, y0: float, x1: float, y1: float) -> FloatArray:
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=float)


def paper_hall() -> World:
    """The paper replica's hall: 30 m x 20 m, 0.2 m walls, pillars, cabinets and alcoves.

    The 78 m route (a 25 m x 14 m rectangle with corners (2.5, 3), (27.5, 3),
    (27.5, 17), (2.5, 17)) keeps at least 1 m from every obstacle.
    """
    wt = 0.2
    polys = [
        _rect(-wt, -wt, 30 + wt, 0.0),  # south wall
        _rect(-wt, 20.0, 30 + wt, 20 + wt),  # north wall
        _rect(-wt, 0.0, 0.0, 20.0),  # west wall
        _rect(30.0, 0.0, 30 + wt, 20.0),  # east wall
        # cabinets and door frames along the walls (break the corridor symmetry)
        _rect(5.0, 0.0, 6.5, 1.2), _rect(11.0, 0.0, 11.4, 0.6), _rect(17.5, 0.0, 19.5, 0.9),
        _rect(24.0, 0.0, 24.6, 1.5), _rect(4.0, 19.0, 4.8, 20.0), _rect(9.5, 18.6, 12.0, 20.0),
        _rect(16.0, 19.4, 16.3, 20.0), _rect(21.0, 18.8, 22.5, 20.0), _rect(26.5, 19.2, 29.0, 20.0),
        _rect(0.0, 6.0, 1.0, 7.5), _rect(0.0, 12.0, 0.6, 12.4), _rect(0.0, 15.5, 1.4, 16.0),
        _rect(29.0, 5.0, 30.0, 6.0), _rect(29.4, 9.0, 30.0, 11.5), _rect(28.8, 14.5, 30.0, 15.0),
        # furniture inside the loop
        _rect(7.0, 7.0, 8.5, 8.0), _rect(13.0, 11.5, 14.0, 13.0), _rect(19.0, 6.5, 21.0, 7.3),
        _rect(23.5, 11.0, 24.3, 13.5), np.array([[10.0, 9.0], [11.5, 9.5], [10.5, 10.6]]),
    ]
    circles = np.array([[6.0, 12.0, 0.25], [12.0, 5.5, 0.3], [16.5, 9.5, 0.25], [22.0, 14.5, 0.3],
                        [18.0, 15.0, 0.2], [25.5, 6.5, 0.25]])
    return World(polys, circles, bounds=(0.0, 0.0, 30.0, 20.0))


PAPER_ROUTE = np.array([[2.5, 3.0], [27.5, 3.0], [27.5, 17.0], [2.5, 17.0], [2.5, 3.0]])
