"""2-D pose-graph SLAM on GTSAM: keyframes, scan-to-submap matching, loop closures.

Pipeline (core maths; no I/O, no printing — progress goes to a callback):

1. *Local tracking*: every scan is aligned (Gauss-Newton on a distance field)
   to a local submap made of the last ``submap_keyframes`` keyframes, starting
   from the previous pose composed with the odometry increment.
2. *Keyframes* every ``kf_dist_m`` / ``kf_angle_deg`` of tracked motion.  A
   keyframe gets a correlative search (coarse) before the refinement, an
   odometry ``BetweenFactorPose2`` and a scan-matching ``BetweenFactorPose2`` to
   the previous keyframe (covariance from the match Hessian), both with a
   Huber kernel.
3. *Loop closures*: the keyframe scan is matched against submaps around earlier
   keyframes within ``loop_radius_m`` of its current estimate (correlative
   search over a wide window, then refinement); accepted when the score and
   inlier fraction are high and the best peak is unambiguous, and added with a
   Cauchy kernel.  The graph is updated incrementally with iSAM2 and polished
   with batch Levenberg-Marquardt at the end.
4. Every scan's pose is its keyframe's optimized pose composed with the
   tracked offset from that keyframe.

Scans only (a log without odometry, ``scans_only``): each scan's guess is the
last tracked pose moved on at the velocity of the last tracked step (constant
velocity, at most ``odom_max_speed`` and ``scan_only_max_turn_dps``), every scan
that refines poorly from it gets the correlative search, and a keyframe's
"odometry" factor is its tracked motion (so a scan that did not fit keeps its
keyframe attached, loosely).  A robot standing still is not skipped: there is no
odometry to say so.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import gtsam
import numpy as np

from fgloc.geometry import between, compose, compose1, inverse, rotate_covariance, transform_points
from fgloc.mapping.occupancy import LogOddsGrid, scan_beams, scan_endpoints
from fgloc.mapping.scanmatch import (
    BufferPool,
    DistanceGrid,
    GrowingDistanceGrid,
    build_distance_grid,
    coarsen_grid,
    correlative_search,
    match_covariance,
    refine,
    voxel_subsample,
)
from fgloc.mapping.source import ScanRecord
from fgloc.maps import OccupancyMap
from fgloc.types import FloatArray, StaticTransform, Trajectory


@dataclass
class MapperConfig:
    """Mapper parameters (metres, degrees); defaults suit 180-360 beam indoor lidars."""

    resolution: float = 0.05          # output map cell size
    kf_dist_m: float = 0.25           # new keyframe after this much translation
    kf_angle_deg: float = 12.0        # ... or this much rotation
    max_range_m: float = 25.0         # returns beyond are not used as hits
    carve_range_m: float = 8.0        # no-return beams carve free space up to here (or to the first
                                      # cell the returns made occupied: occupancy.py)
    match_voxel_m: float = 0.0        # scan point subsampling for matching (0: every return)
    submap_keyframes: int = 25        # local submaps of N keyframes, a new one every N/2 (tracking
                                      # matches against the older one: the last N/2..N keyframes)
    submap_resolution: float = 0.025  # distance-field cell size for matching
    dmax_m: float = 0.3               # distance field clip
    huber_m: float = 0.02             # Gauss-Newton robust kernel width
    match_sigma_m: float = 0.05       # per-point noise for match covariances
    match_cov_inflation: float = 4.0  # points are correlated: inflate Hessian covariance
    track_min_inliers: float = 0.5    # below: tracking falls back to odometry
    kf_search_m: float = 0.15         # keyframe correlative window
    kf_search_deg: float = 6.0
    kf_search_below: float = 0.85     # ... searched only when refining from odometry leaves fewer inliers
    odom_jump_m: float = 1.0          # an odometry step longer than this + max_speed * dt is a jump ...
    odom_max_speed: float = 3.0       # ... (m/s) and is ignored (the scan matching bridges it)
    scan_only_max_turn_dps: float = 180.0  # scans only: the constant-velocity guess turns at most this (deg/s)
    scan_only_search_m: float = 0.3        # ... and a scan it leaves poorly fitted is searched for this far
    scan_only_search_deg: float = 25.0     # ... and turned this far (a robot that starts or stops turning)
    odom_sigma_xy: tuple[float, float] = (0.05, 0.2)     # sigma = a + b * distance (loose: real odometry is biased)
    odom_sigma_yaw: tuple[float, float] = (0.05, 0.5)    # sigma = a + b * |dyaw|
    loop_radius_m: float = 5.0        # candidates within this distance of the estimate
    loop_min_gap_kf: int = 40         # ... and at least this many keyframes older
    loop_every_kf: int = 3            # try loop closures every N keyframes ...
    loop_rest_kf: int = 5             # ... but not within N keyframes after one that the graph already
                                      # agreed with (within 0.1 m / 1 deg: no drift left to correct)
    loop_max_candidates: int = 2
    loop_submap_half: int = 12        # candidate submap = keyframes j-N .. j+N
    loop_window_m: float = 1.5        # correlative window around the predicted relative pose
    loop_window_deg: float = 20.0
    loop_min_score: float = 0.45      # fine Gaussian score to accept
    loop_min_inliers: float = 0.6     # fraction of points within 0.1 m after refinement
    loop_max_ambiguity: float = 0.92  # second-best distinct peak / best (ambiguous matches are kept only
                                      # in corridors, along which they then leave the position free)
    loop_cauchy_k: float = 1.0
    loop_dmax_m: float = 0.35         # distance-field clip of loop submaps
    loop_resolution_m: float = 0.05   # loop submap distance-field cell (refinement interpolates within it);
                                      # the coarse search uses a min-pooled copy of about 0.1 m cells
    loop_anchor_step: int = 4         # loop submaps are anchored at every N-th keyframe (cache reuse)
    loop_grid_cache_kf: int = 20      # reuse a loop submap grid for this many keyframes
    loop_grid_cache_mb: float = 48.0  # ... within this memory (oldest dropped first)
    final_batch: bool = True
    final_refine: bool = False        # re-align every scan to the optimized keyframes around it
    refine_half: int = 6              # ... keyframes k-N .. k+N (its own keyframe excluded)

    @staticmethod
    def from_dict(d: dict | None) -> MapperConfig:
        cfg = MapperConfig()
        for k, v in (d or {}).items():
            if not hasattr(cfg, k):
                from fgloc.errors import ConfigError

                raise ConfigError(f"unknown mapping option '{k}'")
            cur = getattr(cfg, k)
            if isinstance(cur, bool):
                if not isinstance(v, bool):
                    from fgloc.errors import ConfigError

                    raise ConfigError(f"mapping option '{k}' must be true or false, got {v!r}")
                setattr(cfg, k, v)
            elif isinstance(cur, tuple):
                setattr(cfg, k, tuple(float(x) for x in v))
            else:
                try:
                    setattr(cfg, k, type(cur)(v))
                except (TypeError, ValueError):
                    from fgloc.errors import ConfigError

                    raise ConfigError(f"mapping option '{k}': bad value {v!r}") from None
        return cfg


@dataclass
class Keyframe:
    scan_index: int
    stamp: float
    odom: FloatArray
    frontend: FloatArray        # tracked pose (local-SLAM frame)
    points: FloatArray          # hit points, base frame (submap content)
    match_points: FloatArray    # subsampled points, base frame (for matching)


@dataclass
class LoopClosure:
    i: int  # older keyframe
    j: int  # newer keyframe
    delta: FloatArray
    score: float
    inliers: float


@dataclass
class SlamResult:
    keyframes: list[Keyframe]
    keyframe_poses: FloatArray           # (K, 3) optimized, map frame
    scan_trajectory: Trajectory          # every scan's pose (map frame)
    keyframe_trajectory: Trajectory
    loops: list[LoopClosure]
    stats: dict = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)  # one line each: what the map may lack, and why


class GraphSlam:
    """Incremental pose-graph SLAM; feed :class:`ScanRecord` in order, then :meth:`finish`."""

    def __init__(self, mount: StaticTransform, config: MapperConfig | None = None, scans_only: bool = False):
        self.cfg = config or MapperConfig()
        self.scans_only = scans_only  # no odometry: constant-velocity guesses (module doc)
        self._vel = np.zeros(3)       # scans only: the last tracked step's body velocity (m/s, rad/s)
        self.mount = np.asarray(mount.pose, dtype=float)
        self.keyframes: list[Keyframe] = []
        self.loops: list[LoopClosure] = []
        self.scan_kf: list[int] = []             # keyframe each scan is attached to
        self.scan_rel: list[FloatArray] = []      # offset from that keyframe (frontend)
        self.scan_stamps: list[float] = []
        self.scan_points: list[FloatArray] = []   # match points of every scan (base frame)
        self._pose: FloatArray | None = None      # current tracked pose
        self._odom_prev: FloatArray | None = None
        self._odom_prev_inv = np.zeros(3)         # its inverse, and the last keyframe's tracked pose's
        self._kf_inv = np.zeros(3)                # (per-scan steps in scalar maths: compose1)
        self._odom_fix = np.zeros(3)              # odometry jumps removed: corrected = compose(fix, raw)
        self._stamp_prev: float | None = None
        self._grid: DistanceGrid | None = None
        self._submaps: list[tuple[int, GrowingDistanceGrid]] = []  # (first keyframe, field), oldest first
        self._pool = BufferPool()  # closed submaps' memory, for the next ones
        self.jumps: list[tuple[float, float]] = []  # (stamp, length m) of ignored odometry jumps
        self._isam = gtsam.ISAM2(gtsam.ISAM2Params())
        self._graph = gtsam.NonlinearFactorGraph()   # all factors (for the final batch)
        self._new_f = gtsam.NonlinearFactorGraph()
        self._new_v = gtsam.Values()
        self._est: FloatArray = np.zeros((0, 3))
        self._loop_grids: dict[int, tuple[int, DistanceGrid, DistanceGrid]] = {}  # j -> (k, fine, coarse)
        self._loops_seen = 0
        self._last_loop_kf = -(10**9)
        self.stats = {"scans": 0, "tracked": 0, "track_fail": 0, "stationary": 0, "keyframes": 0,
                      "kf_searches": 0, "loop_tries": 0, "loops": 0, "loops_corridor": 0, "loop_rejected": 0,
                      "odom_jumps": 0, "empty_scans": 0, "scans_only": int(scans_only)}

    # ------------------------------------------------------------ helpers
    def _scan_points(self, rec: ScanRecord) -> FloatArray:
        sc = rec.scan
        pts, hit = scan_endpoints(sc.ranges, sc.angles, sc.range_min, sc.range_max,
                                  self.cfg.max_range_m, self.cfg.carve_range_m)
        return transform_points(self.mount, pts[hit])

    def _noise(self, cov: FloatArray, robust: str | None, k: float):
        base = gtsam.noiseModel.Gaussian.Covariance(np.asarray(cov, dtype=float))
        if robust == "huber":
            return gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Huber.Create(k), base)
        if robust == "cauchy":
            return gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Cauchy.Create(k), base)
        return base

    def _add_factor(self, f) -> None:
        self._graph.add(f)
        self._new_f.add(f)

    def _insert_submaps(self, kf: Keyframe) -> None:
        """Stamp the new keyframe into the open submaps (starting one every N/2 keyframes, closing
        them at N); tracking matches against the oldest open one."""
        n = max(int(self.cfg.submap_keyframes), 2)
        k = len(self.keyframes) - 1
        if not self._submaps or k - self._submaps[-1][0] >= n // 2:
            self._submaps.append((k, GrowingDistanceGrid(self.cfg.submap_resolution, self.cfg.dmax_m,
                                                         pool=self._pool)))
        world = transform_points(kf.frontend, kf.points)
        self._grid = None  # its memory may go back to the pool below
        for _, sm in self._submaps:
            sm.add(world)
        while len(self._submaps) > 1 and k - self._submaps[0][0] + 1 >= n:
            self._submaps.pop(0)[1].release()
        self._grid = self._submaps[0][1].grid()

    # ------------------------------------------------------------ main step
    def add(self, rec: ScanRecord) -> None:
        cfg = self.cfg
        self.stats["scans"] += 1
        raw = np.asarray(rec.odom, dtype=float)
        if self.scans_only:  # the "odometry": the last tracked pose moved on at its velocity
            raw = self._constant_velocity(rec.stamp)
        elif not np.all(np.isfinite(raw)):  # no usable odometry: carry the last one on
            raw = self._odom_prev if self._odom_prev is not None else np.zeros(3)
        odom = compose1(self._odom_fix, raw)
        if self._pose is None or self._odom_prev is None:
            pts = self._scan_points(rec)
            mpts = voxel_subsample(pts, cfg.match_voxel_m)
            self.stats["empty_scans"] += len(pts) == 0
            self._pose = np.zeros(3)
            self._odom_prev = odom
            self._odom_prev_inv = inverse(odom)
            self._stamp_prev = rec.stamp
            self._new_keyframe(rec, pts, mpts, None, odom)
            return
        d_odom = compose1(self._odom_prev_inv, odom)
        jumped = False
        dt = abs(rec.stamp - self._stamp_prev) if self._stamp_prev is not None else 0.0
        step = float(np.hypot(d_odom[0], d_odom[1]))
        if step > cfg.odom_jump_m + cfg.odom_max_speed * min(dt, 10.0):
            # an odometry jump (reset, glitch): ignore it, the scan matching bridges the step
            self.jumps.append((float(rec.stamp), step))
            self.stats["odom_jumps"] += 1
            self._odom_fix = compose(self._odom_prev, between(raw, np.zeros(3)))
            odom = compose(self._odom_fix, raw)
            d_odom = between(self._odom_prev, odom)
            jumped = True
        self._odom_prev = odom
        self._odom_prev_inv = inverse(odom)
        self._stamp_prev = rec.stamp
        pred = compose1(self._pose, d_odom)
        rel_pred = compose1(self._kf_inv, pred)
        is_kf = (np.hypot(rel_pred[0], rel_pred[1]) >= cfg.kf_dist_m
                 or abs(rel_pred[2]) >= np.radians(cfg.kf_angle_deg))
        stationary = (np.hypot(d_odom[0], d_odom[1]) < 1e-4 and abs(d_odom[2]) < 1e-5 and not jumped
                      and not self.scans_only)
        info = None
        assert self._grid is not None
        if stationary and not is_kf:  # standing still: the scan is not even read
            self._pose = pred
            self.stats["stationary"] += 1
            self.scan_kf.append(len(self.keyframes) - 1)
            self.scan_rel.append(rel_pred)
            self.scan_stamps.append(rec.stamp)
            if cfg.final_refine:
                self.scan_points.append(voxel_subsample(self._scan_points(rec), cfg.match_voxel_m))
            return
        pts = self._scan_points(rec)
        mpts = voxel_subsample(pts, cfg.match_voxel_m)
        self.stats["empty_scans"] += len(pts) == 0
        if len(mpts) < 10:
            pose = pred
            self.stats["track_fail"] += 1
        else:
            rr = refine(self._grid, mpts, pred, cfg.huber_m)
            if (is_kf or self.scans_only) and rr.inlier_frac < cfg.kf_search_below:
                self.stats["kf_searches"] += 1
                win_m, win_deg = ((cfg.scan_only_search_m, cfg.scan_only_search_deg) if self.scans_only
                                  else (cfg.kf_search_m, cfg.kf_search_deg))
                sr = correlative_search(self._grid, mpts, pred, win_m, np.radians(win_deg),
                                        0.03, np.radians(1.0), 0.05)
                rs = refine(self._grid, mpts, sr.pose, cfg.huber_m)
                if rs.inlier_frac > rr.inlier_frac:
                    rr = rs
            if rr.inlier_frac >= cfg.track_min_inliers and np.hypot(*(rr.pose[:2] - pred[:2])) < 0.5:
                pose = rr.pose
                info = rr.info
                self.stats["tracked"] += 1
            else:
                pose = pred
                self.stats["track_fail"] += 1
        if self.scans_only:
            self._track_velocity(pose, dt, info is not None)
            odom = pose  # a keyframe's "odometry" factor: its tracked motion
        self._pose = pose
        rel = compose1(self._kf_inv, pose)
        if np.hypot(rel[0], rel[1]) >= cfg.kf_dist_m or abs(rel[2]) >= np.radians(cfg.kf_angle_deg):
            self._new_keyframe(rec, pts, mpts, info, odom)
        else:
            self.scan_kf.append(len(self.keyframes) - 1)
            self.scan_rel.append(rel)
            self.scan_stamps.append(rec.stamp)
            if cfg.final_refine:
                self.scan_points.append(mpts)

    def _constant_velocity(self, stamp: float) -> FloatArray:
        """Scans only: the pose the robot reaches at ``stamp`` from the last tracked pose at the last
        tracked step's velocity (the first scan: the origin)."""
        if self._pose is None or self._stamp_prev is None:
            return np.zeros(3)
        dt = min(max(stamp - self._stamp_prev, 0.0), 1.0)
        return compose1(self._pose, self._vel * dt)

    def _track_velocity(self, pose: FloatArray, dt: float, tracked: bool) -> None:
        """Scans only: the velocity of the step from the last pose to ``pose`` over ``dt`` (kept when
        the scan did not fit: the guess goes on as it was), bounded by ``odom_max_speed`` and
        ``scan_only_max_turn_dps``; ``pose`` is the next scan's "previous odometry"."""
        assert self._pose is not None
        if tracked and 0.0 < dt <= 1.0:
            v = between(self._pose, pose) / dt
            speed = float(np.hypot(v[0], v[1]))
            if speed > self.cfg.odom_max_speed:
                v[:2] *= self.cfg.odom_max_speed / speed
            wmax = float(np.radians(self.cfg.scan_only_max_turn_dps))
            v[2] = min(max(float(v[2]), -wmax), wmax)
            self._vel = v
        self._odom_prev = np.array(pose, dtype=float)
        self._odom_prev_inv = inverse(self._odom_prev)

    def _new_keyframe(self, rec: ScanRecord, pts: FloatArray, mpts: FloatArray, info: FloatArray | None,
                      odom: FloatArray) -> None:
        cfg = self.cfg
        assert self._pose is not None
        k = len(self.keyframes)
        kf = Keyframe(rec.index, rec.stamp, np.asarray(odom, dtype=float), self._pose.copy(), pts, mpts)
        self.keyframes.append(kf)
        self._kf_inv = inverse(kf.frontend)
        self.scan_kf.append(k)
        self.scan_rel.append(np.zeros(3))
        self.scan_stamps.append(rec.stamp)
        if cfg.final_refine:
            self.scan_points.append(mpts)
        self.stats["keyframes"] += 1
        if k == 0:
            self._add_factor(gtsam.PriorFactorPose2(0, gtsam.Pose2(0.0, 0.0, 0.0),
                                                    gtsam.noiseModel.Diagonal.Sigmas(np.array([1e-3, 1e-3, 1e-4]))))
            self._new_v.insert(0, gtsam.Pose2(0.0, 0.0, 0.0))
        else:
            prev = self.keyframes[k - 1]
            do = between(prev.odom, kf.odom)
            sxy = cfg.odom_sigma_xy[0] + cfg.odom_sigma_xy[1] * float(np.hypot(do[0], do[1]))
            syaw = cfg.odom_sigma_yaw[0] + cfg.odom_sigma_yaw[1] * abs(float(do[2]))
            self._add_factor(gtsam.BetweenFactorPose2(
                k - 1, k, gtsam.Pose2(*do), self._noise(np.diag([sxy**2, sxy**2, syaw**2]), "huber", 1.345)))
            if info is not None:
                dm = between(prev.frontend, kf.frontend)
                cov = match_covariance(info, cfg.match_sigma_m) * cfg.match_cov_inflation
                cov_local = rotate_covariance(cov, -float(kf.frontend[2]))
                self._add_factor(gtsam.BetweenFactorPose2(
                    k - 1, k, gtsam.Pose2(*dm), self._noise(cov_local, "huber", 1.345)))
            guess = compose(self._est[k - 1], between(prev.frontend, kf.frontend))
            self._new_v.insert(k, gtsam.Pose2(*guess))
            if k % cfg.loop_every_kf == 0 and k - self._last_loop_kf > cfg.loop_rest_kf:
                self._close_loops(k, guess)
        n_loops = self.stats["loops"]
        self._update(full=(k + 1) % cfg.loop_every_kf == 0 or self.stats["loops"] != self._loops_seen or k < 2)
        self._loops_seen = n_loops
        self._insert_submaps(kf)

    def _update(self, full: bool = True) -> None:
        """Update iSAM2; ``full`` re-reads every pose, else only the newest is appended (the older
        ones change little until the next loop-closure search reads them all)."""
        self._isam.update(self._new_f, self._new_v)
        self._new_f = gtsam.NonlinearFactorGraph()
        self._new_v = gtsam.Values()
        k = len(self.keyframes) - 1
        if full or len(self._est) != k:
            est = self._isam.calculateEstimate()
            self._est = np.asarray(gtsam.utilities.extractPose2(est), dtype=float).reshape(-1, 3)
        else:
            p = self._isam.calculateEstimatePose2(k)
            self._est = np.vstack([self._est, [[p.x(), p.y(), p.theta()]]])

    # ------------------------------------------------------------ loops
    def _submap_around(self, j: int, k: int) -> tuple[DistanceGrid, DistanceGrid]:
        """Grid of keyframes j-N..j+N in the frame of keyframe j, and its 4x coarser minimum
        (cached for a few keyframes, within a memory budget)."""
        hit = self._loop_grids.get(j)
        if hit is not None and k - hit[0] <= self.cfg.loop_grid_cache_kf:
            return hit[1], hit[2]
        h = self.cfg.loop_submap_half
        lo, hi = max(0, j - h), min(len(self._est), j + h + 1)
        pj = self._est[j]
        pts = np.concatenate([transform_points(between(pj, self._est[i]), self.keyframes[i].points)
                              for i in range(lo, hi)])
        res = self.cfg.loop_resolution_m
        grid = build_distance_grid(pts, res, self.cfg.loop_dmax_m, 0.5)
        coarse = coarsen_grid(grid, max(int(round(0.1 / res)), 1))
        self._loop_grids = {a: b for a, b in self._loop_grids.items() if k - b[0] <= self.cfg.loop_grid_cache_kf}
        budget = self.cfg.loop_grid_cache_mb * 1e6 - grid.dist.nbytes - coarse.dist.nbytes
        for a in sorted(self._loop_grids, key=lambda a: self._loop_grids[a][0]):  # oldest first
            if sum(g.dist.nbytes + c.dist.nbytes for _, g, c in self._loop_grids.values()) <= budget:
                break
            del self._loop_grids[a]
        self._loop_grids[j] = (k, grid, coarse)
        return grid, coarse

    def _close_loops(self, k: int, guess: FloatArray) -> None:
        cfg = self.cfg
        ncand = k - cfg.loop_min_gap_kf
        if ncand <= 0:
            return
        est = self._est[:ncand]
        d = np.hypot(est[:, 0] - guess[0], est[:, 1] - guess[1])
        order = np.argsort(d)
        chosen: list[int] = []
        for j in order:
            if d[j] > cfg.loop_radius_m or len(chosen) >= cfg.loop_max_candidates:
                break
            ja = int(j) - int(j) % cfg.loop_anchor_step
            if all(abs(ja - c) > cfg.loop_submap_half for c in chosen):
                chosen.append(ja)
        mpts = self.keyframes[k].match_points
        if len(mpts) < 30:
            return
        for j in chosen:
            self.stats["loop_tries"] += 1
            grid, coarse = self._submap_around(j, k)
            pred = between(self._est[j], guess)
            coarse_pts = mpts if len(mpts) <= 70 else mpts[:: int(np.ceil(len(mpts) / 70))]
            sr = correlative_search(coarse, coarse_pts, pred, cfg.loop_window_m, np.radians(cfg.loop_window_deg),
                                    0.12, np.radians(2.0), 0.15, far_m=0.6, far_rad=np.radians(10))
            fr = correlative_search(grid, mpts, sr.pose, 0.1, np.radians(2.0), 0.025, np.radians(0.5), 0.05)
            rr = refine(grid, mpts, fr.pose, cfg.huber_m)
            ok = (fr.score >= cfg.loop_min_score and rr.inlier_frac >= cfg.loop_min_inliers
                  and np.hypot(*(rr.pose[:2] - fr.pose[:2])) < 0.2)
            free_axis = None
            if ok and sr.ambiguity > cfg.loop_max_ambiguity:
                # ambiguous: accept only a corridor (the rival peaks on one line through the best,
                # heading and position across the line unambiguous); the factor then leaves the
                # position along the line free
                free_axis = sr.ambiguous_axis(cfg.loop_max_ambiguity, 0.3, np.radians(5.0))
                ok = free_axis is not None
            if not ok:
                self.stats["loop_rejected"] += 1
                continue
            cov = match_covariance(rr.info, cfg.match_sigma_m) * cfg.match_cov_inflation
            if free_axis is not None:
                self.stats["loops_corridor"] += 1
                cov[:2, :2] += cfg.loop_window_m**2 * np.outer(free_axis, free_axis)
            cov_local = rotate_covariance(cov, -float(rr.pose[2]))
            self._add_factor(gtsam.BetweenFactorPose2(
                j, k, gtsam.Pose2(*rr.pose), self._noise(cov_local, "cauchy", cfg.loop_cauchy_k)))
            self.loops.append(LoopClosure(j, k, rr.pose.copy(), fr.score, rr.inlier_frac))
            self.stats["loops"] += 1
            innov = between(pred, rr.pose)
            if np.hypot(innov[0], innov[1]) < 0.1 and abs(innov[2]) < np.radians(1.0):
                self._last_loop_kf = k  # the graph already agreed: this place is tied in, rest a while

    # ------------------------------------------------------------ results
    def _refine_scans(self, poses: FloatArray, kf_idx: np.ndarray, scan_poses: FloatArray) -> FloatArray:
        """Align each scan to a map of the optimized keyframes around its own (itself excluded)."""
        cfg = self.cfg
        out = scan_poses.copy()
        order = np.argsort(kf_idx, kind="stable")
        bounds = np.searchsorted(kf_idx[order], np.arange(len(self.keyframes) + 1))
        h = cfg.refine_half
        n_ok = 0
        for k in range(len(self.keyframes)):
            members = order[bounds[k]:bounds[k + 1]]
            if len(members) == 0:
                continue
            nb = [i for i in range(max(0, k - h), min(len(self.keyframes), k + h + 1)) if i != k]
            pts = np.concatenate([transform_points(poses[i], self.keyframes[i].points) for i in nb])
            grid = build_distance_grid(pts, cfg.submap_resolution, cfg.dmax_m, 0.5)
            for m in members:
                mp = self.scan_points[m]
                if len(mp) < 20:
                    continue
                rr = refine(grid, mp, scan_poses[m], cfg.huber_m)
                d = between(scan_poses[m], rr.pose)
                if rr.inlier_frac >= 0.7 and np.hypot(d[0], d[1]) < 0.1 and abs(d[2]) < np.radians(3):
                    out[m] = rr.pose
                    n_ok += 1
        self.stats["refined"] = n_ok
        return out

    def finish(self) -> SlamResult:
        if not self.keyframes:
            raise ValueError("no scans were added")
        poses = self._est.copy()
        if self.cfg.final_batch and len(self.keyframes) > 1:
            init = gtsam.Values()
            for i, p in enumerate(poses):
                init.insert(i, gtsam.Pose2(*p))
            params = gtsam.LevenbergMarquardtParams()
            params.setMaxIterations(50)
            res = gtsam.LevenbergMarquardtOptimizer(self._graph, init, params).optimize()
            poses = np.array([[res.atPose2(i).x(), res.atPose2(i).y(), res.atPose2(i).theta()]
                              for i in range(len(poses))])
        kf_idx = np.asarray(self.scan_kf)
        rel = np.asarray(self.scan_rel).reshape(-1, 3)
        scan_poses = compose(poses[kf_idx], rel)
        if self.cfg.final_refine and len(self.keyframes) > 2:
            scan_poses = self._refine_scans(poses, kf_idx, scan_poses)
        scan_traj = Trajectory.from_unsorted(np.asarray(self.scan_stamps), scan_poses)
        kf_traj = Trajectory.from_unsorted(np.array([kf.stamp for kf in self.keyframes]), poses)
        return SlamResult(self.keyframes, poses, scan_traj, kf_traj, self.loops, dict(self.stats), self.warnings())

    def warnings(self) -> list[str]:
        """What the map may lack, one line each (empty for a healthy run)."""
        st = self.stats
        read = st["scans"] - st["stationary"]  # scans looked at (standing still, they are not read)
        n = max(read, 1)
        t0 = self.scan_stamps[0] if self.scan_stamps else 0.0
        guess = "a constant-velocity guess" if self.scans_only else "the odometry"
        out = []
        if self.scans_only:
            out.append("no odometry in the log: the scans were matched to each other alone (a scan that does not "
                       "fit the local map is placed by a constant-velocity guess)")
        if read > 0 and st["empty_scans"] == read:
            out.append("no scan has a return within range (every beam at max range or invalid): the map has "
                       f"no walls, only the free space the beams carve, and the trajectory is {guess}")
        elif st["empty_scans"] > 0.2 * n:
            out.append(f"{100 * st['empty_scans'] / n:.0f} % of the scans have no return within range: "
                       f"the trajectory follows {guess} there")
        if st["scans"] < 50 or st["keyframes"] < 5:
            out.append(f"only {st['scans']} scans ({st['keyframes']} keyframes): too short a log for loop closures "
                       "or a self-check")
        matched = read - st["empty_scans"] - (1 if st["scans"] else 0)
        if st["empty_scans"] < read and matched > 0 and st["track_fail"] - st["empty_scans"] > 0.2 * matched:
            out.append(f"{100 * (st['track_fail'] - st['empty_scans']) / matched:.0f} % of the scans did not fit "
                       f"the local map: the trajectory follows {guess} there")
        if self.jumps:
            big = max(self.jumps, key=lambda j: j[1])
            out.append(f"the odometry jumped {len(self.jumps)} time(s) (largest {big[1]:.1f} m at "
                       f"t={big[0] - t0:.1f} s after the first scan): ignored, the scan matching bridged the step")
        if not self.loops and st["keyframes"] > self.cfg.loop_min_gap_kf:
            out.append("no loop closure: no place was recognised on a second pass, so drift along the path is not "
                       "corrected")
        return out


