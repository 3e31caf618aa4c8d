"""Map self-check: do the passes through a place agree, and does the world still match the map?

Two checks on scans with poses (core maths: no I/O, no printing).

*Consistency* (:func:`check_consistency`, a mapping log and its trajectory): the map is cut
into square regions; within a region the scans fall into *passes* (runs of the trajectory
more than ``pass_sep_m`` of path apart).  Each test scan of a pass is re-matched against a
distance field built only from the scans of the *other* passes near the region, starting at
its own pose.  A scan is *inconsistent* when a pose at least ``offset_m`` / ``offset_deg``
away fits the other passes clearly better (``min_gain`` more of its points within
``inlier_m``); a corridor that lets the match slide along it gains nothing and stays
consistent.  A region is flagged when enough of its checked scans are inconsistent.

*World vs map* (:func:`check_against_map`, a localization log with its trajectory and the
map it ran on): each test scan is re-matched against the map's occupied cells the same way
(does the pose agree with the map?), and every beam is compared with the range the map
predicts: returns well short of it on free space are *added* structure (objects not in the
map), returns well beyond a mapped obstacle are *removed* structure (walls, doors or
furniture that are gone).  Changes seen by several scans are clustered into change regions.

Both return a :class:`CheckResult` with per-region scores, the suspect passes and loop
closures, and a one-line verdict.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from fgloc.geometry import between, compose, transform_points, wrap_angle
from fgloc.mapping.occupancy import scan_endpoints
from fgloc.mapping.scanmatch import (
    DistanceGrid,
    build_distance_grid,
    coarsen_grid,
    correlative_search,
    point_distances,
    refine,
    voxel_subsample,
)
from fgloc.mapping.source import ScanRecord
from fgloc.maps import OccupancyMap
from fgloc.types import FloatArray, Trajectory

# status of a test scan
OK, BAD, NO_OVERLAP = "consistent", "inconsistent", "no-overlap"


@dataclass
class CheckConfig:
    """Self-check parameters (metres, degrees); the same for every log."""

    region_m: float = 5.0          # square regions of this size
    pass_sep_m: float = 10.0       # scans this far apart along the path are different passes
    source_step_m: float = 0.3     # other-pass map: a scan every this much travel ...
    source_step_deg: float = 10.0  # ... or rotation
    test_step_m: float = 0.5       # test scans every this much travel ...
    test_step_deg: float = 15.0    # ... or rotation
    gather_m: float = 6.0          # other-pass scans taken up to this far from the region
    points_range_m: float = 10.0   # scan returns used (m from the laser)
    voxel_m: float = 0.05          # point subsampling
    resolution: float = 0.05       # distance-field cell
    dmax_m: float = 0.3            # distance-field clip: a point within it "sees" the other passes
    window_m: float = 0.8          # re-match search window around the scan's own pose
    window_deg: float = 5.0
    wide_m: float = 3.0            # ... and (on 0.2 m cells) this far: a pass mapped metres off
    wide_deg: float = 10.0
    wide_max_ambiguity: float = 0.9  # ... where that search has one clear peak
    inlier_m: float = 0.08         # a point fits when this close to the other passes
    min_overlap: float = 0.3       # a scan is checked when this fraction of its points sees them
    good_fit: float = 0.85         # fit / overlap at the own pose above which no search is needed
    offset_m: float = 0.15         # a better pose this far away (3 cells of a 5 cm map) ...
    offset_deg: float = 1.5        # ... or turned ...
    min_constraint: float = 0.15   # (shifts count along directions the scene constrains at least this
                                   # fraction as well as its best-constrained one)
    min_gain: float = 0.12         # ... that fits this much more of the points makes a scan inconsistent,
    min_fit: float = 0.4           # when at least this fraction of its points fits there ...
    min_fit_overlap: float = 0.75  # ... and this fraction of those that see the other passes
    region_min_checked: int = 3    # a region is judged from at least this many checked scans
    region_bad_frac: float = 0.3   # ... and flagged when this fraction of them is inconsistent
    max_sources: int = 80          # other-pass scans per distance field (nearest to the region)
    min_sources: int = 8           # fewer other-pass scans than this: too little to judge by
    max_tests_per_pass: int = 12   # test scans per pass and region (spread along the pass)
    # world vs map
    change_m: float = 0.3          # a return this much short of / beyond the map's range is a change
    change_seen_m: float = 0.25    # map structure within this of a return of the same scan is not "removed"
    change_cell_m: float = 0.2     # changes are counted in cells of this size ...
    change_min_obs: int = 3        # ... seen this many times ...
    change_min_scans: int = 2      # ... by this many test scans
    change_min_cells: int = 3      # a change region has at least this many such cells
    change_persistence: float = 0.4  # ... and its cells show the change in this share of the test scans that
                                     # looked there (a person walking by is in a few of them, a moved cabinet in all)
    change_fine_m: float = 0.05    # a region's extent: its returns' distinct cells of this size, x the size
    change_lateral_m: float = 0.1  # how far a mapped surface may lie off its rasterized cells (at least two map
                                   # cells): a beam grazing it at angle a passes the cells by up to this / sin(a)
                                   # before it meets the surface, which is no removed structure
    change_significant_share: float = 0.04  # a change fails the check when its returns are this share of all
                                            # returns of the scans that showed it (smaller ones are listed as
                                            # minor: on five real logs checked against good maps the largest was
                                            # 0.031 but one; the simulated cabinet and table 0.054-0.077)


@dataclass
class ScanCheck:
    stamp: float
    pose: FloatArray        # the scan's own pose (map frame)
    region: tuple[int, int]
    pass_id: int            # index of its pass within the region (consistency check)
    status: str             # consistent / inconsistent / no-overlap
    offset: FloatArray      # best re-matched pose in the frame of the own pose [dx, dy, dyaw]
    fit_own: float          # fraction of points within inlier_m at the own pose
    fit_best: float         # ... at the best re-matched pose
    overlap: float          # fraction of points within dmax_m of the other passes / map
    path_m: float = 0.0     # distance travelled along the trajectory up to this scan


@dataclass
class PassInfo:
    t0: float
    t1: float
    n_checked: int
    n_bad: int


@dataclass
class RegionCheck:
    key: tuple[int, int]
    center: FloatArray
    size_m: float
    n_tests: int
    n_checked: int
    n_bad: int
    score: float            # fraction of checked scans that are consistent (nan: none checked)
    flagged: bool
    passes: list[PassInfo] = field(default_factory=list)
    offset_m: float = 0.0   # median offset of the inconsistent scans
    offset_deg: float = 0.0


@dataclass
class ChangeRegion:
    kind: str               # "added" (objects not in the map) or "removed" (map structure not seen)
    center: FloatArray
    bbox: FloatArray        # [xmin, ymin, xmax, ymax]
    cells: int
    observations: int
    extent_m: float = 0.0   # how much structure changed: distinct change_fine_m cells of its returns x their size
    share: float = 0.0      # its returns / all returns of the test scans that showed it
    major: bool = True      # its share reaches CheckConfig.change_significant_share (else listed as minor)


@dataclass
class LoopInfo:
    """A loop closure of the mapping run: keyframe stamps and positions (map frame)."""

    t_old: float
    t_new: float
    xy_old: FloatArray
    xy_new: FloatArray


@dataclass
class CheckResult:
    mode: str                           # "consistency" or "localization"
    scans: list[ScanCheck]
    regions: list[RegionCheck]
    suspects: list[str]
    verdict: str
    passed: bool
    t_first: float = 0.0                # stamp of the log's first scan (times in texts are relative)
    changes: list[ChangeRegion] = field(default_factory=list)
    culprits: list[tuple[float, float]] = field(default_factory=list)  # (t0, t1) stamps of passes found off
    added_xy: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))
    removed_xy: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))
    stats: dict = field(default_factory=dict)
    # how well the passes register where they agree (consistency check): the r.m.s. offset, per
    # constrained axis, of the consistent scans refined against the other passes from their own
    # pose, and of their heading; nan when no scan was checked
    registration_m: float = float("nan")
    registration_deg: float = float("nan")
    registration_n: int = 0

    @property
    def flagged(self) -> list[RegionCheck]:
        return [r for r in self.regions if r.flagged]


# ---------------------------------------------------------------------------- helpers
def scan_poses(records: Sequence[ScanRecord], trajectory: Trajectory, max_gap_s: float = 0.5
               ) -> tuple[np.ndarray, FloatArray]:
    """Indices of the scans inside the trajectory's time span and their poses (interpolated)."""
    if len(trajectory) == 0 or not records:
        return np.zeros(0, dtype=np.int64), np.zeros((0, 3))
    st = np.array([r.stamp for r in records])
    ok = (st >= trajectory.stamps[0] - 0.05) & (st <= trajectory.stamps[-1] + 0.05)
    if len(trajectory) > 1:  # no pose across a hole in the trajectory
        j = np.clip(np.searchsorted(trajectory.stamps, st), 1, len(trajectory) - 1)
        gap = trajectory.stamps[j] - trajectory.stamps[j - 1]
        near = np.minimum(np.abs(st - trajectory.stamps[j]), np.abs(st - trajectory.stamps[j - 1]))
        ok &= (gap <= max_gap_s) | (near <= 0.05)
    idx = np.nonzero(ok)[0]
    return idx, trajectory.interpolate(st[idx]) if len(idx) else np.zeros((0, 3))


