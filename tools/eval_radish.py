"""Map the real Radish logs (intel, fr079, aces, mit-csail, fr-clinic) with ``fgloc map`` (each in its
own process: wall time and peak RSS measured), score the all-scan trajectories against references,
report the self-check verdicts, and (optionally) localize a part of each log on a map of another.

    python tools/eval_radish.py [--out eval_radish] [--datasets intel fr079 aces mit-csail fr-clinic]
                                [--reference-dir DIR] [--relations aces=aces.relations] [--localize]

References: the GMapping-corrected logs of ``../shared/data/radish-reference`` (intel, fr079) and of
``--reference-dir`` (same file names, e.g. ``aces-corrected.log.gz``, ``csail-corrected.log.gz`` from
the Radish / acschaefer/ple distribution, CC BY); ``--relations NAME=FILE`` adds a relation file of
Kuemmerle et al. 2009 (``t1 t2 x y z roll pitch yaw``, stamps on the log's ipc clock).

Reference association (the corrected logs' timestamps are *not* the raw logs'):
every FLASER line of the corrected log is matched to the raw log's scan with
*identical range readings* (all beams equal after the same no-return coding), taking
the first such raw scan after the previously matched one (order preserved).  The
reference pose of a matched scan is stamped with *our* (raw ipc) stamp of that scan,
so relations built from it are compared on exactly the same scans.  Corrected lines
with no identical raw scan are dropped and counted.  FLASER ``x y theta`` in the
corrected log is the laser pose; it is converted to base_link with the laser mount.

Relations (Kuemmerle et al. 2009) from the reference: every reference pose paired
with the first one 1-2 s later (the intel and aces corrected logs keep only every ~3 s a
scan, so they use 1-6 s), plus loop-closure pairs (<= 1 m apart, >= 30 s apart).
Prints one markdown table; the maps, checks and trajectories stay under --out.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from fgloc.eval.relations import evaluate_relations, relations_from_reference, write_relations
from fgloc.geometry import compose, inverse
from fgloc.io.carmen import open_text
from fgloc.io.tum import read_tum, write_tum
from fgloc.mapping.build import build_map, load_records
from fgloc.mapping.source import ScanRecord
from fgloc.types import StaticTransform, Trajectory

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
LOGS = {
    "intel": DATA / "radish" / "intel.clf.bz2",
    "fr079": DATA / "radish" / "fr079.clf.bz2",
    "aces": DATA / "radish" / "aces.clf.bz2",
    "mit-csail": DATA / "radish" / "mit-csail.clf.bz2",
    "fr-clinic": DATA / "radish" / "fr-clinic_robotlaser.clf.bz2",
}
REF_NAMES = {"intel": "intel-corrected.log.gz", "fr079": "freiburg-079-corrected.log.gz",
             "aces": "aces-corrected.log.gz", "mit-csail": "csail-corrected.log.gz"}
REFS = {k: DATA / "radish-reference" / v for k, v in REF_NAMES.items()}
REL_DT = {"intel": (1.0, 6.0), "fr079": (1.0, 2.0), "aces": (1.0, 6.0), "mit-csail": (1.0, 6.0)}
# aces is one tour: its two halves share under a third of their path (< 70 % for any 600-scan
# segment), so no part of it can be localized on a map made from the other half; there the
# segment (the start of the second half) is localized on the map of the whole log
MAP_WHOLE_LOG = {"aces"}


def _key(ranges: np.ndarray, rmax: float) -> bytes:
    r = np.asarray(ranges, dtype=np.float32).copy()
    r[~np.isfinite(r) | (r >= rmax)] = np.float32(-1.0)
    return r.tobytes()


def reference_trajectory(ref_path: Path, recs: list[ScanRecord], mount: StaticTransform
                         ) -> tuple[Trajectory, dict]:
    """Corrected FLASER poses matched to our scans by identical ranges (see module docstring)."""
    by_key: dict[bytes, list[int]] = {}
    for i, r in enumerate(recs):
        by_key.setdefault(_key(r.scan.ranges, r.scan.range_max), []).append(i)
    rmax = recs[0].scan.range_max
    inv_mount = inverse(np.asarray(mount.pose, dtype=float))
    stamps, poses = [], []
    last = -1
    n_ref = dropped = 0
    with open_text(ref_path) as f:
        for line in f:
            tok = line.split()
            if not tok or tok[0] != "FLASER":
                continue
            n_ref += 1
            n = int(tok[1])
            rng = np.array(tok[2:2 + n], dtype=np.float32)
            laser = np.array(tok[2 + n:5 + n], dtype=float)
            cand = [i for i in by_key.get(_key(rng, rmax), []) if i > last]
            if not cand:
                dropped += 1
                continue
            last = cand[0]
            stamps.append(recs[last].stamp)
            poses.append(compose(laser, inv_mount))
    traj = Trajectory.from_unsorted(np.array(stamps), np.array(poses))
    return traj, {"ref_scans": n_ref, "matched": len(stamps), "dropped": dropped, "unique_stamps": len(traj)}


def _run(cmd: list[str]) -> str:
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed: {p.stderr.strip()[-500:]}")
    return p.stdout


def _covered_segment(recs: list[ScanRecord], full: Trajectory, map_stamps: np.ndarray, lo: int, hi: int,
                     n: int) -> int:
    """Start index in [lo, hi] of the n-scan segment whose poses (full-log SLAM) lie most often
    within 1 m of a pose the map was built from: a revisit, not a drive into unmapped rooms."""
    from scipy.spatial import cKDTree

    tree = cKDTree(full.interpolate(map_stamps)[:, :2])
    stamps = np.array([r.stamp for r in recs])
    near = tree.query(full.interpolate(stamps)[:, :2])[0] < 1.0
    best, best_cov = lo, -1.0
    for s0 in range(lo, max(hi, lo) + 1, 50):
        cov = float(near[s0:s0 + n].mean())
        if cov > best_cov:
            best, best_cov = s0, cov
    return best


def localize(name: str, recs: list[ScanRecord], mount: StaticTransform, full_scans: Trajectory,
             out: Path, ref: Trajectory | None, max_scans: int | None = None,
             config: Path | None = None, map_whole_log: bool = False) -> dict:
    """Map the first half of the scans; localize the last ``max_scans`` scans of the log (in the
    second half) with ``fgloc run`` (defaults: smoother back-end, native front-end) from the SLAM
    pose at the segment's first scan, and with :func:`fgloc.mapping.localize.track_on_map`.

    The map is built from the first half only, so the segment is a different pass through
    the building than the one that made the map.
    """
    from fgloc.eval.metrics import evaluate
    from fgloc.io.mcap_writer import LogWriter
    from fgloc.mapping.source import log_messages

    half = len(recs) // 2
    n_loc = len(recs) - half if max_scans is None else min(max_scans, len(recs) - half)
    if map_whole_log:  # the map of the whole log (already built by main), the second half
        map_dir = out / name
        mo = None
        lo_s, hi_s = half, half
    else:  # the map from the first half, the segment from the second
        map_dir = out / f"{name}_firsthalf"
        mo = build_map(LOGS[name], map_dir, end=0.5)
        lo_s, hi_s = half, len(recs) - n_loc
    map_stamps = full_scans.stamps if mo is None else mo.slam.scan_trajectory.stamps
    start = _covered_segment(recs, full_scans, map_stamps, lo_s, hi_s, n_loc)
    stop = start + n_loc
    mcap = out / f"{name}_segment.mcap"
    n_scan = 0
    started = False
    with LogWriter(mcap) as w:
        for topic, msg in log_messages(LOGS[name]):
            if topic == "/tf_static":
                w.write(topic, msg, stamp=recs[start].stamp - 0.5)
                continue
            if topic == "/scan" and "rear" not in getattr(msg, "frame_id", ""):
                n_scan += 1
                started = start < n_scan <= stop
                if n_scan > stop:
                    break
            # the raw CARMEN odometry as it is (aces / intel: tv = rv = 0; fr079: rv = 0):
            # fgloc run takes the motion from the odometry poses then
            if started:
                w.write(topic, msg)
    # the half-log map has its own frame (its own optimization): hand the full-log SLAM pose
    # at the segment start over through the map's scan nearest to it in space
    hs = full_scans if mo is None else mo.slam.scan_trajectory
    p_start = full_scans.interpolate(recs[start].stamp)[0]
    full_at_h = full_scans.interpolate(hs.stamps)
    i = int(np.argmin(np.hypot(full_at_h[:, 0] - p_start[0], full_at_h[:, 1] - p_start[1])))
    to_half = compose(hs.poses[i], inverse(full_at_h[i]))
    p0 = compose(to_half, p_start)
    run_dir = out / f"{name}_localize"
    t0 = time.perf_counter()
    from fgloc.app.run import RunRequest, run_log  # what `fgloc run LOG --map M --initial-pose ...` does

    run_res = run_log(RunRequest(mcap, run_dir, map_dir / "map.yaml", initial_pose=tuple(float(v) for v in p0),
                                 config=config)).as_dict()
    wall = time.perf_counter() - t0
    est = read_tum(run_dir / "trajectory.tum")
    res: dict = {"map": "whole log" if map_whole_log else "first half", "seg_start": start,
                 "map_scans": len(recs) if mo is None else mo.n_scans, "loc_scans": n_loc, "loc_wall_s": wall,
                 "poses": len(est), "relocalizations": int(run_res["stats"].get("relocalizations", 0)),
                 "fixes": int(run_res["stats"].get("fixes", 0)), "no_fix": int(run_res["stats"].get("no_fix", 0))}
    inseg = (full_scans.stamps >= recs[start].stamp - 1.0) & (full_scans.stamps <= est.stamps[-1] + 1.0)
    slam_part = Trajectory(full_scans.stamps[inseg], full_scans.poses[inseg])
    slam_part = Trajectory(slam_part.stamps, compose(to_half, slam_part.poses))
    m = evaluate(est, slam_part, align=False)
    get = (lambda k: m[k]) if isinstance(m, dict) else (lambda k: getattr(m, k))
    res["vs_slam_rmse_m"] = float(get("position_rmse_m"))
    res["vs_slam_heading_deg"] = float(get("heading_rmse_deg"))
    # frame-free: relations (1-2 s + loop pairs) of the full-log SLAM trajectory
    res["relations_vs_slam"] = evaluate_relations(est, relations_from_reference(full_scans, 1.0, 2.0))
    if ref is not None:
        lo, hi = REL_DT[name]
        rels = relations_from_reference(ref, lo, hi)
        res["relations"] = evaluate_relations(est, rels, max_assoc_dt=0.05)
    # baseline: fgloc.mapping's own scan-to-map tracker on the same segment and map
    from fgloc.mapping.localize import track_on_map
    from fgloc.maps import OccupancyMap

    seg = recs[start:stop]
    t1 = time.perf_counter()
    base, bstats = track_on_map(seg, OccupancyMap.load(map_dir / "map.yaml"), mount, p0)
    res["track_wall_s"] = time.perf_counter() - t1
    res["track_stats"] = bstats
    write_tum(run_dir / "track_on_map.tum", base)
    mb = evaluate(base, slam_part, align=False)
    getb = (lambda k: mb[k]) if isinstance(mb, dict) else (lambda k: getattr(mb, k))
    res["track_vs_slam_rmse_m"] = float(getb("position_rmse_m"))
    res["track_vs_slam_heading_deg"] = float(getb("heading_rmse_deg"))
    if ref is not None:
        res["track_relations"] = evaluate_relations(base, relations_from_reference(ref, *REL_DT[name]))
    _plot_localization(run_dir / "localization.png", map_dir / "map.yaml", est, full_scans, name, base)
    return res


def _plot_localization(path: Path, map_yaml: Path, est: Trajectory, slam: Trajectory, name: str,
                       base: Trajectory | None = None) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fgloc.maps import OccupancyMap

    occ = OccupancyMap.load(map_yaml)
    img = np.full(occ.data.shape, 0.75)
    img[occ.free] = 1.0
    img[occ.occupied] = 0.0
    x0, x1, y0, y1 = occ.extent
    fig, ax = plt.subplots(figsize=(9, 9 * (y1 - y0) / max(x1 - x0, 1e-9) + 0.8))
    ax.imshow(img, cmap="gray", vmin=0, vmax=1, origin="lower", extent=(x0, x1, y0, y1), interpolation="nearest")
    ax.plot(est.poses[:, 0], est.poses[:, 1], "-", color="tab:blue", lw=0.8, label="fgloc run (smoother+native)")
    if base is not None:
        ax.plot(base.poses[:, 0], base.poses[:, 1], "-", color="tab:orange", lw=0.8, alpha=0.8,
                label="scan-to-map tracker (fgloc.mapping.localize)")
    ax.set_title(f"{name}: a log segment localized on {map_yaml.parent.name}/map.yaml", fontsize=9)
    ax.set_aspect("equal")
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


EXCERPTS = {"intel": 1200, "fr079": 600}  # first N scans of each log


def make_excerpts(dest: Path) -> None:
    """Write data/radish/<name>-head.clf.bz2 (the raw log up to scan N) and <name>-head-reference.tum
    (the corrected poses of those scans, stamped with the raw scans' stamps)."""
    import bz2

    dest.mkdir(parents=True, exist_ok=True)
    for name, n in EXCERPTS.items():
        lines = []
        k = 0
        with open_text(LOGS[name]) as f:
            for line in f:
                if line.startswith("FLASER"):
                    if k == n:
                        break
                    k += 1
                lines.append(line)
        out = dest / f"{name}-head.clf.bz2"
        with bz2.open(out, "wt") as g:
            g.writelines(lines)
        recs, mount = load_records(LOGS[name])
        ref, _ = reference_trajectory(REFS[name], recs, mount)
        tmax = recs[n - 1].stamp
        keep = ref.stamps <= tmax
        write_tum(dest / f"{name}-head-reference.tum", Trajectory(ref.stamps[keep], ref.poses[keep]))
        print(f"wrote {out} ({out.stat().st_size} bytes) and its reference ({int(keep.sum())} poses)")


def injected_check(name: str, recs: list[ScanRecord], mount: StaticTransform, traj: Trajectory, out: Path,
                   spec: str) -> str:
    """Self-check of the map with one pass moved (``NAME=T0,T1,DX,DY,DEG``): check.yaml / check.png in
    ``out/NAME_injected_DXxDY`` and the verdict line."""
    from fgloc.mapping.build import write_check
    from fgloc.mapping.selfcheck import check_consistency
    from fgloc.maps import load_map

    t0_s, t1_s, dx, dy, deg = (float(v) for v in spec.split("=", 1)[1].split(","))
    first = recs[0].stamp
    p = traj.poses.copy()
    m = (traj.stamps >= first + t0_s) & (traj.stamps <= first + t1_s)
    c = p[m, :2].mean(axis=0)
    tf = compose(compose(np.array([c[0], c[1], 0.0]), np.array([dx, dy, np.radians(deg)])),
                 np.array([-c[0], -c[1], 0.0]))
    p[m] = compose(tf, p[m])
    moved = Trajectory(traj.stamps, p)
    res = check_consistency(recs, np.asarray(mount.pose), moved)
    d = out / f"{name}_injected_{dx:g}x{dy:g}"
    write_check(d, res, load_map(out / name / "map.yaml"), moved,
                f"{name}: pass t={t0_s:g}-{t1_s:g} s moved ({dx:g}, {dy:g}) m, {deg:g} deg")
    return (f"pass t={t0_s:g}-{t1_s:g} s ({int(m.sum())} scans) moved ({dx:g}, {dy:g}) m / {deg:g} deg around "
            f"({c[0]:.1f}, {c[1]:.1f}): {res.verdict}")


def align_passes(name: str, recs: list[ScanRecord], mount: StaticTransform, traj: Trajectory,
                 ref: Trajectory | None, spec: str) -> list[str]:
    """Do two passes (``NAME=A0,A1,B0,B1``, s after the first scan) agree where the map put them?

    Pass A's returns (every scan of [A0, A1] at its map pose) make a distance field; pass B's
    returns, in the frame of its middle scan (B's own relative poses), are searched over +-4 m /
    +-10 deg around where the map put that scan, and refined.  Prints the best offset from the
    map's pose, the score there and at the map's pose, the strongest rival peaks, the inlier
    fraction (< 0.1 m) and RMS after refinement, both ways round; and, with a reference, the
    relative poses of the reference's scans of A and B against ours."""
    from fgloc.geometry import between
    from fgloc.mapping.occupancy import scan_endpoints
    from fgloc.mapping.scanmatch import build_distance_grid, correlative_search, point_distances, refine

    a0, a1, b0, b1 = (float(v) for v in spec.split("=", 1)[1].split(","))
    first = recs[0].stamp
    st = np.array([r.stamp for r in recs])
    poses = traj.interpolate(st)
    mnt = np.asarray(mount.pose, dtype=float)

    def pts(i: int) -> np.ndarray:
        sc = recs[i].scan
        e, h = scan_endpoints(sc.ranges, sc.angles, sc.range_min, sc.range_max, 25.0, 8.0)
        return compose(mnt, np.column_stack([e[h], np.zeros(int(h.sum()))]))[:, :2]

    def world(p: np.ndarray, pose: np.ndarray) -> np.ndarray:
        return compose(pose, np.column_stack([p, np.zeros(len(p))]))[:, :2]

    out = []
    for (lo, hi), (lo2, hi2) in (((a0, a1), (b0, b1)), ((b0, b1), (a0, a1))):
        ia = np.nonzero((st - first >= lo) & (st - first <= hi))[0]
        ib = np.nonzero((st - first >= lo2) & (st - first <= hi2))[0]
        if len(ia) == 0 or len(ib) == 0:
            out.append(f"no scans in [{lo:g}, {hi:g}] or [{lo2:g}, {hi2:g}] s")
            continue
        grid = build_distance_grid(np.concatenate([world(pts(i), poses[i]) for i in ia]), 0.05, 0.3)
        mid = int(ib[len(ib) // 2])
        pm = poses[mid]
        b = np.concatenate([world(pts(i), between(pm, poses[i])) for i in ib])
        b = b[np.random.default_rng(0).choice(len(b), min(len(b), 3000), replace=False)]
        sr = correlative_search(grid, b, pm, 4.0, np.radians(10.0), 0.1, np.radians(1.0), 0.1)
        off = sr.offsets + (sr.pose - pm)  # every searched pose relative to the map's pose
        at_map = float(sr.scores[int(np.argmin(np.abs(off).sum(axis=1)))])
        peaks = np.nonzero(sr.peaks & (sr.scores > 0.5 * sr.score))[0]
        rivals = [k for k in peaks[np.argsort(-sr.scores[peaks])] if np.hypot(*off[k, :2]) > 0.5][:3]
        rr = refine(grid, b, pm, 0.05, 30)
        d = point_distances(grid, b, rr.pose)
        out.append(
            f"{name}: pass t={lo2:g}-{hi2:g} s ({len(ib)} scans) on pass t={lo:g}-{hi:g} s ({len(ia)} scans): best "
            f"offset from the map's pose ({sr.pose[0] - pm[0]:+.2f}, {sr.pose[1] - pm[1]:+.2f}) m "
            f"{np.degrees(sr.pose[2] - pm[2]):+.1f} deg, score {sr.score:.3f} (at the map's pose {at_map:.3f}); "
            "rivals " + ", ".join(f"({off[k, 0]:+.1f}, {off[k, 1]:+.1f}) m {sr.scores[k]:.3f}" for k in rivals)
            + f"; refined from the map's pose: moved {np.hypot(*(rr.pose[:2] - pm[:2])):.3f} m, "
            f"{100 * rr.inlier_frac:.0f} % of the returns within 0.1 m, median {np.median(d):.3f} m")
    if ref is not None:
        ra = np.nonzero((ref.stamps - first >= a0) & (ref.stamps - first <= a1))[0]
        rb = np.nonzero((ref.stamps - first >= b0) & (ref.stamps - first <= b1))[0]
        if len(ra) and len(rb):
            ours = traj.interpolate(ref.stamps)
            e = np.array([between(between(ref.poses[i], ref.poses[j]), between(ours[i], ours[j]))
                          for i in ra for j in rb])
            et = np.hypot(e[:, 0], e[:, 1])
            out.append(f"{name}: reference vs ours, relative poses between the passes ({len(e)} pairs of reference "
                       f"scans): {et.mean():.3f} m mean, {et.max():.3f} m max, "
                       f"{np.degrees(np.abs(e[:, 2])).mean():.2f} deg mean")
    return out


def pass_offset(name: str, recs: list[ScanRecord], traj: Trajectory, ref: Trajectory, spec: str,
                radius_m: float = 6.0) -> str:
    """Where does the reference put a pass (``NAME=T0,T1``, s after the first scan) relative to the
    other passes nearby, against where our trajectory puts it?  For every reference scan a of the
    pass and b of another pass (more than 30 s apart, within ``radius_m`` in our map): the
    reference's position of a in b's frame minus ours, turned into our map frame with b's heading;
    the mean over the pairs is the pass's offset that the reference sees (a self-check flag of
    that pass should point the same way)."""
    from fgloc.geometry import between

    t0_s, t1_s = (float(v) for v in spec.split("=", 1)[1].split(","))
    first = recs[0].stamp
    t = ref.stamps - first
    ours = traj.interpolate(ref.stamps)
    ia = np.nonzero((t >= t0_s) & (t <= t1_s))[0]
    rows = []
    for i in ia:
        near = (np.abs(t - t[i]) > 30.0) & (np.hypot(ours[:, 0] - ours[i, 0], ours[:, 1] - ours[i, 1]) <= radius_m)
        for j in np.nonzero(near)[0]:
            d = between(ref.poses[j], ref.poses[i])[:2] - between(ours[j], ours[i])[:2]
            c, sn = np.cos(ours[j, 2]), np.sin(ours[j, 2])
            rows.append((c * d[0] - sn * d[1], sn * d[0] + c * d[1]))
    if not rows:
        return f"{name}: pass t={t0_s:g}-{t1_s:g} s: no reference scans of it or of other passes near it"
    r = np.array(rows)
    m = r.mean(axis=0)
    return (f"{name}: pass t={t0_s:g}-{t1_s:g} s ({len(ia)} reference scans, {len(r)} pairs with other passes within "
            f"{radius_m:g} m): reference minus ours, map frame: dx {m[0]:+.3f} +- {r[:, 0].std():.3f} m, "
            f"dy {m[1]:+.3f} +- {r[:, 1].std():.3f} m, |mean| {np.hypot(*m):.3f} m")


def compare_trajectory(name: str, recs: list[ScanRecord], traj: Trajectory, other_path: str,
                       windows: list[str]) -> list[str]:
    """Another trajectory of the same log (``NAME=TUM``, e.g. an older mapper's all-scan poses)
    against this run's, frame-free: the relative pose of every pair of scans (every 5th scan)
    more than 60 s and less than 5 m apart (this run's poses), and of every pair from the two
    windows of each ``--align-passes`` spec of NAME."""
    from fgloc.geometry import between

    other = read_tum(other_path)
    first = recs[0].stamp
    st = traj.stamps[::5]
    st = st[(st >= other.stamps[0]) & (st <= other.stamps[-1])]
    a, b = traj.interpolate(st), other.interpolate(st)

    def diffs(i: np.ndarray, j: np.ndarray) -> np.ndarray:
        e = between(between(b[i], b[j]), between(a[i], a[j]))
        return np.hypot(e[:, 0], e[:, 1])

    i, j = np.triu_indices(len(st), 1)
    keep = (st[j] - st[i] > 60.0) & (np.hypot(a[i, 0] - a[j, 0], a[i, 1] - a[j, 1]) < 5.0)
    e = diffs(i[keep], j[keep])
    out = [f"{name}: {other_path} vs this run, revisits ({len(e)} pairs of scans > 60 s, < 5 m apart): "
           f"{e.mean():.3f} m mean, {e.max():.3f} m max, {(e > 0.3).sum()} pairs > 0.3 m"]
    for spec in windows:
        a0, a1, b0, b1 = (float(v) for v in spec.split("=", 1)[1].split(","))
        ia = np.nonzero((st - first >= a0) & (st - first <= a1))[0]
        ib = np.nonzero((st - first >= b0) & (st - first <= b1))[0]
        if len(ia) and len(ib):
            ii, jj = np.meshgrid(ia, ib, indexing="ij")
            e = diffs(ii.ravel(), jj.ravel())
            out.append(f"{name}: {other_path} vs this run, scans of t={a0:g}-{a1:g} s with t={b0:g}-{b1:g} s "
                       f"({len(e)} pairs): {e.mean():.3f} m mean, {e.max():.3f} m max")
    return out


def map_in_process(name: str, outdir: Path) -> dict:
    """``fgloc map`` on the whole log in a child process: wall time, CPU time (user + system), peak
    RSS (psutil, 20 Hz) and the 1-minute load average at the start (the machine is shared)."""
    import psutil

    # the map command on its own (the same code as ``fgloc map``), so that a half-edited module of
    # another command cannot stop the evaluation
    boot = ("import sys, typer; from fgloc.commands.map import register; app = typer.Typer(); register(app); "
            "app(sys.argv[1:])")
    cmd = [sys.executable, "-c", boot, "map", str(LOGS[name]), "-o", str(outdir), "--no-progress"]
    import os

    load = os.getloadavg()[0]
    t0 = time.perf_counter()
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    proc = psutil.Process(p.pid)
    peak = 0
    cpu = 0.0
    while p.poll() is None:
        try:
            peak = max(peak, proc.memory_info().rss)
            ct = proc.cpu_times()
            cpu = max(cpu, ct.user + ct.system)
        except psutil.Error:
            break
        time.sleep(0.05)
    out, err = p.communicate()
    wall = time.perf_counter() - t0
    if p.returncode != 0:
        raise RuntimeError(f"fgloc map {name} failed: {err.strip()[-400:]}")
    warnings = [ln[len("warning: "):] for ln in err.splitlines() if ln.startswith("warning: ")]
    return {"wall_s": wall, "cpu_s": cpu, "load": load, "peak_rss_mb": peak / 1e6, "stdout": out,
            "warnings": warnings}


def main() -> int:
    import yaml

    from fgloc.eval.relations import read_relations

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=Path("eval_radish"))
    ap.add_argument("--make-excerpts", type=Path, default=None, metavar="DIR",
                    help="only write the test excerpts (data/radish) and exit")
    ap.add_argument("--datasets", nargs="+", default=list(LOGS))
    ap.add_argument("--reference-dir", type=Path, default=None,
                    help="more GMapping-corrected logs (aces-corrected.log.gz, csail-corrected.log.gz)")
    ap.add_argument("--relations", nargs="*", default=[], metavar="NAME=FILE",
                    help="relation files (Kuemmerle et al. 2009) to score against, e.g. aces=aces.relations")
    ap.add_argument("--inject", nargs="*", default=[], metavar="NAME=T0,T1,DX,DY,DEG",
                    help="also self-check NAME's map with the pass between T0 and T1 (s after the first scan) "
                         "moved rigidly by DX, DY (m, map frame) and turned DEG about its centre")
    ap.add_argument("--align-passes", nargs="*", default=[], metavar="NAME=A0,A1,B0,B1",
                    help="do the passes [A0, A1] and [B0, B1] (s after the first scan) agree where the map put "
                         "them? (pass-to-pass search +-4 m, and the reference's relative poses against ours)")
    ap.add_argument("--pass-offset", nargs="*", default=[], metavar="NAME=T0,T1",
                    help="where the reference puts the pass [T0, T1] (s after the first scan) relative to the "
                         "other passes near it, against our trajectory (e.g. a self-check flag's pass)")
    ap.add_argument("--against", nargs="*", default=[], metavar="NAME=TUM",
                    help="another trajectory of the log (e.g. an older mapper's trajectory_scans.tum) against "
                         "this run's, on revisits and on the windows of --align-passes")
    ap.add_argument("--localize", action="store_true", help="also localize a log segment (fgloc run)")
    ap.add_argument("--loc-scans", type=int, default=1500, help="localize the last N scans (within the second half)")
    ap.add_argument("--no-relocalize", action="store_true",
                    help="turn fgloc run's global relocalization off (on by default, as fgloc run)")
    args = ap.parse_args()
    if args.make_excerpts is not None:
        make_excerpts(args.make_excerpts)
        return 0
    refs = dict(REFS)
    if args.reference_dir is not None:
        for k, v in REF_NAMES.items():
            if (args.reference_dir / v).exists():
                refs[k] = args.reference_dir / v
    rel_files = dict(r.split("=", 1) for r in args.relations)
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for name in args.datasets:
        mp = map_in_process(name, out / name)
        mdoc = yaml.safe_load((out / name / "mapping.yaml").read_text())
        cdoc = yaml.safe_load((out / name / "check.yaml").read_text())
        traj = read_tum(out / name / "trajectory.tum")
        row: dict = {"dataset": name, "scans": mdoc["scans"], "keyframes": mdoc["stats"]["keyframes"],
                     "loops": mdoc["stats"]["loops"], "map_s": mp["wall_s"], "rss_mb": mp["peak_rss_mb"],
                     "cpu_s": mp["cpu_s"], "load": mp["load"],
                     "slam_s": mdoc["timings_s"]["slam_s"], "check_s": mdoc["timings_s"]["check_s"],
                     "verdict": cdoc["verdict"], "suspects": cdoc["suspects"], "warnings": mp["warnings"],
                     "png": str(out / name / "map.png")}
        recs, mount = load_records(LOGS[name])
        ref = None
        if name in refs and refs[name].exists():
            ref, info = reference_trajectory(refs[name], recs, mount)
            write_tum(out / name / "reference.tum", ref)
            lo, hi = REL_DT[name]
            rels = relations_from_reference(ref, lo, hi)
            write_relations(out / name / "relations.txt", rels)
            row["ref"] = info
            row["rel"] = evaluate_relations(traj, rels)
        if name in rel_files:
            row["rel_file"] = evaluate_relations(traj, read_relations(rel_files[name]))
        for spec in args.align_passes:
            if spec.split("=", 1)[0] == name:
                row.setdefault("aligned", []).extend(align_passes(name, recs, mount, traj, ref, spec))
        for spec in args.pass_offset:
            if spec.split("=", 1)[0] == name and ref is not None:
                row.setdefault("aligned", []).append(pass_offset(name, recs, traj, ref, spec))
        for spec in args.against:
            if spec.split("=", 1)[0] == name:
                wins = [w for w in args.align_passes if w.split("=", 1)[0] == name]
                row.setdefault("aligned", []).extend(compare_trajectory(name, recs, traj, spec.split("=", 1)[1], wins))
        for spec in args.inject:
            if spec.split("=", 1)[0] == name:
                row.setdefault("injected", []).append(injected_check(name, recs, mount, traj, out, spec))
        if args.localize:
            try:
                cfg_path = None
                if args.no_relocalize:
                    cfg_path = out / "run-no-relocalize.yaml"
                    cfg_path.write_text("pipeline:\n  relocalize_after: 1000000\n")
                row["loc"] = localize(name, recs, mount, traj, out, ref if name in REFS else None, args.loc_scans,
                                      cfg_path, map_whole_log=name in MAP_WHOLE_LOG)
            except Exception as e:  # report, keep going
                row["loc_error"] = f"{e.__class__.__name__}: {e}"[:300]
        rows.append(row)
        print(f"done {name}: {mp['wall_s']:.1f} s, {mp['peak_rss_mb']:.0f} MB; {cdoc['verdict']}", file=sys.stderr)
    _print_table(rows)
    return 0


def _fmt_rel(r: dict | None) -> str:
    if not r or not r.get("n"):
        return "-"
    return (f"{r['trans_mean']:.3f} +- {r['trans_std']:.3f} m, {r['rot_mean_deg']:.2f} +- {r['rot_std_deg']:.2f} deg"
            f" (n={r['n']})")


def _print_table(rows: list[dict]) -> None:
    print("| log | scans | keyframes | loops | map time (wall) | CPU (user+sys) | load | SLAM (wall) "
          "| self-check (wall) | peak RSS | relation error vs GMapping-corrected | self-check verdict |")
    print("|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|---|---|")
    for r in rows:
        rel = _fmt_rel(r.get("rel"))
        if r.get("ref"):
            rel += f" [{r['ref']['matched']}/{r['ref']['ref_scans']} ref scans]"
        if r.get("rel_file"):
            rel += f"; relation file: {_fmt_rel(r['rel_file'])}"
        verdict = r["verdict"].replace("map-check: ", "")
        print(f"| {r['dataset']} | {r['scans']} | {r['keyframes']} | {r['loops']} | {r['map_s']:.1f} s "
              f"| {r['cpu_s']:.1f} s | {r['load']:.1f} | {r['slam_s']:.1f} s | {r['check_s']:.1f} s "
              f"| {r['rss_mb']:.0f} MB | {rel} | {verdict} |")
    for r in rows:
        for s in r["suspects"]:
            print(f"- {r['dataset']}: {s}")
        for s in r.get("injected", []):
            print(f"- {r['dataset']} (injected): {s}")
        for s in r.get("aligned", []):
            print(f"- {s}")
        for w in r["warnings"]:
            print(f"- {r['dataset']} (warning): {w}")
    locs = [r for r in rows if r.get("loc") or r.get("loc_error")]
    if locs:
        print()
        print("| log | localization of a log segment (map from the other half; aces: whole log) |")
        print("|---|---|")
        for r in locs:
            loc = r.get("loc")
            if not loc:
                print(f"| {r['dataset']} | {r['loc_error']} |")
                continue
            print(f"| {r['dataset']} | map: {loc['map']}; {loc['loc_scans']} scans from #{loc['seg_start']}, "
                  f"{loc['loc_wall_s']:.0f} s; vs SLAM RMSE {loc['vs_slam_rmse_m']:.3f} m / "
                  f"{loc['vs_slam_heading_deg']:.2f} deg; relations vs reference {_fmt_rel(loc.get('relations'))} |")


if __name__ == "__main__":
    sys.exit(main())