def run_slam(records: Sequence[ScanRecord], mount: StaticTransform, config: MapperConfig | None = None,
             progress: Callable[[int], None] | None = None) -> SlamResult:
    """Run :class:`GraphSlam` over ``records``; ``progress(n)`` is called after each scan.  Records
    without any odometry pose (a log with scans only) are mapped from the scans alone."""
    from fgloc.mapping.source import scans_only

    slam = GraphSlam(mount, config, scans_only=scans_only(records))
    for rec in records:
        slam.add(rec)
        if progress is not None:
            progress(1)
    return slam.finish()


def build_occupancy(result: SlamResult, records: Sequence[ScanRecord], mount: StaticTransform,
                    config: MapperConfig | None = None) -> OccupancyMap:
    """Ray-traced log-odds map from the keyframe scans at their optimized poses."""
    cfg = config or MapperConfig()
    mnt = np.asarray(mount.pose, dtype=float)
    by_index = {r.index: r for r in records}
    beams = []
    for kf, pose in zip(result.keyframes, result.keyframe_poses, strict=True):
        sc = by_index[kf.scan_index].scan
        ends, hit, missing = scan_beams(sc.ranges, sc.angles, sc.range_min, sc.range_max,
                                        cfg.max_range_m, cfg.carve_range_m)
        lp = compose(pose, mnt)
        beams.append((lp[:2], transform_points(lp, ends), hit, missing))
    hits = np.concatenate([e[h] for _, e, h, _ in beams] + [result.keyframe_poses[:, :2]])
    lo = hits.min(axis=0) - 1.0
    hi = hits.max(axis=0) + 1.0
    grid = LogOddsGrid(lo[0], lo[1], hi[0], hi[1], cfg.resolution)
    for org, ends, hit, missing in beams:
        grid.add_beams(org, ends, hit, missing)  # no-return beams stop at the walls the returns saw
    return grid.to_map()

