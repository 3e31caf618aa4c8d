"""Ray-traced log-odds occupancy grids from scans at known poses.

Each beam lowers the log-odds of the cells it passes through and raises the
one it ends in; beams with no return (``+inf``, or at/over ``range_max``)
carve free space up to ``carve_range_m`` but add no hit.  A no-return reading
is weaker evidence than a return: drivers also report ``+inf`` for a beam that
hit a dark or glossy wall, so such a beam's free space stops before the first
cell that the returns have made occupied (log-odds above 0), and those beams are
applied after every return (:meth:`LogOddsGrid.to_map`), so the order of the
scans does not matter.  (GMapping skips readings beyond ``maxRange`` altogether;
Cartographer inserts ``missing_data_ray_length`` misses, each weaker than a hit,
and a cell hit in the same scan takes no miss.)  The result is an
:class:`fgloc.maps.OccupancyMap` (trinary: 100 occupied, 0 free, -1 unknown).
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

from fgloc.gridmath import dda_init, dda_next
from fgloc.maps import OccupancyMap

FloatArray = NDArray[np.float64]

L_OCC = 0.85
L_FREE = -0.4
L_MIN, L_MAX = -4.0, 4.0
LOGODDS_SCALE = 100  # log-odds are kept as int16 hundredths (half the memory of float32; every
                     # constant above is a whole number of hundredths, so the map is the same)


@njit(cache=True)
def _integrate(logodds, x0, y0, res, ox, oy, ex, ey, hit, l_occ, l_free, lmin, lmax,
               stop_above):  # pragma: no cover
    """Trace beams from (ox, oy) to (ex, ey) (map frame, metres) with a DDA.

    With ``stop_above`` set (no-return beams), a beam ends before the first cell whose
    log-odds is above it, which it leaves as it is."""
    h, w = logodds.shape
    for k in range(ox.shape[0]):
        sx = (ox[k] - x0) / res
        sy = (oy[k] - y0) / res
        gx = (ex[k] - x0) / res
        gy = (ey[k] - y0) / res
        tx, ty = int(np.floor(gx)), int(np.floor(gy))
        dx, dy = gx - sx, gy - sy
        length = np.sqrt(dx * dx + dy * dy)
        if length < 1e-9:
            continue
        cx, cy, step_x, step_y, tmx, tmy, tdx, tdy = dda_init(sx, sy, dx, dy)
        nmax = abs(tx - cx) + abs(ty - cy) + 2
        blocked = False
        for _ in range(nmax):
            if cx == tx and cy == ty:
                break
            if 0 <= cx < w and 0 <= cy < h:
                if logodds[cy, cx] > stop_above:
                    blocked = True
                    break
                v = logodds[cy, cx] + l_free
                logodds[cy, cx] = v if v > lmin else lmin
            cx, cy, tmx, tmy, _t = dda_next(cx, cy, step_x, step_y, tmx, tmy, tdx, tdy)
        if blocked:
            continue
        if 0 <= tx < w and 0 <= ty < h and logodds[ty, tx] <= stop_above:
            if hit[k]:
                v = logodds[ty, tx] + l_occ
                logodds[ty, tx] = v if v < lmax else lmax
            else:
                v = logodds[ty, tx] + l_free
                logodds[ty, tx] = v if v > lmin else lmin


def scan_endpoints(
    ranges: NDArray[np.float32],
    angles: FloatArray,
    range_min: float,
    range_max: float,
    max_range_m: float,
    carve_range_m: float,
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Beam end points ``(N, 2)`` in the laser frame and whether each is a hit.

    Returns within ``[range_min, min(range_max, max_range_m))`` are hits; ``+inf``
    or ``>= range_max`` (no return) are carved to ``carve_range_m`` without a hit;
    NaN, ``-inf`` and too-short readings are dropped.
    """
    pts, hit, _ = scan_beams(ranges, angles, range_min, range_max, max_range_m, carve_range_m)
    return pts, hit


def scan_beams(
    ranges: NDArray[np.float32],
    angles: FloatArray,
    range_min: float,
    range_max: float,
    max_range_m: float,
    carve_range_m: float,
) -> tuple[FloatArray, NDArray[np.bool_], NDArray[np.bool_]]:
    """:func:`scan_endpoints` and, per end point, whether its beam had no return
    (``+inf`` or ``>= range_max``; a return beyond ``max_range_m`` is a return)."""
    r = np.ascontiguousarray(ranges, dtype=np.float64).reshape(-1)
    a = np.ascontiguousarray(angles, dtype=np.float64).reshape(-1)
    return _endpoints(r, a, float(range_min), float(range_max), float(max_range_m), float(carve_range_m))