def _scan_points(rec: ScanRecord, mount: FloatArray, cfg: CheckConfig) -> FloatArray:
    """Hit points (base frame) within ``points_range_m`` of the laser, voxel-subsampled."""
    sc = rec.scan
    ends, hit = scan_endpoints(sc.ranges, sc.angles, sc.range_min, sc.range_max, cfg.points_range_m, cfg.points_range_m)
    return voxel_subsample(transform_points(mount, ends[hit]), cfg.voxel_m)


def _pick_by_travel(poses: FloatArray, step_m: float, step_deg: float) -> np.ndarray:
    """Indices of poses at least ``step_m`` of travel or ``step_deg`` of turn after the previous pick."""
    if len(poses) == 0:
        return np.zeros(0, dtype=np.int64)
    out = [0]
    last = poses[0]
    dist = 0.0
    for i in range(1, len(poses)):
        dist += float(np.hypot(*(poses[i, :2] - poses[i - 1, :2])))
        if dist >= step_m or abs(float(wrap_angle(poses[i, 2] - last[2]))) >= np.radians(step_deg):
            out.append(i)
            last = poses[i]
            dist = 0.0
    return np.asarray(out, dtype=np.int64)


def _arclength(poses: FloatArray) -> FloatArray:
    if len(poses) == 0:
        return np.zeros(0)
    return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(poses[:, :2], axis=0).T))])


