"""Coarse global localization: where in the map does this scan fit?

Used by :class:`fgloc.localization.Localizer` when no initial pose is given and after a
kidnapping (too many scans in a row without an accepted fix), for front-ends without
a global mode of their own (native, kiss; AMCL spreads its particles instead).

Method: candidate positions on a grid over the map's free space (``step_m``, coarser on
large maps so there are about ``max_candidates``; cells at least ``clearance_m`` from
obstacles), ``n_yaw`` headings each; every candidate scores
the scan's (subsampled) points against the map's distance field with a Gaussian
likelihood ``mean(exp(-d^2 / 2 sigma^2))`` (a correlative search, compiled with
numba).  The best ``n_best`` distinct candidates are returned, best first; the caller
refines them with its scan matcher and keeps the one that matches best.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fgloc.config.schema import setting, with_overrides
from fgloc.maps import OccupancyMap

try:
    from numba import njit
except ImportError:  # pragma: no cover
    def njit(*args, **kwargs):  # type: ignore[no-redef]
        def deco(f):
            return f
        return deco if not (args and callable(args[0])) else args[0]

FloatArray = NDArray[np.float64]


@njit(cache=True)
def _score_all(lik, cx, cy, px, py):  # pragma: no cover - compiled
    """Mean likelihood of points (grid units, per yaw: px/py shape (Y, P)) at each candidate."""
    h, w = lik.shape
    n_c = cx.shape[0]
    n_y, n_p = px.shape
    out = np.zeros((n_c, n_y))
    for i in range(n_c):
        for j in range(n_y):
            acc = 0.0
            for k in range(n_p):
                c = int(np.floor(cx[i] + px[j, k]))
                r = int(np.floor(cy[i] + py[j, k]))
                if 0 <= r < h and 0 <= c < w:
                    acc += lik[r, c]
            out[i, j] = acc / n_p
    return out


@dataclass(frozen=True)
class GlobalSearchConfig:
    """``pipeline.global_search``: the coarse correlative global search (native / kiss)."""

    step_m: float = setting(0.25, "candidate grid spacing over free space (coarser on big maps)", gt=0)
    max_candidates: int = setting(4000, "positions scored at most (about)", min=1)
    n_yaw: int = setting(72, "headings per candidate position (72 = 5 deg)", min=1)
    sigma_m: float = setting(0.15, "width of the Gaussian likelihood a point scores with", gt=0)
    max_points: int = setting(60, "scan points scored (uniform stride)", min=1)
    n_best: int = setting(20, "candidates refined by the front-end; the best quality wins", min=1)
    clearance_m: float = setting(0.2, "candidates at least this far from obstacles", min=0)
    seed: int = setting(0, "random subsampling of candidates on very large maps")


class GlobalSearch:
    def __init__(self, occ_map: OccupancyMap, config: GlobalSearchConfig | None = None, **overrides: Any) -> None:
        c = with_overrides(GlobalSearchConfig, config, overrides)
        step_m, n_yaw, sigma_m, max_points = c.step_m, c.n_yaw, c.sigma_m, c.max_points
        clearance_m, n_best, max_candidates, seed = c.clearance_m, c.n_best, c.max_candidates, c.seed
        self.config = c
        self.map = occ_map
        self.n_yaw = int(n_yaw)
        self.sigma = float(sigma_m)
        self.max_points = int(max_points)
        self.n_best = int(n_best)
        df = np.minimum(occ_map.distance_field, 3.0 * sigma_m * 4)
        self._df = np.where(np.isfinite(df), df, 3.0 * sigma_m * 4)
        self._lik = np.ascontiguousarray(np.exp(-0.5 * (self._df / self.sigma) ** 2))
        free = occ_map.free & (occ_map.distance_field >= clearance_m)
        rows, cols = np.nonzero(free)
        # coarser grid on large maps so the candidate count stays near max_candidates
        step = max(step_m, float(np.sqrt(len(rows) / max(1, max_candidates))) * occ_map.resolution)
        stride = max(1, int(round(step / occ_map.resolution)))
        keep = (rows % stride == 0) & (cols % stride == 0)
        cand = occ_map.grid_to_world(rows[keep], cols[keep])
        if len(cand) > 2 * max_candidates:
            rng = np.random.default_rng(seed)
            cand = cand[rng.choice(len(cand), 2 * max_candidates, replace=False)]
        self.candidates = cand
        self.step_m = stride * occ_map.resolution

    def search(self, points_base: FloatArray) -> list[tuple[FloatArray, float]]:
        """Best candidate poses ``[x, y, yaw]`` with their scores in ``[0, 1]``, best first.

        ``points_base``: the scan's valid returns in the robot (``base_link``) frame, ``(N, 2)``.
        """
        pts = np.asarray(points_base, dtype=float)
        if len(pts) == 0 or len(self.candidates) == 0:
            return []
        if len(pts) > self.max_points:
            pts = pts[np.linspace(0, len(pts) - 1, self.max_points).astype(int)]
        yaws = np.linspace(-np.pi, np.pi, self.n_yaw, endpoint=False)
        c, s = np.cos(yaws), np.sin(yaws)
        # rotated points for each yaw: (n_yaw, P, 2)
        rx = c[:, None] * pts[None, :, 0] - s[:, None] * pts[None, :, 1]
        ry = s[:, None] * pts[None, :, 0] + c[:, None] * pts[None, :, 1]
        # everything in continuous grid coordinates (the map origin may be rotated)
        res = self.map.resolution
        oc, os_ = np.cos(self.map.origin[2]), np.sin(self.map.origin[2])
        gpx = (oc * rx + os_ * ry) / res
        gpy = (-os_ * rx + oc * ry) / res
        cg = self.map.world_to_grid_continuous(self.candidates)
        scores = _score_all(self._lik, np.ascontiguousarray(cg[:, 0]), np.ascontiguousarray(cg[:, 1]),
                            np.ascontiguousarray(gpx), np.ascontiguousarray(gpy))
        out: list[tuple[FloatArray, float]] = []
        for flat in best_first(scores.ravel()):
            ci, yi = divmod(int(flat), self.n_yaw)
            pose = np.array([self.candidates[ci, 0], self.candidates[ci, 1], yaws[yi]])
            if all(np.hypot(*(pose[:2] - p[:2])) > 1.0 or abs(np.angle(np.exp(1j * (pose[2] - p[2])))) > 0.5
                   for p, _ in out):
                out.append((pose, float(scores[ci, yi])))
            if len(out) >= self.n_best:
                break
        return out


#: scores sorted per batch by :func:`best_first` (the suppression of near duplicates rarely needs more)
FIRST_BATCH = 1024


def best_first(scores: FloatArray) -> Iterator[int]:
    """The indices of ``scores`` (1-D) from the highest score down, ties from the highest index down
    (as a stable ascending sort read backwards), sorted lazily: a batch of the best
    :data:`FIRST_BATCH` (every score tied with the batch's last included) at a time, each batch
    found by a partial selection (``np.argpartition``, linear) and sorted alone, instead of a full
    sort of every candidate pose's score when only the first few dozen are read."""
    n = len(scores)
    rest = np.arange(n)
    batch = FIRST_BATCH
    while len(rest):
        vals = scores[rest]
        if len(rest) > batch:
            kth = float(vals[np.argpartition(vals, len(rest) - batch)[len(rest) - batch]])
            top = vals >= kth
            take, rest = rest[top], rest[~top]
        else:
            take, rest = rest, rest[:0]
        # descending score, then descending index
        yield from take[np.lexsort((-take, -scores[take]))].tolist()
        batch *= 4
