"""Global localization and relocalization: where in the map is the robot, when tracking cannot say.

:class:`Relocalizer` owns the coarse correlative :class:`~fgloc.backends.global_search.GlobalSearch`
(for front-ends without a global mode of their own) and the relocalization state:

* :meth:`candidates` - global-search candidates refined by the front-end, best quality first
  (the compass, once its offset is known, rules out headings: the mirror image of a
  symmetric hall);
* :meth:`search` - the best candidate if it is good enough (start-up without a pose, lost);
* :meth:`check` - while tracking has had no accepted fix for a while: a candidate becomes
  *pending* only when it is consistent and unambiguous, and is taken only after it matched
  again on further scans spanning some time (see the method).

Core logic only: no I/O.
"""

from __future__ import annotations

import math
import sys
from typing import Any

import numpy as np

from fgloc.backends.base import Backend, FloatArray
from fgloc.geometry import compose1, transform_points, wrap_angle
from fgloc.localization.agreement import agreements, climb, finest_steps
from fgloc.localization.config import PipelineConfig
from fgloc.maps import OccupancyMap
from fgloc.types import LaserScan, PoseFix, StaticTransform


def close(a: FloatArray, b: FloatArray, dist_m: float, dyaw_rad: float) -> bool:
    """Whether poses ``a`` and ``b`` are within ``dist_m`` and ``dyaw_rad`` of each other."""
    return float(np.hypot(a[0] - b[0], a[1] - b[1])) <= dist_m and abs(float(wrap_angle(a[2] - b[2]))) <= dyaw_rad


#: :func:`place_near` climbs at most this many of the agreement's finest steps (0.4 m on a 5 cm map)
NEAR_STEPS = 16


def place_near(occ_map: OccupancyMap, laser_mount: StaticTransform, scan: LaserScan, pose: FloatArray,
               sigma_m: float, reach_m: float = math.inf) -> tuple[FloatArray, float]:
    """The pose the scan's agreement with the map (distance scale ``sigma_m``) climbs to from ``pose`` in its
    finest steps (at most :data:`NEAR_STEPS`, within ``reach_m``), and the agreement there (NaN: no beams)."""
    pts = scan.points()
    start = np.asarray(pose, dtype=float).reshape(3)
    if len(pts) < 2:
        return start, math.nan
    near = climb(occ_map, laser_mount, start, reach_m, sigma_m, pts, finest_steps(sigma_m, pts), NEAR_STEPS)
    return near, float(agreements(occ_map, laser_mount, scan, near[None, :], sigma_m, pts)[0])


def prime_distance_field(occ_map: OccupancyMap) -> None:
    """Give ``occ_map.distance_field`` (a cached property) its value from the native matcher's exact
    distance transform when that module is loaded: :func:`fgloc.frontends.native.edt_squared` is
    ``scipy.ndimage.distance_transform_edt(~occupied) ** 2`` bit for bit, its square root times the
    resolution the same field, 3x faster and without importing ``scipy.ndimage`` (60 ms of a run's
    start on its own).  A map without obstacles, a field already there, or another front-end: the
    property's own way."""
    native = sys.modules.get("fgloc.frontends.native")
    if native is None or "distance_field" in vars(occ_map):
        return
    occ = occ_map.occupied
    if not occ.any():
        return
    d = native.edt_squared(occ)
    np.sqrt(d, out=d)
    d *= occ_map.resolution
    occ_map.distance_field = d


