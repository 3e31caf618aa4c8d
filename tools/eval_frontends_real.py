"""Honest fixes on real maps and in a changed world (issue 13 items 4, 5): one table.

    python tools/eval_frontends_real.py [--logs intel fr079 aces mit-csail] [--scans 1000] [--start S]
                                        [--cache DIR] [--seeds 0 1] [--skip-sim] [--skip-real]
                                        [--backends smoother ekf] [--carmen-odometry log|laser]

Real logs (``../shared/data/radish``): the whole log is mapped once by ``fgloc.mapping`` (GraphSlam;
cached under ``--cache``), which gives every scan a SLAM pose in one map frame.  A segment of
``--scans`` scans is chosen where the robot revisits places (the most scans within 2 m of a keyframe
outside the segment's time window; ties: the later segment; ``--start S``: the one from scan S);
the map it is localized on is built from the SLAM keyframes *outside* the segment's time window
(+-30 s), in the same frame: a different pass through the building, no frame hand-over.  Then
``Localizer`` (default config, raw CARMEN odometry, from the SLAM pose at the segment's first scan)
runs over the segment's odometry and scans in time order, and the table gives

* position / heading RMSE of the smoothed trajectory vs SLAM,
* the front-end fixes' NEES vs SLAM: mean of ``e^T P^-1 e`` over (x, y, yaw) (dimension 3 when the
  covariance is honest), its median, and the per-axis means ``e_i^2 / P_ii`` (1 each),
* fixes / no-fix counts,
* the same RMSE over the segment's mapped part (the SLAM pose within ``COVER_RADIUS_M`` of a map
  keyframe: the rule that chose the segment) and its unmapped part, and the localizer's lost events
  (and seconds lost), re-acquisitions after dead reckoning, fixes held back then, and dead-reckoned
  (unmapped) scans,

each with the map's accuracy as ``--map-accuracy`` says (the native matcher's registration floor,
see ``fgloc.frontends.native``): ``none`` undeclared (no floor),
``measured`` what ``fgloc map`` writes (the self-check of the whole log's SLAM: the passes'
registration and the raster), or metres (0: no floor).

SLAM is a reference, not ground truth (its relations are ~3 cm / 0.5 deg off GMapping's): the NEES
counts its error too.

Changed world (simulator): the paper hall with a quarter of the furniture moved, four pieces gone,
twelve pallets and two closed doors (the scenario of ``tests/frontends/test_changed_world.py``;
``--hard``: plus 28 pallets 0.9 m beside the path), localized on the old map by each back-end with
the native front-end: RMSE and max error against the truth, the fixes' NEES.
"""

from __future__ import annotations

import argparse
import pickle
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data" / "radish"
LOGS = {
    "intel": DATA / "intel.clf.bz2",
    "fr079": DATA / "fr079.clf.bz2",
    "aces": DATA / "aces.clf.bz2",
    "mit-csail": DATA / "mit-csail.clf.bz2",
    "fr-clinic": DATA / "fr-clinic_robotlaser.clf.bz2",
}
WINDOW_MARGIN_S = 30.0  # the map leaves out the keyframes this close in time to the segment
COVER_RADIUS_M = 2.0  # a segment scan within this of a map keyframe is "mapped"
REF_AGREE_DEG = 0.5  # where SLAM and GMapping agree this well in heading, the reference is taken as settled
PARTLY_UNMAPPED = 0.1  # a fix whose scan sends this share of its beams into unmapped space (breakdown only)


def slam_of(name: str, cache: Path):
    """(records, mount, SlamResult) of the whole log, the SLAM result cached on disk."""
    from fgloc.mapping.build import load_records
    from fgloc.mapping.slam import MapperConfig, run_slam

    recs, mount = load_records(LOGS[name])
    f = cache / f"{name}_slam.pkl"
    if f.exists():
        slam = pickle.loads(f.read_bytes())
    else:
        t0 = time.perf_counter()
        slam = run_slam(recs, mount, MapperConfig())
        print(f"{name}: SLAM over {len(recs)} scans in {time.perf_counter() - t0:.0f} s", file=sys.stderr)
        cache.mkdir(parents=True, exist_ok=True)
        f.write_bytes(pickle.dumps(slam))
    return recs, mount, slam


def map_keyframes(recs, slam, s0: int, s1: int) -> np.ndarray:
    """Which SLAM keyframes the map of segment ``s0..s1`` is built from: those outside its time
    window (+- ``WINDOW_MARGIN_S``)."""
    kf_t = np.array([k.stamp for k in slam.keyframes])
    return np.asarray((kf_t < recs[s0].stamp - WINDOW_MARGIN_S) | (kf_t > recs[s1].stamp + WINDOW_MARGIN_S))


