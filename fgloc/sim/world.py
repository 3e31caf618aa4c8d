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

FloatArray = NDArray[np.float64]


@dataclass
class World:
    """Solid obstacles: ``polygons`` (list of ``(K, 2)`` vertex arrays) and ``circles`` ``(M, 3)`` [x, y, r].

    ``bounds``: ``(xmin, ymin, xmax, ymax)`` of the free interior (for the map's free space).
    """

    polygons: list[FloatArray]
    circles: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    bounds: tuple[float, float, float, float] = (0.0, 0.0, 1.0, 1.0)

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
        """Occupancy map: a cell is occupied when its centre is inside a solid, free inside ``bounds``."""
        xmin, ymin, xmax, ymax = self.bounds
        x0 = np.floor((xmin - margin) / resolution) * resolution
        y0 = np.floor((ymin - margin) / resolution) * resolution
        w = int(np.ceil((xmax + margin - x0) / resolution))
        h = int(np.ceil((ymax + margin - y0) / resolution))
        cx = x0 + (np.arange(w) + 0.5) * resolution
        cy = y0 + (np.arange(h) + 0.5) * resolution
        gx, gy = np.meshgrid(cx, cy)
        pts = np.column_stack([gx.ravel(), gy.ravel()])
        occ = np.zeros(len(pts), dtype=bool)
        for poly in self.polygons:
            occ |= points_in_polygon(pts, np.asarray(poly, dtype=float))
        for x, y, r in self.circles:
            occ |= (pts[:, 0] - x) ** 2 + (pts[:, 1] - y) ** 2 <= r * r
        inside = (pts[:, 0] > xmin) & (pts[:, 0] < xmax) & (pts[:, 1] > ymin) & (pts[:, 1] < ymax)
        data = np.full(len(pts), UNKNOWN, dtype=np.int16)
        data[inside] = FREE
        data[occ] = OCCUPIED
        return OccupancyMap(data.reshape(h, w), resolution, np.array([x0, y0, 0.0]))

    def is_free(self, points: FloatArray, clearance: float = 0.0) -> NDArray[np.bool_]:
        """True where points are inside the bounds, outside every solid and at least ``clearance`` from one."""
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        xmin, ymin, xmax, ymax = self.bounds
        ok = (p[:, 0] > xmin + clearance) & (p[:, 0] < xmax - clearance)
        ok &= (p[:, 1] > ymin + clearance) & (p[:, 1] < ymax - clearance)
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
    """Vectorized exact ray casting against segments ``(S, 4)`` and circles ``(C, 3)``."""
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
    (27.5, 17), (2.5, 17)) keeps at least 1 m from every obstacle.  Surfaces lie on
    multiples of 0.05 m so they coincide with the 0.05 m map's cell boundaries.
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
