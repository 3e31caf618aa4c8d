#!/usr/bin/env python
"""Live latency: scan arrival (last byte read from the socket) -> fused pose available.

Replays the paper run (or a log) through the STM32 and SICK emulators into a live
session, per back-end, and prints p50 / p90 / p99 / max latency (target: p99 <= 10 ms),
plus the live trajectory's position RMSE against the ground truth.  The percentiles are the whole run's:
every scan's latency while the runner still holds each one (up to its ``LATENCIES_KEPT`` newest), the first
``--warmup`` left out; on a longer run the runner's run-long histogram (:class:`fgloc.quantiles.LogHistogram`,
within 0.6 %), which counts the warm-up scans too (said in the table).

    python tools/bench_latency.py                       # simulated paper run, 30 s, ekf + smoother
    python tools/bench_latency.py --duration 0          # the whole run
    python tools/bench_latency.py --log run/log.mcap --map run/map.yaml --initial-pose X Y YAW
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--log", type=Path, help="MCAP log (default: simulate the paper run)")
    p.add_argument("--map", type=Path, help="map YAML (with --log)")
    p.add_argument("--initial-pose", type=float, nargs=3, default=None)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--backends", default="ekf,smoother")
    p.add_argument("--frontend", default="native")
    p.add_argument("--duration", type=float, default=30.0, help="seconds of the run (0 = all)")
    p.add_argument("--t-start", type=float, default=0.0)
    p.add_argument("--speed", type=float, default=1.0)
    p.add_argument("--mode", choices=("pty", "tcp"), default="pty")
    p.add_argument("--warmup", type=int, default=25, help="first N fused scans left out of the percentiles")
    args = p.parse_args(argv)

    from fgloc.testing.harness import replay_live

    gt = None
    if args.log is None:
        from fgloc.sim import simulate_paper

        t0 = time.perf_counter()
        sim = simulate_paper(seed=args.seed)
        print(f"simulated the paper run in {time.perf_counter() - t0:.1f} s", file=sys.stderr)
        msgs, occ, mount, robot, gt = sim.messages, sim.map, sim.laser_mount, sim.robot, sim.ground_truth
    else:
        from fgloc.io import open_log
        from fgloc.maps import OccupancyMap

        r = open_log(args.log)
        msgs = list(r.messages())
        occ = OccupancyMap.load(args.map) if args.map else None
        mount = r.laser_mount()
        robot = None
        gt = r.ground_truth()
    stamps = [float(m.stamp) for _, m in msgs if hasattr(m, "stamp")]
    s0 = min(stamps) + args.t_start
    init = None
    if args.initial_pose is not None:
        init = np.array(args.initial_pose)
    elif gt is not None:
        init = gt.interpolate(s0)[0]
    rows = []
    for backend in args.backends.split(","):
        res = replay_live(msgs, occ, mount, robot=robot, backend=backend, frontend=args.frontend,
                          initial_pose=init, t_start=s0, duration=args.duration or None, speed=args.speed,
                          mode=args.mode)
        runner = res.session.runner
        lat_all = np.asarray(runner.latencies_ms)
        hist = runner.latency_hist  # every fused scan's latency, the whole run
        whole = len(lat_all) == hist.count  # the newest-N list still holds every scan
        c = res.summary.counters
        rmse = float("nan")
        if gt is not None and len(res.live_run) > 1:
            from fgloc.eval.metrics import evaluate

            rmse = evaluate(res.live_run, gt).position_rmse_m
        if whole:
            lat = lat_all[args.warmup:]  # the first scans pay for JIT compilation (numba) and cache fills
            q50, q90, q99 = (float(np.percentile(lat, q)) if len(lat) else float("nan") for q in (50, 90, 99))
            qmax = float(lat.max()) if len(lat) else float("nan")
            note = ""
        else:  # more scans than the runner keeps one by one: its histogram, warm-up included
            q50, q90, q99, qmax = hist.percentiles(50, 90, 99, 100)
            note = f" (histogram of all {hist.count}, first {args.warmup} included)"
        rows.append((backend + note, c.get("laser", {}).get("scans", 0), c["scans_fused"],
                     c["scans_skipped_backlog"], q50, q90, q99, qmax, hist.percentile(99), rmse))
    print(f"\nscan arrival -> fused pose ({args.frontend} front-end, {args.mode}, speed {args.speed}, "
          f"{args.duration or 'all'} s of the run)\n")
    print(f"| backend | scans in | fused | skipped (backlog) | p50 ms | p90 ms | p99 ms | max ms "
          f"| p99 incl. first {args.warmup} ms | live RMSE m |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r_ in rows:
        print(f"| {r_[0]} | {r_[1]} | {r_[2]} | {r_[3]} | {r_[4]:.2f} | {r_[5]:.2f} | {r_[6]:.2f} | {r_[7]:.2f} "
              f"| {r_[8]:.2f} | {r_[9]:.4f} |")
    print("\ntarget: p99 <= 10 ms")
    return 0


if __name__ == "__main__":
    sys.exit(main())
