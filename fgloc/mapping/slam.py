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
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import gtsam
import numpy as np

from fgloc.geometry import between, compose, rotate_covariance, transform_points
from fgloc.mapping.occupancy import LogOddsGrid, scan_endpoints
from fgloc.mapping.scanmatch import (
    DistanceGrid,
    build_distance_grid,
    correlative_search,
    match_covariance,
    refine,
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
    carve_range_m: float = 8.0        # no-return beams carve free space up to here
    match_voxel_m: float = 0.0        # scan point subsampling for matching (0: every return)
    submap_keyframes: int = 25        # local submap = last N keyframes
    submap_resolution: float = 0.025  # distance-field cell size for matching
    dmax_m: float = 0.3               # distance field clip
    huber_m: float = 0.02             # Gauss-Newton robust kernel width
    match_sigma_m: float = 0.05       # per-point noise for match covariances
    match_cov_inflation: float = 4.0  # points are correlated: inflate Hessian covariance
    track_min_inliers: float = 0.5    # below: tracking falls back to odometry
    kf_search_m: float = 0.15         # keyframe correlative window
    kf_search_deg: float = 6.0
    odom_sigma_xy: tuple[float, float] = (0.05, 0.2)     # sigma = a + b * distance (loose: real odometry is biased)
    odom_sigma_yaw: tuple[float, float] = (0.05, 0.5)    # sigma = a + b * |dyaw|
    loop_radius_m: float = 5.0        # candidates within this distance of the estimate
    loop_min_gap_kf: int = 40         # ... and at least this many keyframes older
    loop_every_kf: int = 3            # try loop closures every N keyframes
    loop_max_candidates: int = 2
    loop_submap_half: int = 12        # candidate submap = keyframes j-N .. j+N
    loop_window_m: float = 1.5        # correlative window around the predicted relative pose
    loop_window_deg: float = 20.0
    loop_min_score: float = 0.45      # fine Gaussian score to accept
    loop_min_inliers: float = 0.6     # fraction of points within 0.1 m after refinement
    loop_max_ambiguity: float = 0.92  # second-best distinct peak / best
    loop_cauchy_k: float = 1.0
    loop_dmax_m: float = 0.35         # distance-field clip of loop submaps
    loop_anchor_step: int = 4         # loop submaps are anchored at every N-th keyframe (cache reuse)
    loop_grid_cache_kf: int = 20      # reuse a loop submap grid for this many keyframes
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


def _voxel_subsample(pts: FloatArray, voxel: float) -> FloatArray:
    if len(pts) == 0 or voxel <= 0:
        return pts
    keys = np.floor(pts / voxel).astype(np.int64)
    _, idx = np.unique(keys[:, 0] * 1_000_003 + keys[:, 1], return_index=True)
    return pts[np.sort(idx)]


class GraphSlam:
    """Incremental pose-graph SLAM; feed :class:`ScanRecord` in order, then :meth:`finish`."""

    def __init__(self, mount: StaticTransform, config: MapperConfig | None = None):
        self.cfg = config or MapperConfig()
        self.mount = np.asarray(mount.pose, dtype=float)
        self.keyframes: list[Keyframe] = []
        self.loops: list[LoopClosure] = []
        self.scan_kf: list[int] = []             # keyframe each scan is attached to
        self.scan_rel: list[FloatArray] = []      # offset from that keyframe (frontend)
        self.scan_stamps: list[float] = []
        self.scan_points: list[FloatArray] = []   # match points of every scan (base frame)
        self._pose: FloatArray | None = None      # current tracked pose
        self._odom_prev: FloatArray | None = None
        self._grid: DistanceGrid | None = None
        self._isam = gtsam.ISAM2(gtsam.ISAM2Params())
        self._graph = gtsam.NonlinearFactorGraph()   # all factors (for the final batch)
        self._new_f = gtsam.NonlinearFactorGraph()
        self._new_v = gtsam.Values()
        self._est: FloatArray = np.zeros((0, 3))
        self._loop_grids: dict[int, tuple[int, DistanceGrid]] = {}
        self.stats = {"scans": 0, "tracked": 0, "track_fail": 0, "stationary": 0, "keyframes": 0,
                      "loop_tries": 0, "loops": 0, "loop_rejected": 0}

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

    def _rebuild_submap(self) -> None:
        kfs = self.keyframes[-self.cfg.submap_keyframes:]
        pts = np.concatenate([transform_points(kf.frontend, kf.points) for kf in kfs])
        self._grid = build_distance_grid(pts, self.cfg.submap_resolution, self.cfg.dmax_m, 0.5)

    # ------------------------------------------------------------ main step
    def add(self, rec: ScanRecord) -> None:
        cfg = self.cfg
        self.stats["scans"] += 1
        odom = np.asarray(rec.odom, dtype=float)
        pts = self._scan_points(rec)
        mpts = _voxel_subsample(pts, cfg.match_voxel_m)
        if self._pose is None or self._odom_prev is None:
            self._pose = np.zeros(3)
            self._odom_prev = odom
            self._new_keyframe(rec, pts, mpts, None)
            return
        d_odom = between(self._odom_prev, odom)
        self._odom_prev = odom
        pred = compose(self._pose, d_odom)
        last_kf = self.keyframes[-1]
        rel_pred = between(last_kf.frontend, pred)
        is_kf = (np.hypot(rel_pred[0], rel_pred[1]) >= cfg.kf_dist_m
                 or abs(rel_pred[2]) >= np.radians(cfg.kf_angle_deg))
        stationary = np.hypot(d_odom[0], d_odom[1]) < 1e-4 and abs(d_odom[2]) < 1e-5
        info = None
        assert self._grid is not None
        if stationary and not is_kf:
            pose = pred
            self.stats["stationary"] += 1
        elif len(mpts) < 10:
            pose = pred
            self.stats["track_fail"] += 1
        else:
            guess = pred
            if is_kf:
                sr = correlative_search(self._grid, mpts, pred, cfg.kf_search_m, np.radians(cfg.kf_search_deg),
                                        0.03, np.radians(1.0), 0.05)
                guess = sr.pose
            rr = refine(self._grid, mpts, guess, cfg.huber_m)
            if rr.inlier_frac >= cfg.track_min_inliers and np.hypot(*(rr.pose[:2] - pred[:2])) < 0.5:
                pose = rr.pose
                info = rr.info
                self.stats["tracked"] += 1
            else:
                pose = pred
                self.stats["track_fail"] += 1
        self._pose = pose
        rel = between(last_kf.frontend, pose)
        if np.hypot(rel[0], rel[1]) >= cfg.kf_dist_m or abs(rel[2]) >= np.radians(cfg.kf_angle_deg):
            self._new_keyframe(rec, pts, mpts, info)
        else:
            self.scan_kf.append(len(self.keyframes) - 1)
            self.scan_rel.append(rel)
            self.scan_stamps.append(rec.stamp)
            self.scan_points.append(mpts)

    def _new_keyframe(self, rec: ScanRecord, pts: FloatArray, mpts: FloatArray, info: FloatArray | None) -> None:
        cfg = self.cfg
        assert self._pose is not None
        k = len(self.keyframes)
        kf = Keyframe(rec.index, rec.stamp, np.asarray(rec.odom, dtype=float), self._pose.copy(), pts, mpts)
        self.keyframes.append(kf)
        self.scan_kf.append(k)
        self.scan_rel.append(np.zeros(3))
        self.scan_stamps.append(rec.stamp)
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
            if k % cfg.loop_every_kf == 0:
                self._close_loops(k, guess)
        self._update()
        self._rebuild_submap()

    def _update(self) -> None:
        self._isam.update(self._new_f, self._new_v)
        self._new_f = gtsam.NonlinearFactorGraph()
        self._new_v = gtsam.Values()
        est = self._isam.calculateEstimate()
        self._est = np.asarray(gtsam.utilities.extractPose2(est), dtype=float).reshape(-1, 3)

    # ------------------------------------------------------------ loops
    def _submap_around(self, j: int, k: int) -> DistanceGrid:
        """Grid of keyframes j-N..j+N in the frame of keyframe j (cached for a few keyframes)."""
        hit = self._loop_grids.get(j)
        if hit is not None and k - hit[0] <= self.cfg.loop_grid_cache_kf:
            return hit[1]
        h = self.cfg.loop_submap_half
        lo, hi = max(0, j - h), min(len(self._est), j + h + 1)
        pj = self._est[j]
        pts = np.concatenate([transform_points(between(pj, self._est[i]), self.keyframes[i].points)
                              for i in range(lo, hi)])
        grid = build_distance_grid(pts, self.cfg.submap_resolution, self.cfg.loop_dmax_m, 0.5)
        if len(self._loop_grids) > 64:
            self._loop_grids = {a: b for a, b in self._loop_grids.items() if k - b[0] <= self.cfg.loop_grid_cache_kf}
        self._loop_grids[j] = (k, grid)
        return grid

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
            grid = self._submap_around(j, k)
            pred = between(self._est[j], guess)
            coarse_pts = mpts if len(mpts) <= 70 else mpts[:: int(np.ceil(len(mpts) / 70))]
            sr = correlative_search(grid, coarse_pts, pred, cfg.loop_window_m, np.radians(cfg.loop_window_deg),
                                    0.12, np.radians(2.0), 0.15, far_m=0.6, far_rad=np.radians(10))
            fr = correlative_search(grid, mpts, sr.pose, 0.1, np.radians(2.0), 0.025, np.radians(0.5), 0.05)
            rr = refine(grid, mpts, fr.pose, cfg.huber_m)
            ok = (fr.score >= cfg.loop_min_score and rr.inlier_frac >= cfg.loop_min_inliers
                  and sr.ambiguity <= cfg.loop_max_ambiguity
                  and np.hypot(*(rr.pose[:2] - fr.pose[:2])) < 0.2)
            if not ok:
                self.stats["loop_rejected"] += 1
                continue
            cov = match_covariance(rr.info, cfg.match_sigma_m) * cfg.match_cov_inflation
            cov_local = rotate_covariance(cov, -float(rr.pose[2]))
            self._add_factor(gtsam.BetweenFactorPose2(
                j, k, gtsam.Pose2(*rr.pose), self._noise(cov_local, "cauchy", cfg.loop_cauchy_k)))
            self.loops.append(LoopClosure(j, k, rr.pose.copy(), fr.score, rr.inlier_frac))
            self.stats["loops"] += 1

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
        return SlamResult(self.keyframes, poses, scan_traj, kf_traj, self.loops, dict(self.stats))


def run_slam(records: Sequence[ScanRecord], mount: StaticTransform, config: MapperConfig | None = None,
             progress: Callable[[int], None] | None = None) -> SlamResult:
    """Run :class:`GraphSlam` over ``records``; ``progress(n)`` is called after each scan."""
    slam = GraphSlam(mount, config)
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
        ends, hit = scan_endpoints(sc.ranges, sc.angles, sc.range_min, sc.range_max,
                                   cfg.max_range_m, cfg.carve_range_m)
        lp = compose(pose, mnt)
        beams.append((lp[:2], transform_points(lp, ends), hit))
    hits = np.concatenate([e[h] for _, e, h in beams] + [result.keyframe_poses[:, :2]])
    lo = hits.min(axis=0) - 1.0
    hi = hits.max(axis=0) + 1.0
    grid = LogOddsGrid(lo[0], lo[1], hi[0], hi[1], cfg.resolution)
    for org, ends, hit in beams:
        grid.add_beams(org, ends, hit)
    return grid.to_map()

