"""Scan matching against a point-set distance field (numba).

A :class:`DistanceGrid` holds, for every cell of a local grid, the Euclidean
distance (m, clipped at ``dmax_m``) from the cell centre to the nearest map
point.  It is built by stamping a disc around every point (exact sub-cell
distances, no EDT), which is fast for the few thousand points of a submap.

Matching a scan (points ``(N, 2)`` in the robot frame) against a grid:

* :func:`correlative_search` — brute-force search over a window of poses,
  scoring ``mean(exp(-d^2 / 2 sigma^2))`` with nearest-cell lookups; returns the
  best pose, its score and the score of the best pose far from it (ambiguity).
* :func:`refine` — Gauss-Newton on the bilinearly interpolated distance with a
  Huber kernel; returns the pose, the information (``J^T W J``) and quality.

Core maths only: no I/O, no printing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import NDArray

from fgloc.gridmath import bilinear_grad_world as _lookup_bilinear

FloatArray = NDArray[np.float64]


@dataclass
class DistanceGrid:
    """Distance field (m) over a grid in some frame F.

    ``dist[row, col]`` is the distance from the centre of cell ``(row, col)``
    (at ``x0 + (col + 0.5) r, y0 + (row + 0.5) r`` in F) to the nearest point.
    """

    dist: NDArray[np.float32]
    x0: float
    y0: float
    resolution: float
    dmax_m: float


def build_distance_grid(
    points: FloatArray, resolution: float = 0.05, dmax_m: float = 0.3, margin_m: float = 1.0
) -> DistanceGrid:
    """Distance grid over the bounding box of ``points`` (frame F) plus ``dmax_m + margin_m``."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if len(pts) > 0:  # overlapping scans repeat points: keep one per half cell
        keys = np.floor(pts / (0.5 * resolution)).astype(np.int64)
        _, idx = np.unique(keys[:, 0] * 4_000_037 + keys[:, 1], return_index=True)
        pts = pts[idx]
    pts = np.ascontiguousarray(pts)
    if len(pts) == 0:
        return DistanceGrid(np.full((2, 2), dmax_m, np.float32), 0.0, 0.0, resolution, dmax_m)
    pad = dmax_m + margin_m
    x0 = float(pts[:, 0].min() - pad)
    y0 = float(pts[:, 1].min() - pad)
    w = int(np.ceil((pts[:, 0].max() + pad - x0) / resolution)) + 1
    h = int(np.ceil((pts[:, 1].max() + pad - y0) / resolution)) + 1
    dist = np.full((h, w), dmax_m, dtype=np.float32)
    _stamp(dist, pts, x0, y0, resolution, dmax_m)
    return DistanceGrid(dist, x0, y0, resolution, dmax_m)


@njit(cache=True)
def _stamp(dist, pts, x0, y0, res, dmax):  # pragma: no cover - compiled
    """Lower every cell within ``dmax`` of a point to its distance (a disc per point; the square
    root only where the cell gets closer; the columns' centres computed once per call)."""
    h, w = dist.shape
    rad = int(np.ceil(dmax / res))
    d2max = dmax * dmax
    xcs = np.empty(w)
    for ix in range(w):
        xcs[ix] = x0 + (ix + 0.5) * res
    for k in range(pts.shape[0]):
        px, py = pts[k, 0], pts[k, 1]
        cx = int(np.floor((px - x0) / res))
        cy = int(np.floor((py - y0) / res))
        for iy in range(max(cy - rad, 0), min(cy + rad + 1, h)):
            yc = y0 + (iy + 0.5) * res
            dy = yc - py
            dy2 = dy * dy
            if dy2 > d2max:
                continue
            half = int(np.sqrt(d2max - dy2) / res) + 1
            row = dist[iy]
            for ix in range(max(cx - half, 0), min(cx + half + 1, w)):
                dx = xcs[ix] - px
                d2 = dx * dx + dy2
                cur = np.float64(row[ix])
                if d2 < cur * cur:
                    row[ix] = np.sqrt(d2)