def _rematch(grid: DistanceGrid, pts: FloatArray, pose0: FloatArray, cfg: CheckConfig,
             coarse_cache: list | None = None) -> tuple[str, FloatArray, float, float, float]:
    """Status, offset (own-pose frame), fit at the own pose, fit at the best pose, overlap.

    Searched within ``window_m`` of the own pose, and around the clear peak (if there is one) of a
    coarse search within ``wide_m``: a pass put metres off (a wrong loop closure, or a corridor's
    walls matched one corridor-width over) can still overlap the other passes where it was put.
    ``coarse_cache`` (a list the caller keeps) holds the coarse copy of the last grid."""
    n = max(len(pts), 1)
    d0 = point_distances(grid, pts, pose0)
    ov0 = float(np.sum(d0 < cfg.dmax_m * 0.999)) / n
    fit0 = float(np.sum(d0 < cfg.inlier_m)) / n
    if ov0 >= cfg.min_overlap and fit0 >= cfg.good_fit * ov0:
        return OK, np.zeros(3), fit0, fit0, ov0
    coarse = pts if len(pts) <= 120 else pts[:: int(np.ceil(len(pts) / 120))]

    def search(start: FloatArray, win_m: float, win_deg: float) -> tuple[FloatArray, float, float]:
        sr = correlative_search(grid, coarse, start, win_m, np.radians(win_deg), 0.05, np.radians(1.0), 0.08)
        rr = refine(grid, pts, sr.pose, 0.03)
        cand = rr.pose if np.hypot(*(rr.pose[:2] - sr.pose[:2])) < 0.2 else sr.pose
        d1 = point_distances(grid, pts, cand)
        return cand, float(np.sum(d1 < cfg.inlier_m)) / n, float(np.sum(d1 < cfg.dmax_m * 0.999)) / n

    best, fit1, ov1 = search(pose0, cfg.window_m, cfg.window_deg)
    if cfg.wide_m > cfg.window_m and not (ov1 >= cfg.min_overlap and fit1 >= cfg.good_fit * ov1):
        # nothing near the own pose fits well: is there a clear fit farther away?
        if coarse_cache is not None and coarse_cache and coarse_cache[0] is grid:
            cgrid = coarse_cache[1]
        else:
            cgrid = coarsen_grid(grid, max(int(round(0.2 / grid.resolution)), 1))
            if coarse_cache is not None:
                coarse_cache[:] = [grid, cgrid]
        few = coarse if len(coarse) <= 40 else coarse[:: int(np.ceil(len(coarse) / 40))]
        sw = correlative_search(cgrid, few, pose0, cfg.wide_m, np.radians(cfg.wide_deg), cgrid.resolution,
                                np.radians(2.5), 0.15, far_m=1.0, far_rad=np.radians(6.0))
        if sw.score > 0 and sw.ambiguity <= cfg.wide_max_ambiguity and np.hypot(*(sw.pose[:2] - pose0[:2])) > 0.5:
            cand, f, o = search(sw.pose, 0.3, 3.0)  # the wide peak is known to 0.2 m / 2.5 deg
            if f > fit1:
                best, fit1, ov1 = cand, f, o
    if fit1 < fit0:  # the search found nothing better: the own pose stands
        best, fit1, ov1 = pose0, fit0, ov0
    off = between(pose0, best)
    ov = max(ov0, ov1)
    if ov < cfg.min_overlap:
        return NO_OVERLAP, off, fit0, fit1, ov
    # only the part of the shift the scene constrains counts (a corridor leaves its axis free)
    info = refine(grid, pts, best, 0.03, iters=1).info[:2, :2]
    w, v = np.linalg.eigh(0.5 * (info + info.T))
    d_w = best[:2] - pose0[:2]
    strong = v[:, w >= cfg.min_constraint * max(float(w.max()), 1e-12)]
    shift = float(np.linalg.norm(strong.T @ d_w))
    moved = shift >= cfg.offset_m or abs(off[2]) >= np.radians(cfg.offset_deg)
    if moved and fit1 - fit0 >= cfg.min_gain and fit1 >= cfg.min_fit and fit1 >= cfg.min_fit_overlap * ov1:
        return BAD, off, fit0, fit1, ov
    return OK, off, fit0, fit1, ov


def _region_key(xy: FloatArray, size: float) -> tuple[int, int]:
    return int(np.floor(xy[0] / size)), int(np.floor(xy[1] / size))


def _split_passes(s: FloatArray, sep: float) -> np.ndarray:
    """Pass index of each (sorted) arclength value: a new pass after a gap of more than ``sep``."""
    if len(s) == 0:
        return np.zeros(0, dtype=np.int64)
    return np.concatenate([[0], np.cumsum(np.diff(s) > sep)]).astype(np.int64)


def _spread(idx: np.ndarray, k: int) -> np.ndarray:
    if len(idx) <= k:
        return idx
    return idx[np.round(np.linspace(0, len(idx) - 1, k)).astype(np.int64)]


def _summarize_regions(checks: list[ScanCheck], cfg: CheckConfig) -> list[RegionCheck]:
    by: dict[tuple[int, int], list[ScanCheck]] = {}
    for c in checks:
        by.setdefault(c.region, []).append(c)
    out = []
    for key, cs in sorted(by.items()):
        checked = [c for c in cs if c.status != NO_OVERLAP]
        bad = [c for c in checked if c.status == BAD]
        nck = len(checked)
        score = (1.0 - len(bad) / nck) if nck else float("nan")
        passes = []
        for pid in sorted({c.pass_id for c in cs}):
            pc = [c for c in cs if c.pass_id == pid]
            passes.append(PassInfo(min(c.stamp for c in pc), max(c.stamp for c in pc),
                                   sum(c.status != NO_OVERLAP for c in pc), sum(c.status == BAD for c in pc)))
        # flagged: enough of the region's scans disagree, or most scans of one pass do
        flagged = (nck >= cfg.region_min_checked and len(bad) / max(nck, 1) >= cfg.region_bad_frac) or any(
            p.n_bad >= 2 and p.n_bad >= 0.5 * p.n_checked for p in passes)
        off_m = float(np.median([np.hypot(c.offset[0], c.offset[1]) for c in bad])) if bad else 0.0
        off_deg = float(np.degrees(np.median([abs(c.offset[2]) for c in bad]))) if bad else 0.0
        center = (np.array(key, dtype=float) + 0.5) * cfg.region_m
        out.append(RegionCheck(key, center, cfg.region_m, len(cs), nck, len(bad), score, flagged, passes,
                               off_m, off_deg))
    return out


def _set_total(progress: Callable[[int], None] | None, total: int) -> None:
    """Tell a progress callback that has ``set_total`` (the CLI's bar) how many scans a check tests."""
    set_total = getattr(progress, "set_total", None)
    if callable(set_total):
        set_total(total)