@njit(cache=True)
def _endpoints(r, a, range_min, range_max, max_range_m, carve_range_m):  # pragma: no cover - compiled
    n = r.shape[0]
    pts = np.empty((n, 2))
    hit = np.empty(n, dtype=np.bool_)
    missing = np.empty(n, dtype=np.bool_)
    lo = max(range_min, 1e-3)
    hi = min(range_max, max_range_m)
    m = 0
    for i in range(n):
        v = r[i]
        fin = np.isfinite(v)
        h = fin and v >= lo and v < hi
        noret = (v == np.inf or (fin and v >= range_max)) and not h
        longret = fin and v >= max_range_m and v < range_max
        if not (h or noret or longret):
            continue
        rr = v if h else min(carve_range_m, v if fin else carve_range_m)
        pts[m, 0] = rr * np.cos(a[i])
        pts[m, 1] = rr * np.sin(a[i])
        hit[m] = h
        missing[m] = noret
        m += 1
    return pts[:m].copy(), hit[:m].copy(), missing[:m].copy()


def _q(v: float) -> int:
    return int(round(v * LOGODDS_SCALE))


class LogOddsGrid:
    """A growing-free log-odds grid with fixed bounds (map frame, axis-aligned)."""

    def __init__(self, xmin: float, ymin: float, xmax: float, ymax: float, resolution: float = 0.05):
        self.resolution = float(resolution)
        self.x0 = float(np.floor(xmin / resolution) * resolution)
        self.y0 = float(np.floor(ymin / resolution) * resolution)
        w = int(np.ceil((xmax - self.x0) / resolution)) + 1
        h = int(np.ceil((ymax - self.y0) / resolution)) + 1
        self.logodds = np.zeros((h, w), dtype=np.int16)  # log-odds * LOGODDS_SCALE
        self._missing: list[tuple[FloatArray, FloatArray]] = []  # no-return beams, applied last

    def add_beams(self, origin_xy: FloatArray, ends_xy: FloatArray, hit: NDArray[np.bool_],
                  missing: NDArray[np.bool_] | None = None) -> None:
        """Integrate beams from one origin ``(2,)`` (or ``(N, 2)``) to end points ``(N, 2)`` (map frame).

        Beams flagged in ``missing`` (no return: :func:`scan_beams`) are kept and applied by
        :meth:`to_map` after every returned beam, each stopping before the first cell the
        returns made occupied; without ``missing`` every non-hit beam carves all the way."""
        ends = np.asarray(ends_xy, dtype=float).reshape(-1, 2)
        org = np.broadcast_to(np.asarray(origin_xy, dtype=float).reshape(-1, 2), ends.shape)
        hit = np.ascontiguousarray(hit, dtype=np.bool_)
        if missing is not None:
            miss = np.asarray(missing, dtype=np.bool_)
            if miss.any():
                self._missing.append((org[miss].copy(), ends[miss].copy()))
            keep = ~miss
            org, ends, hit = org[keep], ends[keep], np.ascontiguousarray(hit[keep])
        self._trace(org, ends, hit, np.iinfo(np.int16).max)

    def _trace(self, org: FloatArray, ends: FloatArray, hit: NDArray[np.bool_], stop_above: int) -> None:
        _integrate(
            self.logodds, self.x0, self.y0, self.resolution,
            np.ascontiguousarray(org[:, 0]), np.ascontiguousarray(org[:, 1]),
            np.ascontiguousarray(ends[:, 0]), np.ascontiguousarray(ends[:, 1]),
            hit, _q(L_OCC), _q(L_FREE), _q(L_MIN), _q(L_MAX), stop_above,
        )

    def _apply_missing(self) -> None:
        # Each stops before a cell above log-odds 0, which it never lowers, so the cells that stop
        # them are those the returns left above 0 whatever the order of the no-return beams.
        for org, ends in self._missing:
            self._trace(org, ends, np.zeros(len(ends), dtype=np.bool_), 0)
        self._missing.clear()

    def to_map(self, occ_logodds: float = 0.62, free_logodds: float = -1.0) -> OccupancyMap:
        """Trinary map: occupied above ``occ_logodds``, free below ``free_logodds``, else unknown.

        Applies the no-return beams given so far first (:meth:`add_beams`)."""
        self._apply_missing()
        data = np.full(self.logodds.shape, -1, dtype=np.int16)
        for r0 in range(0, data.shape[0], 512):  # in row blocks: no full-size temporaries
            lo = self.logodds[r0:r0 + 512]
            blk = data[r0:r0 + 512]
            blk[lo < free_logodds * LOGODDS_SCALE] = 0
            blk[lo > occ_logodds * LOGODDS_SCALE] = 100
        return OccupancyMap(data=data, resolution=self.resolution, origin=np.array([self.x0, self.y0, 0.0]))
