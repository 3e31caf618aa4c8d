"""No jumps in a changed world: the shipped ``changed_world`` scenario (or another) localized on its old
map by each back-end, with and without the jump gate, over seeds; one table.

    python tools/eval_changed_world.py [--scenario changed_world] [--seeds 0 1 2] [--backends smoother ekf]
        [--route X0 Y0 X1 Y1 ...] [--odometry {late,stops,gap}] [--gate {both,on,off}]

``--odometry``: the odometry delivered 0.3 s late (``late``), stopped for good at a third of the route
(``stops``: a dead wheel driver), or absent for a third of it from there (``gap``: it resumes);
``--route``: a shorter route (the shelves along the north wall: ``24 17 8 17``).

For each run: position RMSE and max error of the final trajectory against the truth, the largest pose
step (the change of the position error between consecutive poses: a jump), the front-end's fixes more
than 0.25 m off the truth and the longest run of consecutive ones, the fixes the gate held back, and
the poses by status.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np


def wrong_runs(loc, gt, off_m: float = 0.25) -> tuple[int, int]:
    """How many of the front-end's fixes are more than ``off_m`` from the truth, and the longest run of them."""
    if not loc.fixes:
        return 0, 0
    st = np.array([f.stamp for f in loc.fixes])
    e = np.hypot(*(np.array([f.pose[:2] for f in loc.fixes]) - gt.interpolate(st)[:, :2]).T)
    bad = e > off_m
    longest = run = 0
    for b in bad:
        run = run + 1 if b else 0
        longest = max(longest, run)
    return int(bad.sum()), longest


def localize(sim, backend: str, gate: bool) -> dict:
    from fgloc.config import load_config
    from fgloc.eval.metrics import position_errors_and_steps
    from fgloc.localization import Localizer, Session

    msgs = [(t, m) for t, m in sim.messages if t != "/ground_truth"]
    loc = Localizer(sim.map, sim.laser_mount, backend, "native", initial_pose=sim.ground_truth.poses[0],
                    config=load_config(overrides={"integrity": {"gate": gate}}))
    t0 = time.perf_counter()
    est = Session(loc).run(msgs)
    wall = time.perf_counter() - t0
    err, step = position_errors_and_steps(est, sim.ground_truth)
    n_wrong, longest = wrong_runs(loc, sim.ground_truth)
    return {"rmse": float(np.sqrt(np.mean(err**2))), "max": float(err.max()), "step": float(step.max()),
            "wrong": n_wrong, "longest": longest, "held": int(loc.stats.get("held_jumps", 0)),
            "status": loc.monitor.counts(est.stamps), "wall": wall}


def main() -> None:
    from fgloc.config import scenario_path
    from fgloc.sim import load_scenario, run_scenario
    from fgloc.sim.simulate import true_motion

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="changed_world", help="a shipped scenario's name or a YAML file")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--backends", nargs="+", default=["smoother", "ekf"])
    ap.add_argument("--route", type=float, nargs="+", help="waypoints x0 y0 x1 y1 ... (m)")
    ap.add_argument("--odometry", choices=["late", "stops", "gap"], help="the odometry late, stopped or absent")
    ap.add_argument("--gate", choices=["both", "on", "off"], default="both")
    args = ap.parse_args()
    path = Path(args.scenario) if Path(args.scenario).is_file() else scenario_path(args.scenario)
    sc = load_scenario(path)
    if args.route:
        sc["route"] = np.asarray(args.route, dtype=float).reshape(-1, 2).tolist()
        d = np.diff(np.asarray(sc["route"]), axis=0)[0]
        sc["initial_yaw"] = float(np.arctan2(d[1], d[0]))
    if args.odometry:
        span = true_motion(sc).t[-1]
        faults = {"late": {"odometry_late": {"delay_s": 0.3}},
                  "stops": {"odometry_dropout": {"start": span / 3, "duration": None}},
                  "gap": {"odometry_dropout": {"start": span / 3, "duration": span / 3}}}[args.odometry]
        sc["faults"] = {**(sc.get("faults") or {}), **faults}
    name = args.scenario + (f" ({args.odometry} odometry)" if args.odometry else "")
    gates = {"both": (False, True), "on": (True,), "off": (False,)}[args.gate]
    print("| scenario | seed | back-end | gate | RMSE m | max m | largest step m | fixes > 0.25 m off (longest run) "
          "| held back | poses ok / degraded / suspect / lost |")
    print("|---|--:|---|---|--:|--:|--:|--:|--:|--:|")
    for seed in args.seeds:
        sim = run_scenario(sc, seed=seed)
        for backend in args.backends:
            for gate in gates:
                r = localize(sim, backend, gate)
                c = r["status"]
                print(f"| {name} | {seed} | {backend} | {'on' if gate else 'off'} | {r['rmse']:.4f} | "
                      f"{r['max']:.3f} | {r['step']:.3f} | {r['wrong']} ({r['longest']}) | {r['held']} | "
                      f"{c['ok']} / {c['degraded']} / {c['suspect']} / {c['lost']} |", flush=True)
                print(f"done seed {seed} {backend} gate={gate} in {r['wall']:.0f} s", file=sys.stderr)


if __name__ == "__main__":
    main()