# ---------------------------------------------------------------------------- consistency
def check_consistency(records: Sequence[ScanRecord], mount_pose: FloatArray, trajectory: Trajectory,
                      loops: Sequence[LoopInfo] = (), config: CheckConfig | None = None,
                      progress: Callable[[int], None] | None = None) -> CheckResult:
    """Re-match test scans against the map built from the other passes through their region."""
    from scipy.spatial import cKDTree

    cfg = config or CheckConfig()
    mount = np.asarray(mount_pose, dtype=float)
    idx, poses = scan_poses(records, trajectory)
    t_first = float(records[0].stamp) if records else 0.0
    if len(idx) < 2:
        verdict = "map-check: NOT CHECKED - fewer than 2 scans have a pose"
        return CheckResult("consistency", [], [], [], verdict, True, t_first, stats={"scans": len(idx)})
    s_all = _arclength(poses)
    src = _pick_by_travel(poses, cfg.source_step_m, cfg.source_step_deg)
    tst = _pick_by_travel(poses, cfg.test_step_m, cfg.test_step_deg)
    pts_cache: dict[int, FloatArray] = {}

    def pts_of(k: int) -> FloatArray:  # base-frame points of the k-th posed scan
        p = pts_cache.get(k)
        if p is None:
            p = _scan_points(records[int(idx[k])], mount, cfg)
            pts_cache[k] = p
        return p

    src_xy = poses[src, :2]
    st_all = np.array([records[int(i)].stamp for i in idx])
    coarse_cache: list = []  # [grid, its coarse copy] for the wide searches
    tree = cKDTree(src_xy)
    n_grids = [0]

    def grid_for(center: FloatArray, s_lo: float, s_hi: float, skips: Sequence[tuple[float, float]] = ()
                 ) -> DistanceGrid | None:
        """Distance field of the other passes (path position outside [s_lo, s_hi] and outside
        every span of ``skips``) near ``center``; None when there are none."""
        near = np.asarray(tree.query_ball_point(center, cfg.region_m * 0.71 + cfg.gather_m), dtype=np.int64)
        if len(near) == 0:
            return None
        ss = s_all[src[near]]
        keep = (ss < s_lo) | (ss > s_hi)
        for a, b in skips:
            keep &= (ss < a) | (ss > b)
        cand = near[keep]
        if len(cand) < cfg.min_sources:
            return None
        if len(cand) > cfg.max_sources:
            dc = np.hypot(*(src_xy[cand] - center).T)
            cand = cand[np.argsort(dc, kind="stable")[: cfg.max_sources]]
        world = np.concatenate([transform_points(poses[src[c]], pts_of(int(src[c]))) for c in cand])
        n_grids[0] += 1
        return build_distance_grid(world, cfg.resolution, cfg.dmax_m, max(cfg.window_m, cfg.wide_m) + 0.5)

    t_keys = [_region_key(poses[k, :2], cfg.region_m) for k in tst]
    by_region: dict[tuple[int, int], list[int]] = {}
    for k, key in zip(tst, t_keys, strict=True):
        by_region.setdefault(key, []).append(int(k))
    _set_total(progress, len(tst))
    checks: list[ScanCheck] = []
    reg_sq: list[float] = []  # registration residuals of the consistent scans (see _registration)
    reg_yaw: list[float] = []
    reg_dirs = 0
    plan: dict[tuple[int, int], list[tuple[int, np.ndarray, float, float]]] = {}  # region -> passes
    for key, ks in sorted(by_region.items()):
        karr = np.asarray(sorted(ks, key=lambda k: s_all[k]), dtype=np.int64)
        pid = _split_passes(s_all[karr], cfg.pass_sep_m)
        center = (np.array(key, dtype=float) + 0.5) * cfg.region_m
        for p in np.unique(pid):
            members = karr[pid == p]
            s_lo, s_hi = s_all[members[0]] - cfg.pass_sep_m, s_all[members[-1]] + cfg.pass_sep_m
            tests = _spread(members, cfg.max_tests_per_pass)
            plan.setdefault(key, []).append((int(p), tests, s_lo, s_hi))
            grid = grid_for(center, s_lo, s_hi)
            for k in tests:
                pts = pts_of(int(k))
                if grid is None or len(pts) < 10:
                    status, off, f0, f1, ov = NO_OVERLAP, np.zeros(3), 0.0, 0.0, 0.0
                else:
                    status, off, f0, f1, ov = _rematch(grid, pts, poses[k], cfg, coarse_cache)
                    if status == OK:
                        reg = _registration(grid, pts, poses[k], cfg)
                        if reg is not None:
                            reg_sq.append(reg[0])
                            reg_dirs += reg[1]
                            reg_yaw.append(reg[2])
                checks.append(ScanCheck(float(st_all[k]), poses[k].copy(), key, int(p), status, off, f0, f1, ov,
                                        float(s_all[k])))
            if progress is not None:
                progress(len(members))  # the pass's test scans are done (the total: every test scan)
        if len(pts_cache) > 20000:  # bounded memory on long logs
            pts_cache.clear()

    def culprit(comp: list[RegionCheck], eps: list[tuple[float, float, float, float]]) -> int | None:
        """The pass whose scans disagree with the passes that are not in dispute (the other
        disputed passes left out of the map), while the others agree with them."""
        reach = cfg.region_m * 0.71 + cfg.gather_m
        near = sorted({int(i) for r in comp for i in tree.query_ball_point(r.center, reach)})
        ss = np.sort(s_all[src[near]]) if near else np.zeros(0)
        cut = np.nonzero(np.diff(ss) > cfg.pass_sep_m)[0]
        runs = [(float(ss[a]), float(ss[b])) for a, b in zip(np.concatenate([[0], cut + 1]),
                                                              np.concatenate([cut, [len(ss) - 1]]), strict=True)
                ] if len(ss) else []
        spans = []  # the whole pass through the neighbourhood of each disputed episode
        for _ta, _tb, sa, sb in eps:
            hit = [(a, b) for a, b in runs if a - cfg.pass_sep_m <= sb and b + cfg.pass_sep_m >= sa]
            spans.append((min([a for a, _ in hit] + [sa]), max([b for _, b in hit] + [sb])))
        frac_bad = []
        for e, (_ta, _tb, sa, sb) in enumerate(eps):
            skips = [(c - 1.0, d + 1.0) for j, (c, d) in enumerate(spans) if j != e]
            n_bad = n_ck = 0
            for r in comp:
                for _p, tests, s_lo, s_hi in plan.get(r.key, []):
                    mine = [k for k in tests if sa - 1.0 <= s_all[k] <= sb + 1.0]
                    if not mine:
                        continue
                    grid = grid_for(r.center, s_lo, s_hi, skips)
                    if grid is None:
                        continue
                    for k in mine:
                        pts = pts_of(int(k))
                        if len(pts) < 10:
                            continue
                        rm = _rematch(grid, pts, poses[k], cfg, coarse_cache)
                        status = rm[0]
                        if status != NO_OVERLAP:
                            n_ck += 1
                            n_bad += status == BAD
            frac_bad.append(n_bad / n_ck if n_ck >= 5 else float("nan"))
        fb = np.array(frac_bad)
        if not np.any(np.isfinite(fb)):
            return None  # only the disputed passes see this place
        k = int(np.nanargmax(fb))
        others = np.delete(fb, k)
        ok_others = np.all(~np.isfinite(others) | (others <= 0.2))
        return k if fb[k] >= 0.5 and ok_others else None

    regions = _summarize_regions(checks, cfg)
    suspects, culprits = _suspects(regions, checks, loops, cfg, t_first, culprit)
    verdict, passed = _verdict_consistency(regions, checks, t_first)
    stats = {"scans": len(records), "posed_scans": int(len(idx)), "tests": len(checks), "grids": n_grids[0],
             "checked": sum(c.status != NO_OVERLAP for c in checks),
             "inconsistent": sum(c.status == BAD for c in checks), "regions": len(regions),
             "regions_checked": sum(r.n_checked >= cfg.region_min_checked for r in regions),
             "regions_flagged": sum(r.flagged for r in regions)}
    reg_m = float(np.sqrt(np.sum(reg_sq) / reg_dirs)) if reg_dirs else float("nan")
    reg_deg = float(np.degrees(np.sqrt(np.mean(np.square(reg_yaw))))) if reg_yaw else float("nan")
    return CheckResult("consistency", checks, regions, suspects, verdict, passed, t_first, stats=stats,
                       culprits=culprits, registration_m=reg_m, registration_deg=reg_deg,
                       registration_n=len(reg_yaw))