def segment_and_map(recs, mount, slam, n_scans: int, start: int | None = None):
    """The best-covered ``n_scans`` segment (or the one from scan ``start``) and the map of the
    keyframes outside it."""
    from fgloc.eval.metrics import within_radius
    from fgloc.mapping.slam import build_occupancy

    stamps = np.array([r.stamp for r in recs])
    traj = slam.scan_trajectory
    poses = traj.interpolate(stamps)
    best, best_cov = 0, -1.0
    starts = range(0, max(len(recs) - n_scans, 0) + 1, 100) if start is None else [start]
    for s0 in starts:
        s1 = min(s0 + n_scans, len(recs)) - 1
        out = map_keyframes(recs, slam, s0, s1)
        if out.sum() < 10 and start is None:
            continue
        cov = float(within_radius(poses[s0:s1 + 1, :2], slam.keyframe_poses[out, :2], COVER_RADIUS_M).mean())
        if cov >= best_cov - 1e-9:  # ties: the later segment
            best, best_cov = s0, cov
    s0, s1 = best, min(best + n_scans, len(recs)) - 1
    out = map_keyframes(recs, slam, s0, s1)
    sub = replace(slam, keyframes=[k for k, o in zip(slam.keyframes, out, strict=True) if o],
                  keyframe_poses=slam.keyframe_poses[out])
    occ = build_occupancy(sub, recs, mount)
    return s0, s1, best_cov, occ


def measured_accuracy(name: str, cache: Path) -> float:
    """The ``accuracy_m`` ``fgloc map`` writes for the whole log (self-check registration + raster), cached."""
    from fgloc.mapping.build import loop_infos
    from fgloc.mapping.selfcheck import check_consistency, map_accuracy_m
    from fgloc.mapping.slam import MapperConfig

    f = cache / f"{name}_accuracy.txt"
    if f.exists():
        return float(f.read_text())
    recs, mount, slam = slam_of(name, cache)
    chk = check_consistency(recs, np.asarray(mount.pose), slam.scan_trajectory, loop_infos(slam))
    acc = round(map_accuracy_m(chk.registration_m, MapperConfig().resolution), 4)
    print(f"{name}: passes register to {chk.registration_m:.4f} m / {chk.registration_deg:.3f} deg "
          f"({chk.registration_n} scans): accuracy_m {acc}", file=sys.stderr)
    f.write_text(str(acc))
    return acc


GMAPPING = {"intel": DATA.parent / "radish-reference" / "intel-corrected.log.gz",
            "fr079": DATA.parent / "radish-reference" / "freiburg-079-corrected.log.gz"}


def reference_floor(name: str, recs, mount, slam, s0: int, s1: int, gmapping_dir: Path | None,
                    est=None) -> dict:
    """How far the SLAM reference itself is from GMapping's over the segment: heading (and position)
    RMS after the rigid 2-D alignment that fits best (the frames differ), on the scans both have.
    The heading error of localization against SLAM cannot be measured below this.  With ``est`` (the
    localizer's trajectory), its heading RMSE at the keyframes GMapping also has: against SLAM,
    against GMapping (rotated by the same alignment), and against SLAM where the two references
    agree within ``REF_AGREE_DEG``."""
    path = GMAPPING.get(name)
    if gmapping_dir is not None and not (path and path.exists()):
        path = gmapping_dir / {"aces": "aces-corrected.log.gz", "mit-csail": "csail-corrected.log.gz"}.get(name, "")
    if path is None or not path.is_file():
        return {}
    sys.path.insert(0, str(REPO / "tools"))
    from eval_radish import reference_trajectory  # type: ignore[import-not-found]

    from fgloc.eval.metrics import three_cornered_hat
    from fgloc.geometry import wrap_angle

    ref, _ = reference_trajectory(path, recs, mount)
    m = (ref.stamps >= recs[s0].stamp) & (ref.stamps <= recs[s1].stamp)
    if m.sum() < 5:
        return {}
    g = ref.poses[m]
    s = slam.scan_trajectory.interpolate(ref.stamps[m])
    dth = float(np.angle(np.mean(np.exp(1j * wrap_angle(s[:, 2] - g[:, 2])))))
    c, sn = np.cos(dth), np.sin(dth)
    gx = np.column_stack([c * g[:, 0] - sn * g[:, 1], sn * g[:, 0] + c * g[:, 1]])
    gx += (s[:, :2] - gx).mean(axis=0)
    e_yaw = np.degrees(wrap_angle(g[:, 2] + dth - s[:, 2]))
    out = {"gm_n": int(m.sum()), "gm_rmse_m": float(np.sqrt(np.mean(np.sum((gx - s[:, :2]) ** 2, axis=1)))),
           "gm_rmse_deg": float(np.sqrt(np.mean(e_yaw**2))), "gm_median_abs_deg": float(np.median(np.abs(e_yaw)))}
    if est is not None and len(est.stamps):
        # the keyframes at the scans GMapping has (stamps within 1 ms; the trajectory is not interpolated)
        gt = ref.stamps[m]
        j = np.clip(np.searchsorted(est.stamps, gt), 1, len(est.stamps) - 1)
        j = np.where(np.abs(est.stamps[j - 1] - gt) < np.abs(est.stamps[j] - gt), j - 1, j)
        hit = np.abs(est.stamps[j] - gt) < 1e-3
        if hit.sum() >= 5:
            y = est.poses[j[hit], 2]
            e_s = np.degrees(wrap_angle(y - s[hit, 2]))
            e_g = np.degrees(wrap_angle(y - g[hit, 2] - dth))
            agree = np.abs(e_yaw[hit]) <= REF_AGREE_DEG
            # the three-cornered hat over these keyframes: the localizer's, SLAM's and GMapping's own
            # heading error (deg, signed root of the variance: negative = errors not independent)
            hat = three_cornered_hat(float(np.mean(e_s**2)), float(np.mean(e_g**2)),
                                     float(np.mean(e_yaw[hit] ** 2)))
            out.update({"gm_kf_n": int(hit.sum()), "est_vs_slam_deg": float(np.sqrt(np.mean(e_s**2))),
                        "est_vs_gm_deg": float(np.sqrt(np.mean(e_g**2))), "agree_n": int(agree.sum()),
                        "slam_vs_gm_kf_deg": float(np.sqrt(np.mean(e_yaw[hit] ** 2))),
                        "est_vs_slam_agree_deg": float(np.sqrt(np.mean(e_s[agree] ** 2))) if agree.any()
                        else float("nan"),
                        **{f"hat_{k}_deg": float(np.sign(v) * np.sqrt(abs(v)))
                           for k, v in zip(("est", "slam", "gm"), hat, strict=True)}})
    return out