@njit(cache=True)
def _lookup_nearest(dist, x0, y0, res, dmax, x, y):  # pragma: no cover - compiled
    h, w = dist.shape
    ix = int(np.floor((x - x0) / res))
    iy = int(np.floor((y - y0) / res))
    if ix < 0 or iy < 0 or ix >= w or iy >= h:
        return dmax
    return dist[iy, ix]


@njit(cache=True)
def _correlative(dist, x0, y0, res, dmax, pts, cx, cy, cth, nlin, lin_step, nang, ang_step, sigma):  # pragma: no cover
    n = pts.shape[0]
    scores = np.zeros((2 * nang + 1, 2 * nlin + 1, 2 * nlin + 1))
    inv2s2 = 1.0 / (2.0 * sigma * sigma)
    h, w = dist.shape
    nlut = 512
    lut = np.empty(nlut + 1)
    for i in range(nlut + 1):
        d = dmax * i / nlut
        lut[i] = np.exp(-d * d * inv2s2)
    qs = nlut / dmax
    s_out = lut[nlut]
    for a in range(2 * nang + 1):
        th = cth + (a - nang) * ang_step
        c, s = np.cos(th), np.sin(th)
        rx = np.empty(n)
        ry = np.empty(n)
        for k in range(n):
            rx[k] = c * pts[k, 0] - s * pts[k, 1]
            ry[k] = s * pts[k, 0] + c * pts[k, 1]
        for iy in range(2 * nlin + 1):
            ty = cy + (iy - nlin) * lin_step
            for ix in range(2 * nlin + 1):
                tx = cx + (ix - nlin) * lin_step
                acc = 0.0
                for k in range(n):
                    jx = int(np.floor((rx[k] + tx - x0) / res))
                    jy = int(np.floor((ry[k] + ty - y0) / res))
                    if jx < 0 or jy < 0 or jx >= w or jy >= h:
                        acc += s_out
                    else:
                        q = int(dist[jy, jx] * qs + 0.5)
                        acc += lut[q if q < nlut else nlut]
                scores[a, iy, ix] = acc / max(n, 1)
    return scores


@njit(cache=True)
def _local_maxima(sc):  # pragma: no cover - compiled
    """Cells not below any of their (up to 26) neighbours (scipy's 3x3x3 maximum_filter with
    mode="nearest", without its temporaries)."""
    na, ny, nx = sc.shape
    out = np.zeros(sc.shape, dtype=np.bool_)
    for a in range(na):
        for iy in range(ny):
            for ix in range(nx):
                v = sc[a, iy, ix]
                ok = True
                for da in range(max(a - 1, 0), min(a + 2, na)):
                    for dy in range(max(iy - 1, 0), min(iy + 2, ny)):
                        for dx in range(max(ix - 1, 0), min(ix + 2, nx)):
                            if sc[da, dy, dx] > v:
                                ok = False
                out[a, iy, ix] = ok
    return out


@dataclass
class SearchResult:
    pose: FloatArray
    score: float
    ambiguity: float  # best score at least ``far_m`` / ``far_rad`` from the best, divided by the best
    offsets: FloatArray | None = None  # (M, 3) every searched pose minus the best [dx, dy, dth] ...
    scores: FloatArray | None = None   # ... and its score (M,), for direction-aware ambiguity
    peaks: np.ndarray | None = None    # (M,) local maxima of the scores

    def ambiguous_axis(self, max_ambiguity: float, across_m: float, far_rad: float) -> FloatArray | None:
        """The unit direction along which the search is ambiguous when that is all it is: the
        rival peaks (score above ``max_ambiguity`` of the best, away from it) lie on a line
        through the best pose, and nothing more than ``across_m`` across that line or ``far_rad``
        turned comes close.  None when the ambiguity is not of that kind."""
        if self.offsets is None or self.scores is None or self.score <= 0:
            return None
        rival = self.scores >= max_ambiguity * self.score
        if self.peaks is not None:
            rival &= self.peaks
        rival &= np.hypot(self.offsets[:, 0], self.offsets[:, 1]) > 2 * across_m
        if not rival.any():
            return None
        d = self.offsets[rival, :2]
        w, v = np.linalg.eigh(d.T @ d)
        axis = v[:, 1]
        return axis if self.ambiguity_across(axis, across_m, far_rad) <= max_ambiguity else None

    def ambiguity_across(self, axis_xy: FloatArray, far_m: float, far_rad: float) -> float:
        """Ambiguity ignoring shifts along ``axis_xy`` (a unit vector): the best score of poses
        more than ``far_m`` across the axis or ``far_rad`` turned, divided by the best.  A
        corridor is ambiguous along itself, yet fixes the position across it and the heading."""
        if self.offsets is None or self.scores is None or self.score <= 0:
            return self.ambiguity
        n = np.array([-axis_xy[1], axis_xy[0]])
        far = (np.abs(self.offsets[:, :2] @ n) > far_m) | (np.abs(self.offsets[:, 2]) > far_rad)
        if self.peaks is not None:
            far &= self.peaks
        return float(self.scores[far].max() / self.score) if far.any() else 0.0