def _registration(grid: DistanceGrid, pts: FloatArray, pose0: FloatArray, cfg: CheckConfig
                  ) -> tuple[float, int, float] | None:
    """How far a consistent scan's own pose is from where it fits the other passes best: refined
    from the own pose (the local optimum a localizer on their map would find), the squared shift
    along the directions the scene constrains (a corridor leaves its axis free), their number and
    the heading offset (rad).  None when the refinement does not settle near the own pose."""
    rr = refine(grid, pts, pose0, 0.03)
    d = rr.pose[:2] - pose0[:2]
    dyaw = float(wrap_angle(rr.pose[2] - pose0[2]))
    if (rr.inlier_frac < cfg.min_overlap or np.hypot(d[0], d[1]) > cfg.offset_m
            or abs(dyaw) > np.radians(cfg.offset_deg)):
        return None
    w, v = np.linalg.eigh(0.5 * (rr.info[:2, :2] + rr.info[:2, :2].T))
    strong = v[:, w >= cfg.min_constraint * max(float(w.max()), 1e-12)]
    return float(np.sum((strong.T @ d) ** 2)), int(strong.shape[1]), dyaw


def map_accuracy_m(registration_m: float, resolution_m: float) -> float:
    """The accuracy a map built from passes that register to ``registration_m`` (1 sigma per
    axis) declares: that, and the raster (a wall known to its cell: uniform over the cell,
    ``resolution / sqrt(12)``), added in quadrature."""
    return float(np.sqrt(registration_m**2 + resolution_m**2 / 12.0))


def _fmt_t(t: float, t0: float) -> str:
    return f"{t - t0:.0f}"


def _episodes(stamps: FloatArray, path_m: FloatArray, gap_m: float) -> list[tuple[float, float, float, float]]:
    """Time spans of the passes of some scans: split where their path positions are more than
    ``gap_m`` apart (a robot standing still stays in its pass)."""
    if len(stamps) == 0:
        return []
    o = np.argsort(path_m, kind="stable")
    st, pm = np.asarray(stamps)[o], np.asarray(path_m)[o]
    cut = np.nonzero(np.diff(pm) > gap_m)[0]
    lo = np.concatenate([[0], cut + 1])
    hi = np.concatenate([cut, [len(st) - 1]])
    return [(float(st[a:b + 1].min()), float(st[a:b + 1].max()), float(pm[a]), float(pm[b]))
            for a, b in zip(lo, hi, strict=True)]


def _clusters(regions: list[RegionCheck]) -> list[list[RegionCheck]]:
    """Flagged regions grouped by adjacency (8-connected)."""
    flagged = {r.key: r for r in regions if r.flagged}
    seen: set[tuple[int, int]] = set()
    out = []
    for key in sorted(flagged):
        if key in seen:
            continue
        stack, comp = [key], []
        seen.add(key)
        while stack:
            k = stack.pop()
            comp.append(flagged[k])
            for dx in (-1, 0, 1):
                for dy in (-1, 0, 1):
                    n = (k[0] + dx, k[1] + dy)
                    if n in flagged and n not in seen:
                        seen.add(n)
                        stack.append(n)
        out.append(comp)
    return out


def _suspects(regions: list[RegionCheck], checks: list[ScanCheck], loops: Sequence[LoopInfo],
              cfg: CheckConfig, t0: float,
              culprit: Callable[[list[RegionCheck], list[tuple[float, float, float, float]]], int | None] | None = None
              ) -> tuple[list[str], list[tuple[float, float]]]:
    """One line per cluster of flagged regions: which passes disagree, which one is the odd one out
    (when a third pass can tell), and the loop closures that tie the disagreeing passes; and the
    time spans of the passes found off."""
    out: list[str] = []
    culprits: list[tuple[float, float]] = []
    for comp in _clusters(regions):
        keys = {r.key for r in comp}
        bad = [c for c in checks if c.region in keys and c.status == BAD]
        eps = _episodes(np.array([c.stamp for c in bad]), np.array([c.path_m for c in bad]), cfg.pass_sep_m)
        center = np.mean([r.center for r in comp], axis=0)
        off_m = float(np.median([np.hypot(c.offset[0], c.offset[1]) for c in bad])) if bad else 0.0
        off_deg = float(np.degrees(np.median([abs(c.offset[2]) for c in bad]))) if bad else 0.0
        ep_txt = ", ".join(f"t={_fmt_t(a, t0)}-{_fmt_t(b, t0)} s" for a, b, _, _ in eps)
        what = f"the passes at {ep_txt} disagree" if len(eps) > 1 else f"the pass at {ep_txt} disagrees with the others"
        line = (f"around ({center[0]:.1f}, {center[1]:.1f}) m ({len(comp)} regions): {what} "
                f"by {off_m:.2f} m / {off_deg:.1f} deg")
        k = culprit(comp, eps) if culprit is not None and len(eps) >= 2 else None
        spans = [(a, b) for a, b, _, _ in eps]
        if len(eps) == 1:  # the other passes agree with each other, this one does not
            culprits.append(spans[0])
        elif k is not None:
            culprits.append(spans[k])
            a, b = eps[k][:2]
            line += (f"; the odd one out is the pass at t={_fmt_t(a, t0)}-{_fmt_t(b, t0)} s "
                     "(the others agree without it)")
            spans = [(a, b)]
        elif len(eps) >= 2:
            line += "; no third pass here tells which of them is off"
        reach = max(r.size_m for r in comp) + cfg.gather_m
        near = [lp for lp in loops
                if min(float(np.min([np.hypot(*(lp.xy_old - r.center)) for r in comp])),
                       float(np.min([np.hypot(*(lp.xy_new - r.center)) for r in comp]))) <= reach]
        sp = [(a - 30.0, b + 30.0) for a, b in spans]
        tied = [lp for lp in near if any(a <= lp.t_new <= b or a <= lp.t_old <= b for a, b in sp)]
        if tied:
            line += "; suspect loop closures " + ", ".join(
                f"t={_fmt_t(lp.t_old, t0)}<->{_fmt_t(lp.t_new, t0)} s" for lp in tied[:6])
            if len(tied) > 6:
                line += f" (+{len(tied) - 6} more)"
        elif loops:
            line += "; no loop closure ties these passes here (a missed loop closure, or drift between them)"
        out.append(line)
    return out, culprits


