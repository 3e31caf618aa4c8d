"""No jumps in a changed world: the shipped ``changed_world`` scenario (or another) localized on its old
map by each back-end, with and without the jump gate, over seeds; one table.

    python tools/eval_changed_world.py [--scenario changed_world] [--seeds 0 1 2] [--backends smoother ekf]

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
    from fgloc.localization import Localizer, Session

    msgs = [(t, m) for t, m in sim.messages if t != "/ground_truth"]
    loc = Localizer(sim.map, sim.laser_mount, backend, "native", initial_pose=sim.ground_truth.poses[0],
                    config=load_config(overrides={"integrity": {"gate": gate}}))
    t0 = time.perf_counter()
    est = Session(loc).run(msgs)
    wall = time.perf_counter() - t0
    gt = sim.ground_truth.interpolate(est.stamps)
    err = np.hypot(*(est.poses[:, :2] - gt[:, :2]).T)
    step = np.hypot(*(np.diff(est.poses[:, :2], axis=0) - np.diff(gt[:, :2], axis=0)).T)
    n_wrong, longest = wrong_runs(loc, sim.ground_truth)
    return {"rmse": float(np.sqrt(np.mean(err**2))), "max": float(err.max()), "step": float(step.max()),
            "wrong": n_wrong, "longest": longest, "held": int(loc.stats.get("held_jumps", 0)),
            "status": loc.monitor.counts(est.stamps), "wall": wall}


def main() -> None:
    from fgloc.config import scenario_path
    from fgloc.sim import run_scenario

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="changed_world", help="a shipped scenario's name or a YAML file")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--backends", nargs="+", default=["smoother", "ekf"])
    args = ap.parse_args()
    path = Path(args.scenario) if Path(args.scenario).is_file() else scenario_path(args.scenario)
    print("| scenario | seed | back-end | gate | RMSE m | max m | largest step m | fixes > 0.25 m off (longest run) "
          "| held back | poses ok / degraded / suspect / lost |")
    print("|---|--:|---|---|--:|--:|--:|--:|--:|--:|")
    for seed in args.seeds:
        sim = run_scenario(path, seed=seed)
        for backend in args.backends:
            for gate in (False, True):
                r = localize(sim, backend, gate)
                c = r["status"]
                print(f"| {args.scenario} | {seed} | {backend} | {'on' if gate else 'off'} | {r['rmse']:.4f} | "
                      f"{r['max']:.3f} | {r['step']:.3f} | {r['wrong']} ({r['longest']}) | {r['held']} | "
                      f"{c['ok']} / {c['degraded']} / {c['suspect']} / {c['lost']} |", flush=True)
                print(f"done seed {seed} {backend} gate={gate} in {r['wall']:.0f} s", file=sys.stderr)


if __name__ == "__main__":
    main()