def correlative_search(
    grid: DistanceGrid,
    points: FloatArray,
    center: FloatArray,
    window_m: float,
    window_rad: float,
    lin_step_m: float,
    ang_step_rad: float,
    sigma_m: float,
    far_m: float = 0.5,
    far_rad: float = 0.2,
) -> SearchResult:
    """Exhaustive search of poses ``center + (dx, dy, dth)`` in the window; best by mean Gaussian score."""
    pts = np.ascontiguousarray(points, dtype=np.float64)
    nlin = max(int(round(window_m / lin_step_m)), 0)
    nang = max(int(round(window_rad / ang_step_rad)), 0)
    sc = _correlative(
        grid.dist, grid.x0, grid.y0, grid.resolution, grid.dmax_m, pts,
        float(center[0]), float(center[1]), float(center[2]),
        nlin, lin_step_m, nang, ang_step_rad, sigma_m,
    )
    a, iy, ix = np.unravel_index(int(np.argmax(sc)), sc.shape)
    best = float(sc[a, iy, ix])
    pose = np.array([
        center[0] + (ix - nlin) * lin_step_m,
        center[1] + (iy - nlin) * lin_step_m,
        center[2] + (a - nang) * ang_step_rad,
    ])
    aa, yy, xx = np.meshgrid(
        (np.arange(2 * nang + 1) - a) * ang_step_rad,
        (np.arange(2 * nlin + 1) - iy) * lin_step_m,
        (np.arange(2 * nlin + 1) - ix) * lin_step_m,
        indexing="ij",
    )
    # rivals are distinct peaks (local maxima) away from the best: the flanks of the best peak,
    # long in a corridor under the coarse search's wide kernel, are no rivals
    peak = _local_maxima(sc)
    far = ((np.hypot(xx, yy) > far_m) | (np.abs(aa) > far_rad)) & peak
    amb = float(sc[far].max() / best) if far.any() and best > 0 else 0.0
    offsets = np.column_stack([xx.ravel(), yy.ravel(), aa.ravel()])
    return SearchResult(pose, best, amb, offsets, sc.ravel(), peak.ravel())


@njit(cache=True)
def _huber_cost(dist, x0, y0, res, dmax, pts, px, py, pth, huber):  # pragma: no cover - compiled
    """Sum of the Huber costs of the points' distances (clipped at ``dmax``: a point leaving the
    field costs as much as one at its edge, so leaving it is no descent)."""
    c, s = np.cos(pth), np.sin(pth)
    cost = 0.0
    for k in range(pts.shape[0]):
        lx, ly = pts[k, 0], pts[k, 1]
        d, _gx, _gy = _lookup_bilinear(dist, x0, y0, res, dmax, px + c * lx - s * ly, py + s * lx + c * ly)
        if d > dmax:
            d = dmax
        cost += 0.5 * d * d if d <= huber else huber * (d - 0.5 * huber)
    return cost


