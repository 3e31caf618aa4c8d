"""Wall time of the in-memory localization pipeline on the simulated paper run, per back-end and front-end.

Prints one table: wall time per simulated second (and the real-time factor), milliseconds
per front-end match, per back-end update (odometry + compass + keyframe
calls), the final trajectory step (batch LM / window flush) and the position RMSE.
The whole ``fgloc run`` command (a child process: start-up, reading, writing run.mcap) is
measured by ``fgloc bench speed`` (:mod:`fgloc.bench.speed`), beside this in-memory pipeline.

    python tools/bench_pipeline.py [--seed 0] [--backends ekf,smoother,batch]
                                   [--frontends native,kiss,amcl]
"""

from __future__ import annotations

import argparse
import importlib
import time

import numpy as np
from rich.console import Console
from rich.table import Table

from fgloc.config import load_config
from fgloc.eval.metrics import evaluate
from fgloc.localization import Localizer
from fgloc.sim import simulate_paper
from fgloc.types import CompassHeading, LaserScan, Odometry


def run(sim, backend: str, frontend: str, config) -> dict:
    loc = Localizer(sim.map, sim.laser_mount, backend=backend, frontend=frontend,
                    initial_pose=sim.ground_truth.poses[0], config=config)
    fe_time = [0.0, 0]
    match = loc.frontend.match

    def timed_match(*a, **k):
        t0 = time.perf_counter()
        r = match(*a, **k)
        fe_time[0] += time.perf_counter() - t0
        fe_time[1] += 1
        return r

    loc.frontend.match = timed_match  # type: ignore[method-assign]
    n_updates = 0
    t0 = time.perf_counter()
    for topic, msg in sim.messages:
        if topic == "/odom" and isinstance(msg, Odometry):
            loc.on_odometry(msg)
            n_updates += 1
        elif topic == "/imu" and isinstance(msg, CompassHeading):
            loc.on_compass(msg)
            n_updates += 1
        elif topic == "/scan" and isinstance(msg, LaserScan):
            loc.on_scan(msg)
            n_updates += 1
    t_online = time.perf_counter() - t0
    t1 = time.perf_counter()
    final = loc.finish()
    t_finish = time.perf_counter() - t1
    wall = t_online + t_finish
    sim_s = float(sim.ground_truth.duration)
    scans = max(1, loc.stats["scans"])
    return {
        "wall": wall, "sim_s": sim_s, "rt": sim_s / wall, "per_sim_s_ms": 1000 * wall / sim_s,
        "fe_ms": 1000 * fe_time[0] / max(1, fe_time[1]), "be_us": 1e6 * (t_online - fe_time[0]) / max(1, n_updates),
        "finish_s": t_finish, "rmse": evaluate(final, sim.ground_truth).position_rmse_m,
        "scans": scans, "updates": n_updates,
    }


def _have_amcl() -> bool:
    try:
        importlib.import_module("fgloc.frontends.amcl")
    except ImportError:
        return False
    return True


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--backends", default="ekf,smoother,batch")
    ap.add_argument("--frontends", default="native,kiss,amcl")
    ap.add_argument("--frontend-every", default="1,2",
                    help="pipeline.frontend_every values to time (1 = match every scan; 2 = the default)")
    args = ap.parse_args()
    con = Console(width=170)
    with con.status("simulating the paper run"):
        sim = simulate_paper(seed=args.seed)
    config = load_config()
    frontends = [fe for fe in args.frontends.split(",") if fe != "amcl" or _have_amcl()]
    # warm up numba / caches so compile time is not charged to the first row
    for fe in frontends:
        short = Localizer(sim.map, sim.laser_mount, "ekf", fe, sim.ground_truth.poses[0], config)
        for topic, msg in sim.messages[:400]:
            if topic == "/scan":
                short.on_scan(msg)  # type: ignore[arg-type]
    t = Table(title=f"pipeline wall time, paper run seed {args.seed} "
                    f"({sim.ground_truth.duration:.0f} s simulated)")
    for c in ("back-end", "front-end", "match every", "wall (s)", "ms per sim s", "x real time", "front-end ms/scan",
              "back-end us/update", "finish (s)", "pos RMSE (m)"):
        t.add_column(c, justify="right")
    for every in [int(v) for v in args.frontend_every.split(",")]:
        cfg = load_config(None, {"pipeline": {"frontend_every": every}})
        for be in args.backends.split(","):
            for fe in frontends:
                with con.status(f"{be} + {fe}, every {every}"):
                    r = run(sim, be, fe, cfg)
                t.add_row(be, fe, f"{every}", f"{r['wall']:.2f}", f"{r['per_sim_s_ms']:.1f}", f"{r['rt']:.0f}x",
                          f"{r['fe_ms']:.2f}", f"{r['be_us']:.0f}", f"{r['finish_s']:.2f}", f"{r['rmse']:.4f}")
    con.print(t)
    con.print(f"{r['scans']} scans, {r['updates']} updates per run; numpy {np.__version__}")


if __name__ == "__main__":
    main()
