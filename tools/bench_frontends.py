#!/usr/bin/env python
"""Benchmark the scan-to-map front-ends side by side on the same scans.

Rows: the native matcher, KISS-ICP registration against the map, AMCL with 2000
particles (if ``fgloc.frontends.amcl`` exists), kiss-icp as shipped (its KissICP
odometry pipeline on the same scans as 3-D points, z = 0), small-gicp ICP and
Open3D point-to-point ICP scan-to-map (map = the same surface points the kiss
front-end uses, KD-trees built once, outside the timing).

Data: the simulated paper run (``fgloc.sim.simulate_paper``); ``--synthetic`` (or no
simulator) uses the small synthetic room of ``tests/frontends/synth.py``.  Every
registration starts from the same guess per scan: the ground truth disturbed by
N(0, ``--noise-m``) in x, y and N(0, ``--noise-deg``) in yaw (seeded), or exactly
0.3 m / 10 deg off with ``--offset``.  Timing: median and p95 wall time per scan in
this process, single-threaded where the library allows it; the first ``--warmup``
scans of each row are run but not timed (numba compilation, caches).

    python tools/bench_frontends.py [--scans 500] [--offset] [--synthetic]

The small-gicp and Open3D rows need the bench extra (``pip install "fgloc[bench]"``; Open3D's wheel
also needs ``sudo apt-get install libusb-1.0-0 libgl1``); without it they say "not available".
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from fgloc.frontends import make_frontend  # noqa: E402
from fgloc.frontends.base import ScanPreprocessor  # noqa: E402
from fgloc.frontends.kiss import surface_points  # noqa: E402
from fgloc.geometry import between, compose, from_matrix, wrap_angle  # noqa: E402
from fgloc.types import LaserScan, Odometry  # noqa: E402


def odom_poses_at(odoms: list[Odometry], stamps: np.ndarray) -> np.ndarray:
    """Odometry-frame poses at ``stamps``: the messages' poses if present, else integrated twists."""
    t = np.array([o.stamp for o in odoms])
    if all(o.pose is not None for o in odoms):
        p = np.array([o.pose for o in odoms], dtype=float)
    else:
        p = np.zeros((len(odoms), 3))
        for i in range(1, len(odoms)):
            dt = t[i] - t[i - 1]
            v = np.asarray(odoms[i - 1].twist, dtype=float)
            p[i] = compose(p[i - 1], v * dt)
    from fgloc.geometry import interpolate_poses

    return interpolate_poses(t, p, stamps)


def load_data(n_scans: int, synthetic: bool):
    if not synthetic:
        try:
            from fgloc.sim import simulate_paper
        except ImportError:
            print("fgloc.sim not available: using the synthetic room")
            synthetic = True
    if not synthetic:
        sim = simulate_paper(seed=0)
        scans = [m for topic, m in sim.messages if isinstance(m, LaserScan)]
        odoms = [m for topic, m in sim.messages if isinstance(m, Odometry) and topic != "/ground_truth"]
        stamps = np.array([s.stamp for s in scans])
        gt = sim.ground_truth.interpolate(stamps)
        od = odom_poses_at(odoms, stamps) if odoms else gt
        deltas = [None] + [between(od[i - 1], od[i]) for i in range(1, len(scans))]
        source = f"simulated paper run, {len(scans)} scans of {len(scans[0].ranges)} beams"
        occ_map, mount = sim.map, sim.laser_mount
    else:
        sys.path.insert(0, str(REPO / "tests" / "frontends"))
        from synth import MOUNT, make_map, make_moving_scan  # type: ignore[import-not-found]

        occ_map, mount = make_map(), MOUNT
        rng = np.random.default_rng(0)
        # an 8 m x 1.5 m rectangle at 0.8 m/s, turning in place at 1 rad/s at the corners;
        # scans at 25 Hz, motion-distorted
        rng = np.random.default_rng(0)
        dt, v, w = 0.04, 0.8, 1.0
        pose = np.array([6.5, 3.5, 0.0])
        scans, gt_l, tw = [], [], []
        lengths = [8.0, 1.5, 8.0, 1.5]
        k = 0
        while len(scans) < 900:
            for twist, dur in ((np.array([v, 0.0, 0.0]), lengths[k % 4] / v), (np.array([0.0, 0.0, w]), np.pi / 2 / w)):
                for _ in range(int(round(dur / dt))):
                    scans.append(make_moving_scan(occ_map, pose, twist, rng, stamp=len(scans) * dt))
                    gt_l.append(pose.copy())
                    tw.append(twist)
                    pose = compose(pose, twist * dt)
            k += 1
        gt = np.array(gt_l)
        deltas = [None] + [tw[i - 1] * dt for i in range(1, len(scans))]
        source = f"synthetic room, {len(scans)} scans of {len(scans[0].ranges)} beams"
    idx = np.unique(np.linspace(0, len(scans) - 1, min(n_scans, len(scans))).astype(int))
    return occ_map, mount, scans, gt, deltas, idx, source