@njit(cache=True)
def _gauss_newton(dist, x0, y0, res, dmax, pts, px, py, pth, huber, iters):  # pragma: no cover - compiled
    """Levenberg-Marquardt: a step is taken only when it lowers the cost (else the damping grows).
    The bilinear distance field is flat between the two cell centres either side of a wall, so the
    plain Gauss-Newton step there (gradient ~0, residual ~half a cell) was unbounded: from the
    right pose it jumped decimetres and degrees away and wandered back only partly."""
    n = pts.shape[0]
    H = np.zeros((3, 3))
    lam = 1e-3
    cost = _huber_cost(dist, x0, y0, res, dmax, pts, px, py, pth, huber)
    for _it in range(iters):
        H = np.zeros((3, 3))
        g = np.zeros(3)
        c, s = np.cos(pth), np.sin(pth)
        for k in range(n):
            lx, ly = pts[k, 0], pts[k, 1]
            wx = px + c * lx - s * ly
            wy = py + s * lx + c * ly
            d, gx, gy = _lookup_bilinear(dist, x0, y0, res, dmax, wx, wy)
            if d >= dmax * 0.999:
                continue
            w = 1.0 if d <= huber else huber / d
            # d(wx,wy)/dth
            dxt = -s * lx - c * ly
            dyt = c * lx - s * ly
            j0, j1, j2 = gx, gy, gx * dxt + gy * dyt
            H[0, 0] += w * j0 * j0
            H[0, 1] += w * j0 * j1
            H[0, 2] += w * j0 * j2
            H[1, 1] += w * j1 * j1
            H[1, 2] += w * j1 * j2
            H[2, 2] += w * j2 * j2
            g[0] += w * j0 * d
            g[1] += w * j1 * d
            g[2] += w * j2 * d
        H[1, 0] = H[0, 1]
        H[2, 0] = H[0, 2]
        H[2, 1] = H[1, 2]
        accepted = False
        step = np.zeros(3)
        for _try in range(8):
            A = H.copy()
            for i in range(3):
                A[i, i] += 1e-6 + lam * H[i, i]
            if abs(np.linalg.det(A)) < 1e-18:
                break
            step = -np.linalg.solve(A, g)
            c_new = _huber_cost(dist, x0, y0, res, dmax, pts, px + step[0], py + step[1], pth + step[2], huber)
            if c_new <= cost:
                cost = c_new
                accepted = True
                lam = max(lam * 0.1, 1e-6)
                break
            lam *= 10.0
        if not accepted:
            break
        px += step[0]
        py += step[1]
        pth += step[2]
        if abs(step[0]) < 1e-5 and abs(step[1]) < 1e-5 and abs(step[2]) < 1e-6:
            break
    # final quality
    c, s = np.cos(pth), np.sin(pth)
    sq = 0.0
    nin = 0
    for k in range(n):
        lx, ly = pts[k, 0], pts[k, 1]
        d = _lookup_nearest(dist, x0, y0, res, dmax, px + c * lx - s * ly, py + s * lx + c * ly)
        if d < 0.1:
            nin += 1
            sq += d * d
    return px, py, pth, H, nin, sq


@dataclass
class RefineResult:
    pose: FloatArray
    info: FloatArray  # 3x3 J^T W J (unit per-point noise)
    inlier_frac: float  # fraction of points within 0.1 m of the map after refinement
    rms_inlier_m: float


def refine(grid: DistanceGrid, points: FloatArray, guess: FloatArray, huber_m: float = 0.05,
           iters: int = 15) -> RefineResult:
    """Gauss-Newton alignment of ``points`` (robot frame) to the grid, starting at ``guess``."""
    pts = np.ascontiguousarray(points, dtype=np.float64)
    px, py, pth, H, nin, sq = _gauss_newton(
        grid.dist, grid.x0, grid.y0, grid.resolution, grid.dmax_m, pts,
        float(guess[0]), float(guess[1]), float(guess[2]), huber_m, iters,
    )
    n = max(len(pts), 1)
    pose = np.array([px, py, (pth + np.pi) % (2 * np.pi) - np.pi])
    return RefineResult(pose, H, nin / n, float(np.sqrt(sq / max(nin, 1))))


def match_covariance(info: FloatArray, sigma_m: float, floor_xy_m: float = 0.01,
                     floor_yaw_rad: float = 0.003) -> FloatArray:
    """Covariance ``sigma^2 H^-1`` of a refined match, regularized and floored."""
    H = np.asarray(info, dtype=float) + np.diag([1e-3, 1e-3, 1e-3])
    try:
        cov = sigma_m**2 * np.linalg.inv(H)
    except np.linalg.LinAlgError:
        cov = np.diag([1.0, 1.0, 0.1])
    cov = 0.5 * (cov + cov.T)
    cov[0, 0] += floor_xy_m**2
    cov[1, 1] += floor_xy_m**2
    cov[2, 2] += floor_yaw_rad**2
    return cov