def _verdict_consistency(regions: list[RegionCheck], checks: list[ScanCheck], t0: float) -> tuple[str, bool]:
    judged = [r for r in regions if r.n_checked > 0]
    n_ck = sum(c.status != NO_OVERLAP for c in checks)
    flagged = [r for r in regions if r.flagged]
    if not judged:
        return ("map-check: NOT CHECKED - no place was passed twice (no overlap between passes)", True)
    if not flagged:
        worst = min(judged, key=lambda r: (r.score, -r.n_checked))
        return (f"map-check: CONSISTENT - {len(judged)} regions seen by several passes, {n_ck} scans re-matched, "
                f"none disagrees (lowest region score {worst.score:.2f} at ({worst.center[0]:.1f}, "
                f"{worst.center[1]:.1f}))", True)
    w = max(flagged, key=lambda r: (r.n_bad, r.offset_m))
    return (f"map-check: INCONSISTENT - {len(flagged)} of {len(judged)} regions disagree between passes; worst at "
            f"({w.center[0]:.1f}, {w.center[1]:.1f}) m: {w.n_bad}/{w.n_checked} scans off by {w.offset_m:.2f} m / "
            f"{w.offset_deg:.1f} deg", False)


# ---------------------------------------------------------------------------- world vs map
def check_against_map(records: Sequence[ScanRecord], mount_pose: FloatArray, trajectory: Trajectory,
                      occ: OccupancyMap, config: CheckConfig | None = None,
                      progress: Callable[[int], None] | None = None) -> CheckResult:
    """Where does a localization log (scans at the poses of ``trajectory``) disagree with ``occ``?"""
    cfg = config or CheckConfig()
    mount = np.asarray(mount_pose, dtype=float)
    idx, poses = scan_poses(records, trajectory)
    t_first = float(records[0].stamp) if records else 0.0
    if len(idx) == 0:
        verdict = "map-check: NOT CHECKED - no scan of the log lies within the trajectory's time span"
        return CheckResult("localization", [], [], [], verdict, True, t_first, stats={"scans": 0})
    rows, cols = np.nonzero(occ.occupied)
    occ_xy = occ.grid_to_world(rows, cols)
    grid = build_distance_grid(occ_xy, min(cfg.resolution, occ.resolution), cfg.dmax_m, cfg.window_m + 1.0)
    tst = _pick_by_travel(poses, cfg.test_step_m * 0.5, cfg.test_step_deg)
    _set_total(progress, len(tst))
    coarse_cache: list = []
    checks: list[ScanCheck] = []
    cell = cfg.change_cell_m
    add_obs: dict[tuple[int, int], set[int]] = {}
    rem_obs: dict[tuple[int, int], set[int]] = {}
    add_cnt: dict[tuple[int, int], int] = {}
    rem_cnt: dict[tuple[int, int], int] = {}
    n_returns: dict[int, int] = {}  # test scan -> its valid returns
    add_fine: dict[tuple[int, int], set[int]] = {}  # coarse cell -> the fine cells its returns fell in
    rem_fine: dict[tuple[int, int], set[int]] = {}
    views_free: list[np.ndarray] = []  # per test scan: the cells its beams crossed where the map is free ...
    views_hit: list[np.ndarray] = []   # ... and the mapped cells its beams should have ended in
    for n_t, k in enumerate(tst):
        rec = records[int(idx[k])]
        pose = poses[k]
        pts = _scan_points(rec, mount, cfg)
        key = _region_key(pose[:2], cfg.region_m)
        if progress is not None:
            progress(1)
        if len(pts) < 10:
            checks.append(ScanCheck(float(rec.stamp), pose.copy(), key, 0, NO_OVERLAP, np.zeros(3), 0, 0, 0))
            continue
        status, off, f0, f1, ov = _rematch(grid, pts, pose, cfg, coarse_cache)
        checks.append(ScanCheck(float(rec.stamp), pose.copy(), key, 0, status, off, f0, f1, ov))
        if status != OK:
            continue  # changes are read only where the pose agrees with the map
        added, removed, seen_free, seen_hit = _beam_changes(rec, mount, pose, occ, grid, cfg, trajectory, views=True)
        n_returns[n_t] = int(np.count_nonzero(rec.scan.valid_mask()))
        views_free.append(np.unique(_cell_keys(seen_free, cell)))
        views_hit.append(np.unique(_cell_keys(seen_hit, cell)))
        for xy, obs, cnt, fine in ((added, add_obs, add_cnt, add_fine), (removed, rem_obs, rem_cnt, rem_fine)):
            for c, f in zip(map(tuple, np.floor(xy / cell).astype(np.int64).tolist()),
                            _cell_keys(xy, cfg.change_fine_m).tolist(), strict=True):
                fine.setdefault(c, set()).add(f)
            for c in {(int(a), int(b)) for a, b in np.floor(xy / cell)}:
                obs.setdefault(c, set()).add(n_t)
            for a, b in np.floor(xy / cell).astype(np.int64):
                cnt[(int(a), int(b))] = cnt.get((int(a), int(b)), 0) + 1
    changes: list[ChangeRegion] = []
    pts_out = {}
    for kind, obs, cnt, views, fine in (("added", add_obs, add_cnt, views_free, add_fine),
                                        ("removed", rem_obs, rem_cnt, views_hit, rem_fine)):
        seen = _view_counts(views)
        keep = [c for c, s in obs.items() if len(s) >= cfg.change_min_scans and cnt[c] >= cfg.change_min_obs
                and len(s) >= cfg.change_persistence * max(seen.get(_key_of(c), 0), len(s))]
        pts_out[kind] = (np.array(keep, dtype=float).reshape(-1, 2) + 0.5) * cell
        found = _cluster_changes(keep, cnt, kind, cfg)
        for ch_ in found:
            lo, hi = np.floor(ch_.bbox[:2] / cell + 0.5), np.floor(ch_.bbox[2:] / cell - 0.5)
            cells_in = [c for c in keep if lo[0] <= c[0] <= hi[0] and lo[1] <= c[1] <= hi[1]]
            ch_.extent_m = len(set().union(*(fine.get(c, set()) for c in cells_in))) * cfg.change_fine_m
            scans_in = set().union(*(obs.get(c, set()) for c in cells_in))
            ch_.share = ch_.observations / max(1, sum(n_returns.get(k, 0) for k in scans_in))
            ch_.major = ch_.share >= cfg.change_significant_share
        changes += found
    regions = _summarize_regions(checks, cfg)
    verdict, passed = _verdict_localization(regions, checks, changes, cfg.change_significant_share)
    stats = {"scans": len(records), "posed_scans": int(len(idx)), "tests": len(checks),
             "checked": sum(c.status != NO_OVERLAP for c in checks),
             "inconsistent": sum(c.status == BAD for c in checks), "regions": len(regions),
             "change_regions_added": sum(c.kind == "added" for c in changes),
             "change_regions_removed": sum(c.kind == "removed" for c in changes)}
    suspects = [f"{'' if c.major else 'minor: '}{c.kind} structure at "
                f"({c.center[0]:.1f}, {c.center[1]:.1f}) m, {c.bbox[2] - c.bbox[0]:.1f} x "
                f"{c.bbox[3] - c.bbox[1]:.1f} m ({c.observations} returns, {100 * c.share:.1f} % of those of the "
                "scans that saw it)"
                for c in changes]
    suspects += [f"region ({r.center[0]:.1f}, {r.center[1]:.1f}) m: {r.n_bad}/{r.n_checked} scans fit the map "
                 f"better {r.offset_m:.2f} m / {r.offset_deg:.1f} deg away from the trajectory"
                 for r in regions if r.flagged]
    return CheckResult("localization", checks, regions, suspects, verdict, passed, t_first, changes=changes,
                       added_xy=pts_out["added"], removed_xy=pts_out["removed"], stats=stats)