def fix_errors(fixes, ref) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The fixes' stamps, errors ``[ex, ey, eyaw]`` against ``ref`` (interpolated at their stamps)
    and covariances."""
    from fgloc.geometry import wrap_angle

    st = np.array([f.stamp for f in fixes], dtype=float)
    P = np.array([f.cov for f in fixes], dtype=float).reshape(-1, 3, 3)
    e = np.array([f.pose for f in fixes], dtype=float).reshape(-1, 3) - ref.interpolate(st).reshape(-1, 3)
    e[:, 2] = wrap_angle(e[:, 2])
    return st, e, P


def nees_of(fixes, ref) -> dict:
    from fgloc.eval.metrics import nees_summary

    if not fixes:
        return {"n": 0}
    _, e, P = fix_errors(fixes, ref)
    s = nees_summary(e, P)
    s["fix_rmse_m"], s["fix_rmse_deg"] = s.pop("rmse_m"), s.pop("rmse_deg")
    return s


def nees_breakdown(fixes, ref, kf_stamps: np.ndarray, shares: np.ndarray) -> dict:
    """The fixes' NEES beside the full figure, never instead of it: at the SLAM keyframes' scans
    (the graph's own poses) and between them (a keyframe's pose plus SLAM's tracked offset: is the
    reference's interpolation part of the NEES?), and for the fixes of scans with at least
    ``PARTLY_UNMAPPED`` of their beams ending in space the map does not have (cast from the SLAM pose,
    ``fgloc.localization.coverage.unmapped_share``) and the rest."""
    from fgloc.eval.metrics import nees_summary

    if not fixes:
        return {}
    st, e, P = fix_errors(fixes, ref)
    kf = np.sort(np.asarray(kf_stamps, dtype=float))
    j = np.clip(np.searchsorted(kf, st), 1, max(len(kf) - 1, 1)) if len(kf) else np.zeros(len(st), dtype=int)
    at_kf = (np.minimum(np.abs(kf[j] - st), np.abs(kf[j - 1] - st)) < 1e-6) if len(kf) > 1 else \
        np.zeros(len(st), dtype=bool)
    part = np.asarray(shares, dtype=float) >= PARTLY_UNMAPPED
    return {"nees_parts": {"keyframes": nees_summary(e[at_kf], P[at_kf]),
                           "between": nees_summary(e[~at_kf], P[~at_kf]),
                           "partly_unmapped": nees_summary(e[part], P[part]),
                           "mapped": nees_summary(e[~part], P[~part])}}


def run_real(name: str, cache: Path, n_scans: int, backend: str, accuracy: float | None,
             gmapping_dir: Path | None = None, overrides: dict | None = None, start: int | None = None,
             carmen_odometry: str = "log") -> dict:
    from fgloc.config import load_config
    from fgloc.eval.metrics import split_errors, within_radius
    from fgloc.geometry import wrap_angle
    from fgloc.io import open_log
    from fgloc.localization import Localizer, Session
    from fgloc.localization.coverage import unmapped_share
    from fgloc.mapping.source import open_log_scan_stamps
    from fgloc.types import LaserScan, Trajectory

    recs, mount, slam = slam_of(name, cache)
    key = cache / (f"{name}_{n_scans}_map.pkl" if start is None else f"{name}_{n_scans}_from{start}_map.pkl")
    if start is not None and not 0 <= start < len(recs):
        print(f"fgloc: error: {LOGS[name]}: --start {start} outside its {len(recs)} scans", file=sys.stderr)
        raise SystemExit(2)
    if key.exists():
        s0, s1, cov, occ = pickle.loads(key.read_bytes())
    else:
        s0, s1, cov, occ = segment_and_map(recs, mount, slam, n_scans, start)
        key.write_bytes(pickle.dumps((s0, s1, cov, occ)))
    occ.accuracy_m = accuracy  # what the map declares (None: undeclared)
    t0, t1 = recs[s0].stamp, recs[s1].stamp
    # read as `fgloc run` reads the log (open_log: log-time order, CARMEN's out-of-place stamps repaired)
    msgs = [(topic, m) for topic, m in open_log(LOGS[name]).messages(["/odom", "/scan"])
            if t0 - 1e-6 <= m.stamp <= t1 + 1e-6]  # type: ignore[attr-defined]
    if carmen_odometry == "laser":
        msgs = sorted([(tp, m) for tp, m in msgs if tp != "/odom"] + laser_odometry(name, recs, t0, t1),
                      key=lambda tm: tm[1].stamp)  # type: ignore[attr-defined]
    # the SLAM poses stamped as the localizer sees the same scans (the mapper keeps the file's
    # stamps, open_log repairs a CARMEN line's out-of-place stamp: intel 434 scans, up to 1.7 s)
    own = np.array([r.stamp for r in recs])
    scan_t = open_log_scan_stamps(LOGS[name], recs)
    ref = Trajectory.from_unsorted(scan_t, slam.scan_trajectory.interpolate(own))
    p0 = ref.interpolate(np.array([t0]))[0]
    loc = Localizer(occ, mount, backend, "native", initial_pose=p0, config=load_config(overrides=overrides or None))
    tw = time.perf_counter()
    est = Session(loc).run(msgs)
    wall = time.perf_counter() - tw
    inside = (est.stamps >= ref.stamps[0]) & (est.stamps <= ref.stamps[-1])
    gt = ref.interpolate(est.stamps[inside])
    e_xy = np.hypot(*(est.poses[inside, :2] - gt[:, :2]).T)
    e_yaw_rad = np.asarray(wrap_angle(est.poses[inside, 2] - gt[:, 2]), dtype=float)
    e_yaw = np.degrees(e_yaw_rad)
    # mapped / unmapped by the segment's own rule: the SLAM pose within COVER_RADIUS_M of a map keyframe
    mapped = within_radius(gt[:, :2], slam.keyframe_poses[map_keyframes(recs, slam, s0, s1), :2], COVER_RADIUS_M)
    split = split_errors(e_xy, e_yaw_rad, mapped)
    res = {"log": name, "backend": backend, "accuracy": "-" if accuracy is None else f"{accuracy:.3f}",
           "seg": f"{s0}-{s1}", "coverage": cov,
           "rmse_m": float(np.sqrt(np.mean(e_xy**2))), "max_m": float(e_xy.max()),
           "rmse_deg": float(np.sqrt(np.mean(e_yaw**2))), "fixes": loc.stats["fixes"],
           "no_fix": loc.stats["no_fix"], "reloc": loc.stats["relocalizations"], "wall_s": wall,
           "split": split, "lost_events": int(loc.stats.get("lost_events", 0)),
           "reacquisitions": int(loc.stats.get("reacquisitions", 0)),
           "unmapped_scans": int(loc.stats.get("unmapped_scans", 0)),
           "held_fixes": int(loc.stats.get("held_fixes", 0)), "lost_s": float(loc.stats.get("lost_s", 0.0)),
           "odom_clock": loc.stats.get("odom_clock")}
    res.update(heading_views(est, ref, t0, t1))
    res.update(odometry_timing(msgs, ref, t0, t1))
    res.update(carried_timing(name, recs, s0, s1, msgs))
    res.update(nees_of(loc.fixes, ref))
    pos = {r.index: i for i, r in enumerate(recs)}
    kf_t = np.array([scan_t[pos[k.scan_index]] for k in slam.keyframes if k.scan_index in pos])
    scans = {float(m.stamp): m for topic, m in msgs if topic == "/scan" and isinstance(m, LaserScan)}
    shares = np.array([unmapped_share(occ, mount, scans[f.stamp], ref.interpolate(np.array([f.stamp]))[0])
                       if f.stamp in scans else 0.0 for f in loc.fixes])
    res.update(nees_breakdown(loc.fixes, ref, kf_t, shares))
    res.update(reference_floor(name, recs, mount, slam, s0, s1, gmapping_dir, est))
    return res


def heading_views(est, ref, t0: float, t1: float) -> dict:
    """The heading error two more ways: after removing its mean over the segment (the best rigid
    alignment's rotation: what is left when the map of the other passes is turned against this
    pass as a whole) and over relations 1-2 s apart, as relation benchmarks measure (RMS)."""
    from fgloc.eval.relations import relation_errors, relations_from_reference
    from fgloc.geometry import wrap_angle

    inside = (est.stamps >= max(ref.stamps[0], t0)) & (est.stamps <= min(ref.stamps[-1], t1))
    if inside.sum() < 5:
        return {}
    e = wrap_angle(est.poses[inside, 2] - ref.interpolate(est.stamps[inside])[:, 2])
    mean = float(np.angle(np.mean(np.exp(1j * e))))
    m = (ref.stamps >= max(t0, est.stamps[0])) & (ref.stamps <= min(t1, est.stamps[-1]))
    seg = type(ref)(ref.stamps[m], ref.poses[m])
    at_ref = type(ref)(seg.stamps, est.interpolate(seg.stamps))  # both at the scans' stamps
    _, er, _ = relation_errors(at_ref, relations_from_reference(seg, 1.0, 2.0, loop_closures=False))
    a = np.sort(np.abs(np.degrees(e)))
    return {"yaw_mean_deg": float(np.degrees(mean)), "yaw_median_abs_deg": float(np.median(a)),
            "yaw_rmse_98_deg": float(np.sqrt(np.mean(a[: max(int(0.98 * len(a)), 1)] ** 2))),
            "rmse_deg_aligned": float(np.degrees(np.sqrt(np.mean(wrap_angle(e - mean) ** 2)))),
            "rel_rot_rms_deg": float(np.degrees(np.sqrt(np.mean(er**2)))) if len(er) else float("nan"),
            "rel_n": int(len(er))}


def odometry_timing(msgs, ref, t0: float, t1: float, pair_s: float = 0.5) -> dict:
    """How the odometry's clock sits against the scans': the odometry's yaw change over pairs of scans
    ``pair_s`` apart vs the SLAM reference's, RMS (deg) with the odometry read at the scans' stamps and
    at the stamps shifted by the best ``shift`` (s, -0.3..0.3 in 0.02 s steps; negative: the odometry
    matches the scan stamped ``t`` at ``t + shift``, the scans are stamped late against it)."""
    from fgloc.geometry import wrap_angle

    od = [(m.stamp, m.pose[2]) for topic, m in msgs if topic == "/odom" and getattr(m, "pose", None) is not None]
    if len(od) < 10:
        return {}
    a = np.array(sorted(od))
    ot, oy = a[:, 0], np.unwrap(a[:, 1])
    m = (ref.stamps >= t0) & (ref.stamps <= t1)
    rt, ry = ref.stamps[m], np.unwrap(ref.poses[m, 2])
    i = np.arange(len(rt))
    j = np.searchsorted(rt, rt + pair_s)
    ok = (j < len(rt))
    i, j = i[ok], j[ok]
    ok = rt[j] - rt[i] < 2 * pair_s
    i, j = i[ok], j[ok]
    if len(i) < 10:
        return {}
    d_ref = ry[j] - ry[i]

    def rms(shift: float) -> float:
        d = np.interp(rt[j] + shift, ot, oy) - np.interp(rt[i] + shift, ot, oy)
        return float(np.degrees(np.sqrt(np.mean(wrap_angle(d - d_ref) ** 2))))

    shifts = np.round(np.arange(-0.30, 0.3001, 0.02), 2)
    r = [rms(float(s)) for s in shifts]
    k = int(np.argmin(r))
    return {"odo_rms0_deg": rms(0.0), "odo_shift_s": float(shifts[k]), "odo_rms_shift_deg": r[k]}


def carried_poses(name: str) -> tuple[list[np.ndarray | None], bool]:
    """The odometry pose each (front) laser line of a CARMEN log carries, in scan order (a record's
    ``index``), and whether the log's odometry is taken from them (no ODOM lines)."""
    from fgloc.io.carmen import CarmenReader

    reader = CarmenReader(LOGS[name])
    carried: list[np.ndarray | None] = []
    for topic, m in reader:
        if topic == "/scan" and "rear" not in m.frame_id:  # type: ignore[attr-defined]
            p = reader.last_laser_pose
            carried.append(None if p is None else np.asarray(p, dtype=float).copy())
    return carried, bool(reader.stats.get("odom_from_laser"))


def laser_odometry(name: str, recs, t0: float, t1: float) -> list:
    """``/odom`` messages from the poses the laser lines carry, each stamped 1 us before its scan as
    ``open_log`` stamps it (pose-derived twist): an experiment (``--carmen-odometry laser``), not what
    ``fgloc run`` reads from a log with ODOM lines."""
    from fgloc.geometry import between
    from fgloc.mapping.source import open_log_scan_stamps
    from fgloc.types import Odometry

    carried, _ = carried_poses(name)
    stamps = open_log_scan_stamps(LOGS[name], recs)
    pts = sorted((float(t), carried[r.index]) for r, t in zip(recs, stamps, strict=True)
                 if r.index < len(carried) and carried[r.index] is not None and t0 - 1e-6 <= t <= t1 + 1e-6)
    out: list = []
    prev: tuple[float, np.ndarray] | None = None
    for t, p in pts:
        if prev is not None and t <= prev[0]:
            continue
        tw = np.zeros(3) if prev is None else between(prev[1], p) / (t - prev[0])
        out.append(("/odom", Odometry(stamp=t - 1e-6, twist=tw, pose=p.copy())))
        prev = (t, p)
    return out


def carried_timing(name: str, recs, s0: int, s1: int, msgs, window_s: float = 0.5) -> dict:
    """When each segment scan was taken on the odometry's clock, by the odometry pose its CARMEN laser
    line carries (``FLASER ... odom_x odom_y odom_theta``: the robot's odometry when the scan was
    logged; ``fgloc.io.carmen`` reads it only for the mount, the stamp repair and, in a log without
    ODOM lines, as the odometry): the time ``t'`` within ``+-window_s`` of the scan's stamp ``t`` at
    which the log's odometry (as ``open_log`` stamps it) passes closest to that pose (5 ms grid, metres
    plus 0.5 m per radian).  Counted where it passes within 1 cm / 0.6 deg while moving (0.05 m/s or
    5 deg/s there: the timing is observable); ``t' - t`` negative: the scan's pose is the odometry's
    of before its stamp.  Empty for a log without ODOM lines (its odometry is the carried poses)."""
    from fgloc.geometry import wrap_angle
    from fgloc.mapping.source import open_log_scan_stamps

    carried, from_laser = carried_poses(name)
    if from_laser:
        return {}
    seg = recs[s0:s1 + 1]
    stamps = open_log_scan_stamps(LOGS[name], seg)
    od = sorted((float(m.stamp), *np.asarray(m.pose, dtype=float)) for topic, m in msgs
                if topic == "/odom" and getattr(m, "pose", None) is not None)
    if len(od) < 10:
        return {}
    a = np.array(od)
    ot, ox, oy, oth = a[:, 0], a[:, 1], a[:, 2], np.unwrap(a[:, 3])
    grid = np.arange(-window_s, window_s + 1e-9, 0.005)
    dts = []
    for r, t in zip(seg, stamps, strict=True):
        c = carried[r.index] if r.index < len(carried) else None
        if c is None or t - window_s < ot[0] or t + window_s > ot[-1]:
            continue
        tg = t + grid
        gx, gy, gth = np.interp(tg, ot, ox), np.interp(tg, ot, oy), np.interp(tg, ot, oth)
        d_xy = np.hypot(gx - c[0], gy - c[1])
        d_th = np.abs(wrap_angle(gth - c[2]))
        k = int(np.argmin(d_xy + 0.5 * d_th))
        if d_xy[k] > 0.01 or d_th[k] > np.radians(0.6) or k in (0, len(grid) - 1):
            continue
        k0, k1 = max(k - 2, 0), min(k + 2, len(grid) - 1)
        dt = tg[k1] - tg[k0]
        speed = np.hypot(gx[k1] - gx[k0], gy[k1] - gy[k0]) / dt
        rate = abs(gth[k1] - gth[k0]) / dt
        if speed >= 0.05 or rate >= np.radians(5.0):
            dts.append(float(grid[k]))
    if not dts:
        return {}
    d = np.array(dts)
    return {"carried_n": len(d), "carried_median_s": float(np.median(d)),
            "carried_p90_abs_s": float(np.percentile(np.abs(d), 90)),
            "carried_over_50ms": int(np.count_nonzero(np.abs(d) > 0.05)),
            "carried_over_150ms": int(np.count_nonzero(np.abs(d) > 0.15))}


def changed_world(hard: bool) -> dict:
    """The changed-world scenario of tests/frontends/test_changed_world.py; ``hard``: plus a 0.6 m
    pallet every 2.5 m along the whole route, 0.9 m beside the path, alternating sides."""
    import copy

    sys.path.insert(0, str(REPO / "tests" / "frontends"))
    from test_changed_world import CHANGED_WORLD, _static  # type: ignore[import-not-found]

    sc = copy.deepcopy(CHANGED_WORLD)
    if hard:
        sc["name"] = "changed_world_hard"
        route = [[2.5, 3.0], [27.5, 3.0], [27.5, 17.0], [2.5, 17.0], [2.5, 3.0]]  # the paper route
        for (x0, y0), (x1, y1) in zip(route[:-1], route[1:], strict=True):
            length = float(np.hypot(x1 - x0, y1 - y0))
            d = np.array([x1 - x0, y1 - y0]) / length
            nrm = np.array([-d[1], d[0]])
            for k, along in enumerate(np.arange(2.0, length - 1.5, 2.5)):
                p = np.array([x0, y0]) + along * d + (0.9 if k % 2 else -0.9) * nrm
                sc["faults"]["moving_obstacles"].append(_static(float(p[0]), float(p[1]), 0.3))
    return sc


def run_changed_world(seed: int, backend: str, cache: Path, hard: bool = False) -> dict:
    from fgloc.config import load_config
    from fgloc.geometry import wrap_angle
    from fgloc.localization import Localizer, Session

    f = cache / f"changed_world{'_hard' if hard else ''}_{seed}.pkl"
    if f.exists():
        sim = pickle.loads(f.read_bytes())
    else:
        from fgloc.sim import run_scenario

        sim = run_scenario(changed_world(hard), seed=seed)
        cache.mkdir(parents=True, exist_ok=True)
        f.write_bytes(pickle.dumps(sim))
    msgs = [(t, m) for t, m in sim.messages if t != "/ground_truth"]
    loc = Localizer(sim.map, sim.laser_mount, backend, "native", initial_pose=sim.ground_truth.poses[0],
                    config=load_config())
    est = Session(loc).run(msgs)
    gt = sim.ground_truth.interpolate(est.stamps)
    e = np.hypot(est.poses[:, 0] - gt[:, 0], est.poses[:, 1] - gt[:, 1])
    yaw = np.degrees(wrap_angle(est.poses[:, 2] - gt[:, 2]))
    res = {"log": f"changed world{' + pallets' if hard else ''} s{seed}", "backend": backend,
           "rmse_m": float(np.sqrt(np.mean(e**2))),
           "max_m": float(e.max()), "p99_m": float(np.percentile(e, 99)),
           "rmse_deg": float(np.sqrt(np.mean(yaw**2))), "fixes": loc.stats["fixes"], "no_fix": loc.stats["no_fix"],
           "reloc": loc.stats["relocalizations"]}
    res.update(nees_of(loc.fixes, sim.ground_truth))
    return res


def _f(r: dict, k: str, fmt: str) -> str:
    return format(r[k], fmt) if k in r else "-"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--logs", nargs="+", default=["intel", "fr079", "aces", "mit-csail"], choices=list(LOGS))
    ap.add_argument("--scans", type=int, default=1000, help="segment length (scans)")
    ap.add_argument("--start", type=int, default=None,
                    help="first scan of the segment (default: the best-covered segment, see above)")
    ap.add_argument("--cache", type=Path, default=Path("eval_frontends_real"), help="SLAM results, maps, sims")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0], help="changed-world seeds")
    ap.add_argument("--backends", nargs="+", default=["smoother", "ekf"])
    ap.add_argument("--real-backends", nargs="+", default=["smoother"])
    ap.add_argument("--map-accuracy", nargs="+", default=["none", "measured"],
                    help="the real maps' declared accuracy_m per run: none (undeclared), measured (as fgloc map "
                         "writes it), half-cell, or metres")
    ap.add_argument("--gmapping-dir", type=Path, default=None,
                    help="folder with aces-corrected.log.gz / csail-corrected.log.gz (intel, fr079: the shared data)")
    ap.add_argument("--set", nargs="*", default=[], metavar="SECTION.KEY=VALUE",
                    help="configuration overrides for the real-log runs (YAML values), e.g. smoother.adapt_noise=false")
    ap.add_argument("--carmen-odometry", choices=["log", "laser"], default="log",
                    help="laser: an experiment, the real logs' odometry taken from the poses their laser lines "
                         "carry, stamped as the scans (log: as fgloc run reads it)")
    ap.add_argument("--skip-sim", action="store_true")
    ap.add_argument("--hard", action="store_true", help="also the changed world with 28 more pallets along the path")
    ap.add_argument("--skip-real", action="store_true")
    args = ap.parse_args()
    args.cache.mkdir(parents=True, exist_ok=True)
    rows: list[dict] = []
    overrides: dict = {}
    for item in args.set:
        import yaml

        key, _, val = item.partition("=")
        sec, _, opt = key.partition(".")
        overrides.setdefault(sec, {})[opt] = yaml.safe_load(val)
    if not args.skip_real:
        for name in args.logs:
            if not LOGS[name].exists():
                print(f"{name}: {LOGS[name]} absent, skipped", file=sys.stderr)
                continue
            for be in args.real_backends:
                for acc_s in args.map_accuracy:
                    acc = (None if acc_s == "none" else 0.025 if acc_s == "half-cell"
                           else measured_accuracy(name, args.cache) if acc_s == "measured" else float(acc_s))
                    rows.append(run_real(name, args.cache, args.scans, be, acc, args.gmapping_dir, overrides,
                                         args.start, args.carmen_odometry))
                    print(f"done {name} {be} accuracy {acc_s}", file=sys.stderr)
    if not args.skip_sim:
        for seed in args.seeds:
            for hard in (False, True) if args.hard else (False,):
                for be in args.backends:
                    rows.append(run_changed_world(seed, be, args.cache, hard))
                    print(f"done changed world seed {seed} {be} hard={hard}", file=sys.stderr)
    print("| run | back-end | map accuracy_m | segment | pos RMSE m | max m | heading RMSE deg | fix RMSE m / deg | "
          "fix sigma m / deg (median) | NEES mean (median) | NEES x / y / yaw | fixes / no fix / reloc |")
    print("|---|---|--:|---|--:|--:|--:|--:|--:|--:|--:|--:|")
    for r in rows:
        seg = f"{r['seg']} ({100 * r['coverage']:.0f} % mapped)" if "seg" in r else "-"
        print(f"| {r['log']} | {r['backend']} | {r.get('accuracy', '-')} | {seg} "
              f"| {r['rmse_m']:.4f} | {r['max_m']:.3f} | {r['rmse_deg']:.3f} "
              f"| {_f(r, 'fix_rmse_m', '.4f')} / {_f(r, 'fix_rmse_deg', '.3f')} "
              f"| {_f(r, 'sigma_xy_med_m', '.4f')} / {_f(r, 'sigma_yaw_med_deg', '.3f')} "
              f"| {_f(r, 'nees_mean', '.2f')} ({_f(r, 'nees_median', '.2f')}) "
              f"| {_f(r, 'nees_x', '.2f')} / {_f(r, 'nees_y', '.2f')} / {_f(r, 'nees_yaw', '.2f')} "
              f"| {r['fixes']} / {r['no_fix']} / {r['reloc']} |")
    if any("nees_parts" in r for r in rows):
        # beside the full figure, never instead of it: which fixes carry the NEES (mean (median) n,
        # per-axis x / y / yaw, fix RMSE m / deg)
        print(f"\n| run | map accuracy_m | all fixes | at SLAM keyframes | between keyframes | scans with >= "
              f"{100 * PARTLY_UNMAPPED:.0f} % of beams into unmapped space (at the SLAM pose) | the other fixes "
              "| worst 5 % of the fixes' share of the NEES sum (chi-square: 17 %) | NEES mean of the other 95 % "
              "(chi-square: 2.63) |")
        print("|---|--:|--:|--:|--:|--:|--:|--:|--:|")

        def cell(s: dict) -> str:
            if not s.get("n"):
                return "-"
            return (f"{s['nees_mean']:.2f} ({s['nees_median']:.2f}) n={s['n']}: {s['nees_x']:.2f} / "
                    f"{s['nees_y']:.2f} / {s['nees_yaw']:.2f}, {s['rmse_m']:.4f} m / {s['rmse_deg']:.3f} deg")
        for r in rows:
            if "nees_parts" not in r:
                continue
            q = r["nees_parts"]
            allf = {**{k: r[k] for k in ("n", "nees_mean", "nees_median", "nees_x", "nees_y", "nees_yaw")},
                    "rmse_m": r["fix_rmse_m"], "rmse_deg": r["fix_rmse_deg"]}
            print(f"| {r['log']} | {r.get('accuracy', '-')} | {cell(allf)} | {cell(q['keyframes'])} "
                  f"| {cell(q['between'])} | {cell(q['partly_unmapped'])} | {cell(q['mapped'])} "
                  f"| {100 * r['worst_share']:.0f} % | {r['nees_trimmed']:.2f} |")
    print("\n| run | map accuracy_m | heading RMSE deg | mean heading offset deg | RMSE about that mean deg | "
          "median abs deg | RMSE without the worst 2 % deg | relation heading RMS (1-2 s) deg |")
    print("|---|--:|--:|--:|--:|--:|--:|--:|")
    for r in rows:
        if "rmse_deg_aligned" in r:
            print(f"| {r['log']} | {r.get('accuracy', '-')} | {r['rmse_deg']:.3f} | {r['yaw_mean_deg']:+.3f} "
                  f"| {r['rmse_deg_aligned']:.3f} | {r['yaw_median_abs_deg']:.3f} | {r['yaw_rmse_98_deg']:.3f} "
                  f"| {r['rel_rot_rms_deg']:.3f} (n={r['rel_n']}) |")
    if any("split" in r for r in rows):
        print(f"\n| run | map accuracy_m | mapped poses (SLAM pose within {COVER_RADIUS_M:g} m of a map keyframe): "
              "n / pos RMSE m / max m / heading RMSE deg | unmapped poses: n / pos RMSE m / max m / heading RMSE deg "
              "| lost events / lost s | re-acquisitions / held fixes | unmapped (dead-reckoned) scans |")
        print("|---|--:|--:|--:|--:|--:|--:|")
        for r in rows:
            if "split" not in r:
                continue
            cells = []
            for part in ("in", "out"):
                p = r["split"][part]
                cells.append(f"{int(p['n'])} / {p['rmse_m']:.4f} / {p['max_m']:.3f} / {p['rmse_deg']:.3f}"
                             if p["n"] else "0 / - / - / -")
            print(f"| {r['log']} | {r.get('accuracy', '-')} | {cells[0]} | {cells[1]} "
                  f"| {r['lost_events']} / {r['lost_s']:.1f} | {r['reacquisitions']} / {r['held_fixes']} "
                  f"| {r['unmapped_scans']} |")
    timing = {r["log"]: r for r in rows if "odo_shift_s" in r}
    for name, r in timing.items():
        print(f"\n{name}: odometry yaw change over scan pairs 0.5 s apart vs SLAM: {r['odo_rms0_deg']:.2f} deg RMS "
              f"at the scans' stamps, {r['odo_rms_shift_deg']:.2f} deg read {r['odo_shift_s']:+.2f} s off them")
    for name, r in {r["log"]: r for r in rows if "carried_n" in r}.items():
        print(f"\n{name}: the odometry pose each scan's laser line carries is the log's odometry at its stamp "
              f"{r['carried_median_s']:+.3f} s (median over {r['carried_n']} scans taken while moving), "
              f"|offset| 90th percentile {r['carried_p90_abs_s']:.3f} s; {r['carried_over_50ms']} scans more "
              f"than 50 ms off, {r['carried_over_150ms']} more than 150 ms")
    for r in rows:
        c = r.get("odom_clock")
        if c:
            used = f"{c['offset_s']:+.3f} s in use" if c["applied"] else "not used (0)"
            why = ("" if c["applied"] else ", odometry fast" if not c["slow"] else
                   ", odometry stamps in bursts (its timing carried as yaw variance in the smoother)"
                   if not c["regular"] else ", not confident")
            print(f"\n{r['log']} (map accuracy {r.get('accuracy', '-')}): odometry clock offset (localization.clock) "
                  f"{used}: estimate {c['estimate_s']:+.3f} +- {max(c['sigma_s'], 0):.3f} s, last fit "
                  f"{c['fit_s']:+.3f} s (fixes' turn / odometry's {c['yaw_scale'] or float('nan'):.3f}), "
                  f"gain {c['gain']:.1f}, "
                  f"{c['pairs']} fix pairs{why}")
    floors = {r["log"]: r for r in rows if "gm_rmse_deg" in r}
    for name, r in floors.items():
        print(f"\n{name}: SLAM vs GMapping over the segment ({r['gm_n']} scans, rigid alignment): "
              f"{r['gm_rmse_m']:.3f} m / {r['gm_rmse_deg']:.2f} deg RMS, median {r['gm_median_abs_deg']:.2f} deg "
              "(the reference's own error is of this order)")
    if any("gm_kf_n" in r for r in rows):
        # beside the full figure, never instead of it: the heading at the keyframes GMapping also has,
        # against either reference, where the two agree, and each one's own error by the three-cornered hat
        print(f"\n| run | map accuracy_m | keyframes GMapping has | heading RMSE vs SLAM deg | vs GMapping deg "
              f"| SLAM vs GMapping deg | vs SLAM where the references agree within {REF_AGREE_DEG:g} deg (n) "
              "| own error (three-cornered hat): localizer / SLAM / GMapping deg |")
        print("|---|--:|--:|--:|--:|--:|--:|--:|")
        for r in rows:
            if "gm_kf_n" in r:
                h = (r["hat_est_deg"], r["hat_slam_deg"], r["hat_gm_deg"])
                print(f"| {r['log']} | {r.get('accuracy', '-')} | {r['gm_kf_n']} | {r['est_vs_slam_deg']:.3f} "
                      f"| {r['est_vs_gm_deg']:.3f} | {r['slam_vs_gm_kf_deg']:.3f} "
                      f"| {r['est_vs_slam_agree_deg']:.3f} ({r['agree_n']}) | {h[0]:.3f} / {h[1]:.3f} / {h[2]:.3f} |")
        print("(the hat assumes independent errors: an error the localizer shares with SLAM (the same scans, "
              "the map built from SLAM's other passes) cancels in their pair and is counted to GMapping; "
              "a negative entry: not independent)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