@njit(cache=True)
def _distances(dist, x0, y0, res, dmax, pts, px, py, pth):  # pragma: no cover - compiled
    n = pts.shape[0]
    out = np.empty(n)
    c, s = np.cos(pth), np.sin(pth)
    for k in range(n):
        lx, ly = pts[k, 0], pts[k, 1]
        out[k] = _lookup_nearest(dist, x0, y0, res, dmax, px + c * lx - s * ly, py + s * lx + c * ly)
    return out


def point_distances(grid: DistanceGrid, points: FloatArray, pose: FloatArray) -> FloatArray:
    """Distance (m, clipped at ``grid.dmax_m``) from each of ``points`` (robot frame) placed at
    ``pose`` to the grid's point set (nearest-cell lookup)."""
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2)
    return _distances(grid.dist, grid.x0, grid.y0, grid.resolution, grid.dmax_m, pts,
                      float(pose[0]), float(pose[1]), float(pose[2]))


def voxel_subsample(points: FloatArray, voxel_m: float) -> FloatArray:
    """One point per ``voxel_m`` square (the first in input order); all points when ``voxel_m <= 0``."""
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    if len(pts) == 0 or voxel_m <= 0:
        return pts
    keys = np.floor(pts / voxel_m).astype(np.int64)
    _, idx = np.unique(keys[:, 0] * 1_000_003 + keys[:, 1], return_index=True)
    return pts[np.sort(idx)]


class BufferPool:
    """Freed float32 buffers kept for reuse (at most ``max_bytes``): a submap field of tens of
    megabytes taken from the pool costs a fill, from the OS also its page faults and zeroing."""

    def __init__(self, max_bytes: float = 64e6):
        self.max_bytes = float(max_bytes)
        self._free: list[NDArray[np.float32]] = []

    def take(self, n: int) -> NDArray[np.float32]:
        """A flat buffer of at least ``n`` values (contents undefined)."""
        fits = [i for i, b in enumerate(self._free) if b.size >= n]
        if fits:
            return self._free.pop(min(fits, key=lambda i: self._free[i].size))
        return np.empty(n, dtype=np.float32)

    def give(self, buf: NDArray[np.float32]) -> None:
        """Return ``buf`` (flat; nothing may use it afterwards); the smallest are dropped over budget."""
        self._free.append(buf)
        self._free.sort(key=lambda b: b.size, reverse=True)
        while self._free and sum(b.nbytes for b in self._free) > self.max_bytes:
            self._free.pop()