def _beam_laser_poses(rec: ScanRecord, mount: FloatArray, pose: FloatArray, trajectory: Trajectory | None
                      ) -> FloatArray:
    """Map-frame laser pose of every beam: the trajectory at each beam's own time (``stamp + i *
    time_increment``) when the scan says when its beams were measured, else the scan's pose."""
    sc = rec.scan
    n = len(sc.ranges)
    tinc = float(sc.time_increment or 0.0)
    if trajectory is None or tinc <= 0.0 or n < 2 or len(trajectory) < 2:
        return np.tile(compose(pose, mount), (n, 1))
    t = float(rec.stamp) + tinc * np.arange(n, dtype=np.float64)
    # the pose the check stands at (its own, maybe re-matched) moved by the trajectory's motion
    # between the scan stamp and each beam
    p_t = trajectory.interpolate(t)
    p_0 = trajectory.interpolate(np.array([float(rec.stamp)]))[0]
    return compose(compose(pose, between(p_0, p_t)), mount)


_KEY_SHIFT = np.int64(1 << 32)


def _cell_keys(xy: FloatArray, cell: float) -> np.ndarray:
    """One int64 per point: its ``cell``-sized cell (i, j) packed."""
    ij = np.floor(np.asarray(xy, dtype=float).reshape(-1, 2) / cell).astype(np.int64)
    return ij[:, 0] * _KEY_SHIFT + ij[:, 1]


def _key_of(c: tuple[int, int]) -> int:
    return int(np.int64(c[0]) * _KEY_SHIFT + np.int64(c[1]))


def _view_counts(per_scan: list[np.ndarray]) -> dict[int, int]:
    """``{cell key: test scans that looked at it}``."""
    if not per_scan:
        return {}
    keys, counts = np.unique(np.concatenate(per_scan), return_counts=True)
    return dict(zip(keys.tolist(), counts.tolist(), strict=True))


