#!/usr/bin/env python3
"""Where the front-ends' fixes sit against SLAM along and across the track, Radish segments.

    python tools/eval_fix_bias.py [--logs fr079 aces] [--frontends amcl native] [--backends smoother]
                                  [--scans 800] [--cache DIR] [--config FILE] [--odom-shift-s S] [--odom-scale K]

The segments and maps of ``tools/eval_frontends_real.py`` / ``tools/eval_nees.py`` (SLAM cached under
``--cache``, map undeclared).  For each log and front-end it localizes the segment from the SLAM
pose at its first scan and splits each fix's position error against the SLAM pose of the same scan
into the robot's frame (SLAM's heading): along-track (ahead +) and cross-track (left +), their mean
and RMS, the mean per speed bin (SLAM's speed at the fix: a timing error grows with the speed, a
map / sensor model offset does not), the least-squares time constant of the along-track error
against the speed and of the yaw error against the yaw rate, and the time shift ``d`` of the
reference (SLAM at ``t + d``) that minimizes the fixes' position RMSE; and the back-end's output
(``trajectory.tum``'s poses) against SLAM: position / heading RMSE, the largest error, the poses by status.

Per log it also gives the odometry against SLAM over the segment: the path length ratio and the
clock offset at which the odometry's speed profile (0.5 s mean) best meets SLAM's.

``--odom-shift-s`` / ``--odom-scale``: diagnostics only, the odometry's stamps shifted / its
distances scaled before the run (does the fixes' bias follow the odometry's timing or scale?).
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
sys.path.insert(0, str(REPO / "tools"))

SPEED_BINS = ((-9.0, -0.05), (-0.05, 0.05), (0.05, 0.2), (0.2, 0.4), (0.4, 0.6), (0.6, 9.0))
GOOD_M = 0.3  # fixes farther than this from SLAM are left out of the means (a wrong place, not a bias)
SHIFTS_S = np.arange(-0.30, 0.3001, 0.005)


def odometry_vs_slam(msgs, ref, t0: float, t1: float) -> str:
    """Path length ratio and clock offset of the odometry poses against the SLAM trajectory."""
    od = np.array([(m.stamp, *np.asarray(m.pose, dtype=float).reshape(-1)[:2]) for tp, m in msgs
                   if tp == "/odom" and m.pose is not None])
    if len(od) < 10:
        return "odometry: too few poses"
    ts = np.arange(t0 + 1.0, t1 - 1.0, 0.02)
    g = ref.interpolate(ts)[:, :2]
    k = np.ones(25) / 25

    def speed(xy: np.ndarray) -> np.ndarray:
        return np.convolve(np.hypot(np.gradient(xy[:, 0], ts), np.gradient(xy[:, 1], ts)), k, "same")

    def odo_at(tt: np.ndarray) -> np.ndarray:
        return np.column_stack([np.interp(tt, od[:, 0], od[:, 1]), np.interp(tt, od[:, 0], od[:, 2])])

    vs = speed(g)[50:-50]
    length_slam = float(np.sum(np.hypot(*np.diff(g, axis=0).T)))
    length_odo = float(np.sum(np.hypot(*np.diff(odo_at(ts), axis=0).T)))
    fits = []
    for d in np.arange(-0.3, 0.3001, 0.01):
        vo = speed(odo_at(ts + d))[50:-50]
        sc = float(np.sum(vo * vs) / max(np.sum(vo * vo), 1e-12))
        fits.append((float(np.sqrt(np.mean((sc * vo - vs) ** 2))), float(d)))
    rms0 = min(fits, key=lambda f: abs(f[1]))[0]
    rms, d = min(fits)
    return (f"odometry vs SLAM: path {length_odo:.2f} / {length_slam:.2f} m "
            f"(SLAM / odometry {length_slam / length_odo:.4f}); speed profiles meet best with the odometry at "
            f"t {1000 * d:+.0f} ms (rms {1000 * rms:.1f} mm/s, at 0: {1000 * rms0:.1f})")


def split(fixes: np.ndarray, ref) -> list[str]:
    """The fixes' error against SLAM in the robot's frame: means, per speed bin, time constants, best shift."""
    from fgloc.eval.metrics import track_errors
    from fgloc.geometry import wrap_angle

    t, pose = fixes[:, 0], fixes[:, 1:4]
    g = ref.interpolate(t)
    along, cross, e = track_errors(pose, g)
    c, s = np.cos(g[:, 2]), np.sin(g[:, 2])
    good = np.hypot(e[:, 0], e[:, 1]) < GOOD_M
    dt = 0.05
    g2, g1 = ref.interpolate(t + dt), ref.interpolate(t - dt)
    v = ((g2[:, 0] - g1[:, 0]) * c + (g2[:, 1] - g1[:, 1]) * s) / (2 * dt)
    w = wrap_angle(g2[:, 2] - g1[:, 2]) / (2 * dt)
    rmse0 = float(np.sqrt(np.mean(along[good] ** 2 + cross[good] ** 2)))
    out = [f"fixes {len(t)} ({good.sum()} within {GOOD_M} m): RMSE {rmse0:.4f} m, "
           f"along {1000 * along[good].mean():+.1f} mm "
           f"(rms {1000 * np.sqrt(np.mean(along[good] ** 2)):.1f}), cross {1000 * cross[good].mean():+.1f} mm "
           f"(rms {1000 * np.sqrt(np.mean(cross[good] ** 2)):.1f}), yaw {np.degrees(e[good, 2]).mean():+.2f} deg"]
    for lo, hi in SPEED_BINS:
        m = good & (v > lo) & (v <= hi)
        if m.sum() > 3:
            out.append(f"  speed {lo:+.2f}..{hi:+.2f} m/s: n {m.sum():4d}, along {1000 * along[m].mean():+6.1f} mm, "
                       f"cross {1000 * cross[m].mean():+6.1f} mm")
    tau_pos = float(np.sum(along[good] * v[good]) / max(np.sum(v[good] ** 2), 1e-12))
    tau_yaw = float(np.sum(e[good, 2] * w[good]) / max(np.sum(w[good] ** 2), 1e-12))
    best = None
    for d in SHIFTS_S:
        gd = ref.interpolate(t + d)
        r = float(np.sqrt(np.mean(np.sum((pose[good, :2] - gd[good, :2]) ** 2, axis=1))))
        if best is None or r < best[1]:
            best = (float(d), r, gd)
    assert best is not None
    gd = best[2]
    along_d = c * (pose[:, 0] - gd[:, 0]) + s * (pose[:, 1] - gd[:, 1])
    out.append(f"  time constant from along-track / speed {1000 * tau_pos:+.1f} ms, "
               f"from yaw / yaw rate {1000 * tau_yaw:+.1f} ms; "
               f"best shift of the reference {1000 * best[0]:+.0f} ms: RMSE {best[1]:.4f} m (at 0: {rmse0:.4f}), "
               f"along then {1000 * along_d[good].mean():+.1f} mm")
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--logs", nargs="+", default=["fr079", "aces"])
    ap.add_argument("--frontends", nargs="+", default=["amcl", "native"])
    ap.add_argument("--backends", nargs="+", default=["smoother"])
    ap.add_argument("--config", help="a configuration file over the defaults (as fgloc run --config)")
    ap.add_argument("--scans", type=int, default=800)
    ap.add_argument("--cache", type=Path, default=Path("eval_frontends_real"))
    ap.add_argument("--odom-shift-s", type=float, default=0.0, help="diagnostic: odometry stamps shifted by S s")
    ap.add_argument("--odom-scale", type=float, default=1.0, help="diagnostic: odometry distances times K")
    args = ap.parse_args()

    import eval_frontends_real as efr  # type: ignore[import-not-found]

    from fgloc.config import load_config
    from fgloc.eval.metrics import track_errors
    from fgloc.io import open_log
    from fgloc.localization import Localizer, Session
    from fgloc.mapping.source import open_log_scan_stamps
    from fgloc.types import Trajectory

    for name in args.logs:
        if name not in efr.LOGS or not efr.LOGS[name].exists():
            print(f"{name}: no log at {efr.LOGS.get(name, name)}: skipped", file=sys.stderr)
            continue
        recs, mount, slam = efr.slam_of(name, args.cache)
        key = args.cache / f"{name}_{args.scans}_map.pkl"
        if key.exists():
            s0, s1, _cov, occ = pickle.loads(key.read_bytes())
        else:
            s0, s1, _cov, occ = efr.segment_and_map(recs, mount, slam, args.scans)
            key.write_bytes(pickle.dumps((s0, s1, _cov, occ)))
        occ.accuracy_m = None
        t0, t1 = recs[s0].stamp, recs[s1].stamp
        msgs = [(tp, m) for tp, m in open_log(efr.LOGS[name]).messages(["/odom", "/scan"])
                if t0 - 1e-6 <= m.stamp <= t1 + 1e-6]  # type: ignore[attr-defined]
        own = np.array([r.stamp for r in recs])
        ref = Trajectory.from_unsorted(open_log_scan_stamps(efr.LOGS[name], recs),
                                       slam.scan_trajectory.interpolate(own))
        print(f"{name} scans {s0}-{s1}: {odometry_vs_slam(msgs, ref, t0, t1)}", flush=True)
        if args.odom_scale != 1.0:
            k = np.array([args.odom_scale, args.odom_scale, 1.0])
            msgs = [(tp, replace(m, twist=np.asarray(m.twist, dtype=float) * k,
                                 pose=None if m.pose is None else np.asarray(m.pose, dtype=float) * k))
                    if tp == "/odom" else (tp, m) for tp, m in msgs]
        if args.odom_shift_s:
            msgs = sorted(((tp, replace(m, stamp=m.stamp + args.odom_shift_s)) if tp == "/odom" else (tp, m)
                           for tp, m in msgs), key=lambda r: r[1].stamp)
        p0 = ref.interpolate(np.array([t0]))[0]
        for fe in args.frontends:
            for backend in args.backends:
                loc = Localizer(occ, mount, backend, fe, initial_pose=p0, config=load_config(args.config))
                tw = time.perf_counter()
                est = Session(loc).run(msgs)
                fx = np.array([(f.stamp, *f.pose) for f in loc.fixes if f.source == fe]).reshape(-1, 4)
                print(f"{name} {fe} / {backend} ({time.perf_counter() - tw:.0f} s):", flush=True)
                for line in split(fx, ref) if len(fx) else ["no fixes"]:
                    print("  " + line, flush=True)
                inside = (est.stamps >= ref.stamps[0]) & (est.stamps <= ref.stamps[-1])
                along, cross, e = track_errors(est.poses[inside], ref.interpolate(est.stamps[inside]))
                pos = np.hypot(along, cross)
                c = loc.monitor.counts(est.stamps)
                print(f"  output: position RMSE {np.sqrt(np.mean(pos**2)):.4f} m, heading RMSE "
                      f"{np.degrees(np.sqrt(np.mean(e[:, 2] ** 2))):.3f} deg, max {pos.max():.3f} m; poses ok "
                      f"{c['ok']} / degraded {c['degraded']} / suspect {c['suspect']} / lost {c['lost']}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