class GrowingDistanceGrid:
    """A distance field that point sets are stamped into one after another (a submap being built).

    Cells keep the distance to the nearest point stamped so far (clipped at ``dmax_m``); the
    bounds grow (by at least ``grow_m``) when new points fall outside.  Adding a point set costs
    its own points only, not a rebuild of everything stamped before.  With a ``pool`` the field's
    memory comes from and goes back to it: a :meth:`grid` is then valid only until the next
    :meth:`add` or :meth:`release`.
    """

    def __init__(self, resolution: float = 0.05, dmax_m: float = 0.3, grow_m: float = 5.0,
                 pool: BufferPool | None = None):
        self.resolution = float(resolution)
        self.dmax_m = float(dmax_m)
        self.grow_m = float(grow_m)
        self.dist: NDArray[np.float32] | None = None
        self._buf: NDArray[np.float32] | None = None  # the flat buffer under dist
        self.pool = pool
        self.ix0 = 0  # lower-left cell index of the grid on the global lattice (x0 = ix0 * resolution)
        self.iy0 = 0
        self.count = 0  # point sets added

    @property
    def nbytes(self) -> int:
        return 0 if self.dist is None else int(self.dist.nbytes)

    def _alloc(self, h: int, w: int) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        buf = self.pool.take(h * w) if self.pool is not None else np.empty(h * w, dtype=np.float32)
        return buf, buf[: h * w].reshape(h, w)

    def release(self) -> None:
        """Give the field's memory back to the pool (the grid is empty afterwards)."""
        if self.pool is not None and self._buf is not None:
            self.pool.give(self._buf)
        self.dist = self._buf = None

    def add(self, points: FloatArray) -> None:
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        self.count += 1
        if len(pts) == 0:
            return
        res = self.resolution
        keys = np.floor(pts / (0.5 * res)).astype(np.int64)
        _, idx = np.unique(keys[:, 0] * 4_000_037 + keys[:, 1], return_index=True)
        pts = np.ascontiguousarray(pts[idx])
        pad = self.dmax_m + res
        lo = np.floor((pts.min(axis=0) - pad) / res).astype(np.int64)
        hi = np.ceil((pts.max(axis=0) + pad) / res).astype(np.int64)
        if self.dist is None:
            g = int(np.ceil(self.grow_m / res))
            self.ix0, self.iy0 = int(lo[0] - g), int(lo[1] - g)
            h, w = int(hi[1] + g - self.iy0), int(hi[0] + g - self.ix0)
            self._buf, self.dist = self._alloc(h, w)
            self.dist.fill(self.dmax_m)
        else:
            h, w = self.dist.shape
            if lo[0] < self.ix0 or lo[1] < self.iy0 or hi[0] > self.ix0 + w or hi[1] > self.iy0 + h:
                g = int(np.ceil(self.grow_m / res))
                nx0 = min(self.ix0, int(lo[0]) - g) if lo[0] < self.ix0 else self.ix0
                ny0 = min(self.iy0, int(lo[1]) - g) if lo[1] < self.iy0 else self.iy0
                nx1 = max(self.ix0 + w, int(hi[0]) + g) if hi[0] > self.ix0 + w else self.ix0 + w
                ny1 = max(self.iy0 + h, int(hi[1]) + g) if hi[1] > self.iy0 + h else self.iy0 + h
                buf, new = self._alloc(ny1 - ny0, nx1 - nx0)
                r0, c0 = self.iy0 - ny0, self.ix0 - nx0  # the old field's place in the new one
                new[:r0] = self.dmax_m  # the margins only: the old field is copied into the rest
                new[r0 + h:] = self.dmax_m
                new[r0:r0 + h, :c0] = self.dmax_m
                new[r0:r0 + h, c0 + w:] = self.dmax_m
                new[r0:r0 + h, c0:c0 + w] = self.dist
                self.release()
                self._buf, self.dist, self.ix0, self.iy0 = buf, new, nx0, ny0
        _stamp(self.dist, pts, self.ix0 * res, self.iy0 * res, res, self.dmax_m)

    def grid(self) -> DistanceGrid:
        """The field as a :class:`DistanceGrid` (a view: later ``add`` calls change it)."""
        if self.dist is None:
            return DistanceGrid(np.full((2, 2), self.dmax_m, np.float32), 0.0, 0.0, self.resolution, self.dmax_m)
        return DistanceGrid(self.dist, self.ix0 * self.resolution, self.iy0 * self.resolution, self.resolution,
                            self.dmax_m)


def coarsen_grid(grid: DistanceGrid, factor: int) -> DistanceGrid:
    """The grid at ``factor`` times the cell size, each coarse cell holding the minimum of its fine
    cells (an optimistic distance: for coarse correlative search, where it keeps the true peak)."""
    f = max(int(factor), 1)
    if f == 1:
        return grid
    return DistanceGrid(_minpool(grid.dist, f, np.float32(grid.dmax_m)), grid.x0, grid.y0, grid.resolution * f,
                        grid.dmax_m)


@njit(cache=True)
def _minpool(dist, f, dmax):  # pragma: no cover - compiled
    h, w = dist.shape
    hh = (h + f - 1) // f
    ww = (w + f - 1) // f
    out = np.full((hh, ww), dmax, dtype=np.float32)
    for i in range(h):
        oi = i // f
        for j in range(w):
            v = dist[i, j]
            if v < out[oi, j // f]:
                out[oi, j // f] = v
    return out