def _beam_changes(rec: ScanRecord, mount: FloatArray, pose: FloatArray, occ: OccupancyMap, grid: DistanceGrid,
                  cfg: CheckConfig, trajectory: Trajectory | None = None,
                  views: bool = False) -> tuple[FloatArray, ...]:
    """Added (returns short of the map's range, off mapped structure) and removed (map hits the beam
    went through) points of one scan, map frame.  Each beam is cast from where the laser was when it
    was measured (a scan taken while turning at 0.8 rad/s smears a wall 9 m away by 0.7 m, which
    the check read as a change)."""
    sc = rec.scan
    r = np.asarray(sc.ranges, dtype=float)
    a = np.asarray(sc.angles, dtype=float)
    lps = _beam_laser_poses(rec, mount, pose, trajectory)
    use = np.isfinite(r) | np.isposinf(r)
    with np.errstate(invalid="ignore"):
        use &= ~(np.isfinite(r) & (r < max(sc.range_min, 1e-3)))
    r, a, lps = r[use], a[use], lps[use]
    if len(r) == 0:
        return (np.zeros((0, 2)),) * (4 if views else 2)
    rmax = min(float(sc.range_max), cfg.points_range_m)
    exp_r = occ.raycast(lps[:, :2], a + lps[:, 2], rmax)
    hit = np.isfinite(r) & (r < sc.range_max)
    with np.errstate(invalid="ignore"):
        short = hit & (r < rmax) & (r < exp_r - cfg.change_m)
        beyond = np.isfinite(exp_r) & (exp_r < rmax - cfg.change_m) & (~hit | (r > exp_r + cfg.change_m))
    if beyond.any():  # a beam grazing a mapped surface: its tolerance grows as 1 / sin(incidence)
        lateral = max(cfg.change_lateral_m, 2.0 * occ.resolution)
        sin_inc = _incidence_sin(grid, lps[beyond], a[beyond], exp_r[beyond], occ.resolution)
        with np.errstate(invalid="ignore", divide="ignore"):
            tol = lateral / np.maximum(sin_inc, 1e-3)
            # a return past it; no return only where the beam meets the surface steeply enough that a
            # return's tolerance would not have grown (at a grazing angle the beam may glance off: no return)
            beyond[beyond] &= np.where(hit[beyond], r[beyond] > exp_r[beyond] + np.maximum(cfg.change_m, tol),
                                       tol <= cfg.change_m)

    def world(rng: FloatArray, sel: np.ndarray) -> FloatArray:
        loc = np.column_stack([rng * np.cos(a[sel]), rng * np.sin(a[sel]), np.zeros(int(sel.sum()))])
        return compose(lps[sel], loc)[:, :2] if sel.any() else np.zeros((0, 2))

    added = world(r[short], short)
    if len(added):  # not on (or next to) mapped structure
        d = point_distances(grid, added, np.zeros(3))
        added = added[d > 0.15]
    # the first mapped cell the beam should have hit (just past the boundary the raycast returns)
    removed = world(exp_r[beyond] + 0.5 * occ.resolution, beyond)
    if len(removed) and hit.any():
        # structure other beams of this scan still hit is there: a beam that grazed past a
        # rasterized corner or a wall's edge removed nothing
        from scipy.spatial import cKDTree

        seen = world(r[hit], hit)
        d, _ = cKDTree(seen).query(removed, distance_upper_bound=cfg.change_seen_m)
        removed = removed[~np.isfinite(d)]
    if not views:
        return added, removed
    # where this scan looked: the free cells along each beam up to the map's range (a return short of
    # it included), and the mapped cells the beams should have ended in
    reach = np.where(np.isfinite(exp_r), np.minimum(exp_r, rmax), rmax)
    step = 0.5 * cfg.change_cell_m
    n_s = np.maximum(1, np.floor(reach / step).astype(np.int64))
    beam = np.repeat(np.arange(len(reach)), n_s)
    dist = (np.arange(int(n_s.sum())) - np.repeat(np.cumsum(n_s) - n_s, n_s) + 0.5) * step
    ang = a[beam] + lps[beam, 2]
    free = np.column_stack([lps[beam, 0] + dist * np.cos(ang), lps[beam, 1] + dist * np.sin(ang)])
    aims = np.isfinite(exp_r) & (exp_r < rmax - cfg.change_m)
    hit_cells = world(exp_r[aims] + 0.5 * occ.resolution, aims)
    return added, removed, free, hit_cells


def _incidence_sin(grid: DistanceGrid, lps: FloatArray, a: FloatArray, exp_r: FloatArray, res: float) -> FloatArray:
    """|sin| of the angle between each beam and the mapped surface it should hit: the beam direction
    against the surface normal, the gradient of the distance field just in front of the hit."""
    ang = a + lps[:, 2]
    d = np.column_stack([np.cos(ang), np.sin(ang)])
    p = lps[:, :2] + d * np.maximum(exp_r - 2.0 * res, 0.0)[:, None]
    h = max(grid.resolution, res)
    z = np.zeros(3)
    gx = point_distances(grid, p + [h, 0.0], z) - point_distances(grid, p - [h, 0.0], z)
    gy = point_distances(grid, p + [0.0, h], z) - point_distances(grid, p - [0.0, h], z)
    norm = np.hypot(gx, gy)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.abs(gx * d[:, 0] + gy * d[:, 1]) / norm
    return np.where(norm > 0, s, 1.0)  # no gradient (inside a blob, past the clip): head-on


def _cluster_changes(cells: list[tuple[int, int]], cnt: dict[tuple[int, int], int], kind: str,
                     cfg: CheckConfig) -> list[ChangeRegion]:
    if not cells:
        return []
    from scipy.ndimage import label

    arr = np.array(cells, dtype=np.int64)
    lo = arr.min(axis=0)
    img = np.zeros(tuple(arr.max(axis=0) - lo + 1), dtype=bool)
    img[arr[:, 0] - lo[0], arr[:, 1] - lo[1]] = True
    lab, n = label(img, structure=np.ones((3, 3), dtype=bool))
    out = []
    for k in range(1, n + 1):
        ij = np.argwhere(lab == k) + lo
        if len(ij) < cfg.change_min_cells:
            continue
        xy = (ij + 0.5) * cfg.change_cell_m
        obs = sum(cnt[(int(a), int(b))] for a, b in ij)
        h = 0.5 * cfg.change_cell_m
        out.append(ChangeRegion(kind, xy.mean(axis=0), np.array([xy[:, 0].min() - h, xy[:, 1].min() - h,
                                                                  xy[:, 0].max() + h, xy[:, 1].max() + h]),
                                len(ij), int(obs)))
    return out


def _verdict_localization(regions: list[RegionCheck], checks: list[ScanCheck], changes: list[ChangeRegion],
                          significant_share: float) -> tuple[str, bool]:
    judged = [r for r in regions if r.n_checked > 0]
    flagged = [r for r in regions if r.flagged]
    n_add = sum(c.kind == "added" for c in changes)
    n_rem = sum(c.kind == "removed" for c in changes)
    if not judged:
        return "map-check: NOT CHECKED - no scan overlaps the map at its pose", True
    major = [c for c in changes if c.major]
    minor = len(changes) - len(major)
    if not flagged and not major:
        return (f"map-check: MATCHES - the log agrees with the map in all {len(judged)} regions it passed "
                f"({sum(c.status != NO_OVERLAP for c in checks)} scans)"
                + (f"; {minor} minor difference(s), each under {100 * significant_share:.0f} % of the returns "
                   "that saw it (listed)" if minor else ""), True)
    parts = []
    if changes:
        parts.append(f"{n_add} added and {n_rem} removed structure regions"
                     + (f" ({minor} of them minor)" if minor else ""))
    if flagged:
        parts.append(f"{len(flagged)} of {len(judged)} regions where the poses disagree with the map")
    return "map-check: CHANGED - " + "; ".join(parts), False