class Relocalizer:
    """Global search and the pending relocalization candidate (see the module docstring)."""

    def __init__(self, cfg: PipelineConfig, occ_map: OccupancyMap, laser_mount: StaticTransform,
                 frontend: Any, backend: Backend, stats: dict[str, Any]) -> None:
        self.cfg = cfg
        self.map = occ_map
        self.laser_mount = laser_mount
        self.frontend = frontend
        self.backend = backend
        self.stats = stats
        self.pending: tuple[FloatArray, FloatArray, int, float] | None = None  # pose, cov, matches, t_first
        self.tick = 0
        self._global: Any = None
        self.last_compass: tuple[float, float] | None = None  # (stamp, compass yaw)
        # the back-end's compass offset rules out headings only once accepted map fixes have
        # confirmed it: from a wrong initial pose it is wrong by as much (the localizer sets this)
        self.trust_compass = False

    def reset(self) -> None:
        """Forget the pending candidate (a fix was accepted, or the back-end was reset)."""
        self.pending = None
        self.tick = 0

    # ------------------------------------------------------------------ search
    def candidates(self, msg: LaserScan) -> list[tuple[float, PoseFix]]:
        """Front-end-refined global search candidates, best quality first."""
        from fgloc.backends.global_search import GlobalSearch

        if self._global is None:
            prime_distance_field(self.map)
            self._global = GlobalSearch(self.map, self.cfg.global_search)
        self.stats["global_searches"] += 1
        pts = msg.points()
        if len(pts) < 10:
            return []
        pts_base = transform_points(self.laser_mount.pose, pts)
        heading = None
        off = self.backend.compass_offset() if self.trust_compass else None
        if off is not None and self.last_compass is not None and \
                abs(float(msg.stamp) - self.last_compass[0]) < 1.0:
            heading = float(wrap_angle(self.last_compass[1] - off))
        max_dyaw = math.radians(self.cfg.global_compass_tolerance_deg)
        out: list[tuple[float, PoseFix]] = []
        for cand, _score in self._global.search(pts_base):
            if heading is not None and abs(float(wrap_angle(cand[2] - heading))) > max_dyaw:
                continue
            fix = self.frontend.match(msg, cand, None).to_fix(float(msg.stamp), self.frontend.name)
            if fix is not None:
                out.append((fix.quality, fix))
        out.sort(key=lambda qc: -qc[0])
        return out

    def search(self, msg: LaserScan) -> PoseFix | None:
        """The best global candidate, if its quality reaches ``global_min_quality`` and it is
        unambiguous as :meth:`check` requires (no other candidate more than 1 m / 20 deg away within
        ``relocalize_ambiguity`` of its quality): a scan that fits several places of the map equally
        well does not say which (on the mit-csail segment of ``tools/eval_frontends_real.py``, lost in
        space the map did not have, the best of 0.62, 0.62, 0.60 was 33 m off); the next scans may."""
        cands = self.candidates(msg)
        if not cands or cands[0][0] < self.cfg.global_min_quality:
            return None
        if self.ambiguous(cands):
            return None
        return cands[0][1]

    def ambiguous(self, cands: list[tuple[float, PoseFix]]) -> bool:
        """Another candidate more than 1 m / 20 deg from the best within ``relocalize_ambiguity`` of its
        quality (counted in ``stats['ambiguous_relocalizations']``)."""
        best_q, best = cands[0]
        for q, c in cands[1:]:
            if q >= best_q - self.cfg.relocalize_ambiguity and not close(c.pose, best.pose, 1.0, math.radians(20.0)):
                self.stats["ambiguous_relocalizations"] = self.stats.get("ambiguous_relocalizations", 0) + 1
                return True
        return False

    # ------------------------------------------------------------------ relocalization
    def check(self, msg: LaserScan, local: Any, odom_delta: FloatArray | None) -> PoseFix | None:
        """Tracking has had no accepted fix for ``relocalize_after`` scans: look for a better place.

        Tracking goes on meanwhile.  A global candidate (every ``relocalize_search_every``-th
        such scan) becomes *pending* only when it is consistent and unambiguous: quality at
        least ``relocalize_min_quality``, ``relocalize_margin`` better than the tracked pose's
        match (unless it is the tracked match itself), and no other candidate more than 1 m /
        20 deg away within ``relocalize_ambiguity`` of it.  A pending pose is carried along by
        odometry and must match again on ``relocalize_confirm`` further scans spanning at least
        ``relocalize_confirm_s`` (scans logged in a burst are not independent evidence) before
        it is returned (the caller resets the back-end to it); one failed match drops it.  So
        repetitive buildings (similar rooms, corridors) and fixes merely rejected for a while
        do not make the robot jump.
        """
        t = float(msg.stamp)
        cfg = self.cfg
        if self.pending is not None:
            pose = compose1(self.pending[0], odom_delta) if odom_delta is not None else self.pending[0]
            res = self.frontend.match(msg, pose, None)
            if res.ok and res.pose is not None and res.cov is not None and \
                    float(res.quality) >= cfg.relocalize_min_quality:
                count = self.pending[2] + 1
                t_first = self.pending[3]
                self.pending = (np.asarray(res.pose, dtype=float), np.asarray(res.cov, dtype=float), count, t_first)
                if count > cfg.relocalize_confirm and t - t_first >= cfg.relocalize_confirm_s:
                    self.pending = None
                    return PoseFix(t, np.asarray(res.pose, dtype=float), np.asarray(res.cov, dtype=float),
                                   quality=float(res.quality), source=self.frontend.name)
            else:
                self.pending = None
            return None
        self.tick += 1
        if (self.tick - 1) % cfg.relocalize_search_every != 0:
            return None
        cands = self.candidates(msg)
        if not cands:
            return None
        best_q, best = cands[0]
        if best_q < cfg.relocalize_min_quality:
            return None
        local_q = float(getattr(local, "quality", 0.0) or 0.0)
        near_local = local.ok and local.pose is not None and \
            close(best.pose, np.asarray(local.pose, dtype=float), 0.3, math.radians(5.0))
        if not near_local and best_q < local_q + cfg.relocalize_margin:
            return None
        for q, c in cands[1:]:
            if q >= best_q - cfg.relocalize_ambiguity and not close(c.pose, best.pose, 1.0, math.radians(20.0)):
                self.stats["ambiguous_relocalizations"] = self.stats.get("ambiguous_relocalizations", 0) + 1
                return None
        self.pending = (best.pose.copy(), best.cov.copy(), 1, t)
        return None