def guesses_for(gt: np.ndarray, offset: bool, noise_m: float, noise_deg: float, seed: int = 1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    n = len(gt)
    if offset:
        a = rng.uniform(0, 2 * np.pi, n)
        d = np.column_stack([0.3 * np.cos(a), 0.3 * np.sin(a), np.radians(10.0) * rng.choice([-1, 1], n)])
    else:
        d = np.column_stack([rng.normal(0, noise_m, (n, 2)), rng.normal(0, np.radians(noise_deg), n)])
    g = gt + d
    g[:, 2] = wrap_angle(g[:, 2])
    return g


class Row:
    def __init__(self, name: str, note: str = ""):
        self.name, self.note = name, note
        self.times: list[float] = []
        self.errs: list[np.ndarray] = []
        self.fails = 0
        self.available = True

    def cells(self) -> list[str]:
        if not self.available:
            return [self.name, "-", "-", "-", "-", "-", self.note]
        t = np.array(self.times) * 1e3
        e = np.array(self.errs) if self.errs else np.zeros((0, 3))
        pos = np.hypot(e[:, 0], e[:, 1]) if len(e) else np.array([np.nan])
        yaw = np.degrees(np.abs(e[:, 2])) if len(e) else np.array([np.nan])
        n = len(self.times)
        return [
            self.name,
            f"{np.median(t):.2f}" if n else "-",
            f"{np.percentile(t, 95):.2f}" if n else "-",
            f"{1e3 * np.median(pos):.1f}" if len(e) else "-",
            f"{np.median(yaw):.3f}" if len(e) else "-",
            f"{self.fails}/{n}",
            self.note,
        ]


def run_row(row: Row, fn: Callable[[int], np.ndarray | None], idx: np.ndarray, gt: np.ndarray, warmup: int,
            prime: Callable[[int], object] | None = None) -> None:
    for j, i in enumerate(idx):
        if prime is not None:
            prime(int(i))  # untimed
        t0 = time.perf_counter()
        pose = fn(int(i))
        dt = time.perf_counter() - t0
        if j < warmup:
            continue
        row.times.append(dt)
        if gt is None:
            continue
        if pose is None:
            row.fails += 1
        else:
            e = np.asarray(pose, dtype=float) - gt[i]
            e[2] = wrap_angle(e[2])
            row.errs.append(e)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scans", type=int, default=500, help="scans to time per row (evenly spread)")
    ap.add_argument("--warmup", type=int, default=5, help="untimed scans at the start of each row")
    ap.add_argument("--offset", action="store_true", help="guesses exactly 0.3 m / 10 deg off")
    ap.add_argument("--noise-m", type=float, default=0.05)
    ap.add_argument("--noise-deg", type=float, default=2.0)
    ap.add_argument("--synthetic", action="store_true", help="use the synthetic room instead of the simulator")
    ap.add_argument("--skip", default="",
                    help="comma-separated rows to skip (native,kiss,amcl,raycast,kiss-icp,small-gicp,open3d)")
    ap.add_argument("--native", action="append", default=[], metavar="KEY=VALUE",
                    help="a native matcher setting for this run (YAML value), e.g. heading_check_deg=0")
    args = ap.parse_args()
    skip = set(filter(None, args.skip.split(",")))

    occ_map, mount, scans, gt, deltas, idx, source = load_data(args.scans, args.synthetic)
    guesses = guesses_for(gt, args.offset, args.noise_m, args.noise_deg)
    # the synthetic room's scans are ray cast on the grid itself: beams end on the cells' faces
    depth = {"surface_depth_cells": 0.0} if source.startswith("synthetic") else {}
    fe_cfg = {"native": dict(depth), "kiss": dict(depth)}
    import yaml

    for kv in args.native:
        key, _, val = kv.partition("=")
        fe_cfg["native"][key.strip()] = yaml.safe_load(val)
    guess_txt = "0.3 m / 10 deg off" if args.offset else f"N(0, {args.noise_m} m), N(0, {args.noise_deg} deg) off"
    rows: list[Row] = []
    pre = ScanPreprocessor(mount)
    pts_cache: dict[int, np.ndarray] = {}

    def prime(p: ScanPreprocessor, i: int) -> None:
        """Feed the two scans before ``i`` through a preprocessor (de-skew clock and twist history),
        as if the front-end had been called on every scan."""
        p.reset()
        for j in (i - 2, i - 1):
            if j >= 0:
                p(scans[j], deltas[j])

    def points(i: int) -> np.ndarray:  # de-skewed base-frame points for the external rows (not timed)
        if i not in pts_cache:
            prime(pre, i)
            p, _ = pre(scans[i], deltas[i])
            pts_cache[i] = p if p is not None else np.zeros((0, 2))
        return pts_cache[i]

    for name in ("native", "kiss"):
        if name in skip:
            continue
        fe = make_frontend(name, occ_map, mount, fe_cfg[name])
        row = Row(f"{name} (fgloc)", "scan-to-map, Hessian cov")

        def fn(i: int, fe=fe) -> np.ndarray | None:
            r = fe.match(scans[i], guesses[i], deltas[i])
            return r.pose if r.ok else None

        run_row(row, fn, idx, gt, args.warmup, prime=lambda i, fe=fe: (fe.reset(), prime(fe.pre, i)))
        rows.append(row)

    if "amcl" not in skip:
        row = Row("AMCL 2000 particles", "sequential, every scan")
        try:
            fe_a = None
            for cfg in ({"min_particles": 2000, "max_particles": 2000}, {"particles": 2000}, {}):
                try:
                    fe_a = make_frontend("amcl", occ_map, mount, cfg)
                    row.note = f"config {cfg}, sequential over all scans"
                    break
                except Exception:  # noqa: BLE001 - AMCL keys unknown to this tool: try the next
                    continue
            if fe_a is None:
                raise ImportError("AMCL could not be built")
            fe_a.reset(gt[0])
            ts: list[float] = []
            upd = Row("AMCL 2000, updates only", "calls that ran the filter (motion, weights, resampling)")
            for i in range(len(scans)):
                t0 = time.perf_counter()
                r = fe_a.match(scans[i], guesses[i], deltas[i])
                dt = time.perf_counter() - t0
                if i >= args.warmup:
                    ts.append(dt)
                    if r.info.get("updated"):
                        upd.times.append(dt)
                    if r.ok and r.pose is not None:
                        e = r.pose - gt[i]
                        e[2] = wrap_angle(e[2])
                        row.errs.append(e)
                        if r.info.get("updated"):
                            upd.errs.append(e)
                    else:
                        row.fails += 1
                        upd.fails += bool(r.info.get("updated"))
            row.times = ts
        except Exception as e:  # noqa: BLE001 - report, do not crash the benchmark
            row.available = False
            row.note = f"not available ({e.__class__.__name__}: {str(e)[:60]})"
            upd = None
        rows.append(row)
        if upd is not None and upd.times:
            rows.append(upd)

    if "raycast" not in skip:
        # the simulator's and the map's grid DDA (fgloc.gridmath.raycast_grid): one scan's beams per call
        row = Row("ray cast, one scan (map DDA)", "OccupancyMap.raycast of every beam from the true laser pose")
        n_beams = len(scans[0].ranges)
        mount_pose = np.asarray(getattr(mount, "pose", np.zeros(3)), dtype=float)

        def fn_rc(i: int) -> np.ndarray | None:
            lp = compose(gt[i], mount_pose)
            ang = lp[2] + float(scans[i].angle_min) + float(scans[i].angle_increment) * np.arange(n_beams)
            occ_map.raycast(lp[:2], ang, float(scans[i].range_max))
            return None

        run_row(row, fn_rc, idx, None, args.warmup)  # type: ignore[arg-type]
        row.fails = 0
        rows.append(row)

    surf, _ = surface_points(occ_map, 2, fe_cfg["kiss"].get("surface_depth_cells", 0.5))
    surf3 = np.column_stack([surf, np.zeros(len(surf))])

    if "kiss-icp" not in skip:
        row = Row("kiss-icp as shipped", "KissICP odometry, not map-relative")
        try:
            from kiss_icp.config import load_config
            from kiss_icp.kiss_icp import KissICP

            cfg = load_config(None)
            cfg.data.max_range = float(scans[0].range_max)
            cfg.data.min_range = float(scans[0].range_min)
            cfg.data.deskew = False
            cfg.mapping.voxel_size = cfg.data.max_range / 100.0
            odo = KissICP(cfg)
            ts = []
            start = None
            for i in range(len(scans)):
                p3 = np.column_stack([points(i), np.zeros(len(points(i)))])
                t0 = time.perf_counter()
                odo.register_frame(p3, np.zeros(len(p3)))
                dt = time.perf_counter() - t0
                pose = from_matrix(odo.last_pose)
                if start is None:
                    start = gt[i]
                est = compose(start, pose)
                if i >= args.warmup:
                    ts.append(dt)
                    e = est - gt[i]
                    e[2] = wrap_angle(e[2])
                    row.errs.append(e)
            row.times = ts
            row.note = f"odometry (drifts), voxel {cfg.mapping.voxel_size:.2f} m, all scans"
        except Exception as e:  # noqa: BLE001
            row.available, row.note = False, f"not available ({e.__class__.__name__}: {str(e)[:60]})"
        rows.append(row)

    if "small-gicp" not in skip:
        row = Row("small-gicp ICP", "scan-to-map, KD-tree prebuilt")
        try:
            import small_gicp

            target = small_gicp.PointCloud(surf3)
            tree = small_gicp.KdTree(target)

            def fn_sg(i: int) -> np.ndarray | None:
                p = points(i)
                src = small_gicp.PointCloud(np.column_stack([p, np.zeros(len(p))]))
                T0 = np.eye(4)
                T0[:3, :3] = [[np.cos(guesses[i][2]), -np.sin(guesses[i][2]), 0],
                              [np.sin(guesses[i][2]), np.cos(guesses[i][2]), 0], [0, 0, 1]]
                T0[:2, 3] = guesses[i][:2]
                res = small_gicp.align(target, src, tree, init_T_target_source=T0, registration_type="ICP",
                                       max_correspondence_distance=0.5, max_iterations=50)
                return from_matrix(res.T_target_source) if res.converged else None

            for i in idx:  # external rows get the same de-skewed points, prepared outside the timing
                points(int(i))
            run_row(row, fn_sg, idx, gt, args.warmup)
        except Exception as e:  # noqa: BLE001
            row.available, row.note = False, f"not available ({e.__class__.__name__}: {str(e)[:60]})"
        rows.append(row)

    if "open3d" not in skip:
        row = Row("Open3D ICP p2p", "scan-to-map (KD-tree built per call)")
        try:
            import open3d as o3d

            tgt = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(surf3))
            est = o3d.pipelines.registration.TransformationEstimationPointToPoint()
            crit = o3d.pipelines.registration.ICPConvergenceCriteria(max_iteration=50)

            def fn_o3d(i: int) -> np.ndarray | None:
                p = points(i)
                src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.column_stack([p, np.zeros(len(p))])))
                T0 = np.eye(4)
                T0[:3, :3] = [[np.cos(guesses[i][2]), -np.sin(guesses[i][2]), 0],
                              [np.sin(guesses[i][2]), np.cos(guesses[i][2]), 0], [0, 0, 1]]
                T0[:2, 3] = guesses[i][:2]
                res = o3d.pipelines.registration.registration_icp(src, tgt, 0.5, T0, est, crit)
                return from_matrix(res.transformation) if res.fitness > 0.3 else None

            n_o3d = idx[:: max(1, len(idx) // 100)]  # Open3D is slow: at most ~100 scans
            run_row(row, fn_o3d, n_o3d, gt, min(args.warmup, 2))
            row.note += f", {len(n_o3d)} scans"
        except Exception as e:  # noqa: BLE001
            row.available, row.note = False, f"not available ({e.__class__.__name__}: {str(e)[:60]})"
        rows.append(row)

    header = ["front-end", "median ms", "p95 ms", "median pos err mm", "median yaw err deg", "no fix", "notes"]
    table = [header] + [r.cells() for r in rows]
    try:
        from rich.console import Console
        from rich.table import Table

        t = Table(title=f"Front-ends on the {source}; guess {guess_txt}; {len(idx)} scans "
                        f"(first {args.warmup} per row untimed: numba compile / warm-up)")
        for h in header:
            t.add_column(h)
        for r in table[1:]:
            t.add_row(*r)
        Console(width=200).print(t)
    except ImportError:  # pragma: no cover
        print(f"{source}; guess {guess_txt}")
        for r in table:
            print(" | ".join(r))


if __name__ == "__main__":
    main()
