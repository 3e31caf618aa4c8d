#!/usr/bin/env python3
"""Smoother against the EKF with the same AMCL front-end, per scene and seed.

The paper's system is an EKF fed by AMCL.  With the front-end held the same, the back-end is
the only difference: this tool simulates each scene (``paper``: ``fgloc simulate paper``; the
others: ``fgloc simulate scenario NAME``) per seed, localizes it with ``ekf`` + ``amcl`` and
``smoother`` + ``amcl`` (the fixed-lag smoother's final trajectory and its online estimate) and
prints position and heading RMSE against the ground truth, the smoother / EKF ratio of each, and
the NEES of each back-end's output poses (the online estimate at each keyframe with its
covariance, as ``/fused_pose`` carries it: the smoother's marginal computed at every keyframe,
``smoother.online_covariance``), ``e^T P^-1 e`` over (x, y, yaw): 3 on average when the covariance
is honest.  ``--frontends native`` gives the same for fgloc's own matcher.

Usage::

    python tools/eval_amcl_ratio.py [--scenes paper willow obstacles] [--seeds 3] [--config C.yaml] [--batch]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

SCENES = ("paper", "willow", "obstacles")


def simulate(scene: str, seed: int) -> Any:
    from fgloc.sim import simulate_paper
    from fgloc.sim.simulate import run_scenario

    if scene == "paper":
        return simulate_paper(seed=seed)
    from fgloc.config import scenario_path

    return run_scenario(scenario_path(scene), seed=seed)


def output_nees(online: Any, gt: Any) -> dict[str, float]:
    """:func:`fgloc.eval.metrics.nees_summary` of the online poses (with their covariances) against the truth."""
    from fgloc.eval.metrics import nees_summary
    from fgloc.geometry import wrap_angle

    t = np.asarray(online.stamps, dtype=float)
    inside = (t >= gt.stamps[0]) & (t <= gt.stamps[-1])
    if online.covs is None or not inside.any():
        return {"n": 0}
    e = np.asarray(online.poses, dtype=float)[inside] - gt.interpolate(t[inside])
    e[:, 2] = wrap_angle(e[:, 2])
    return nees_summary(e, np.asarray(online.covs, dtype=float)[inside])


def one(scene: str, seed: int, config: Any, frontend: str, batch: bool = False) -> dict[str, Any]:
    """RMSEs of EKF and smoother (fixed-lag and online; ``batch``: the batch smoother too) with
    ``frontend`` on one simulated run, and each back-end's output NEES."""
    from fgloc.bench.common import localize_sim
    from fgloc.eval.metrics import evaluate

    sim = simulate(scene, seed)
    out: dict[str, Any] = {}
    for be in ("ekf", "smoother"):
        final, online, _loc, wall = localize_sim(sim, be, frontend, config)
        for which, tr in (("final", final), ("online", online)):
            if be == "ekf" and which == "online":
                continue
            m = evaluate(tr, sim.ground_truth)
            out[f"{be} {which}"] = (m.position_rmse_m, m.heading_rmse_deg, wall)
        out[f"{be} nees"] = output_nees(online, sim.ground_truth)
    if batch:
        final, _online, _loc, wall = localize_sim(sim, "batch", frontend, config)
        m = evaluate(final, sim.ground_truth)
        out["batch final"] = (m.position_rmse_m, m.heading_rmse_deg, wall)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", nargs="+", default=list(SCENES))
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--config", type=Path, default=None, help="YAML overlaid on the defaults")
    ap.add_argument("--frontends", nargs="+", default=["amcl"], choices=["amcl", "native"])
    ap.add_argument("--batch", action="store_true", help="also the batch smoother (whole-run smoothing)")
    a = ap.parse_args(argv)
    from tqdm import tqdm

    from fgloc.config import load_config

    cfg = load_config(a.config)
    cfg.smoother.online_covariance = True  # the output's covariance at every keyframe (for the NEES)
    t0 = time.perf_counter()
    tasks = [(f, s, k) for f in a.frontends for s in a.scenes for k in range(a.seeds)]
    rows = []
    for fe, scene, seed in tqdm(tasks, desc="runs", file=sys.stderr):
        rows.append((fe, scene, seed, one(scene, seed, cfg, fe, a.batch)))
    for fe in a.frontends:
        table(fe, [(scene, seed, r) for f, scene, seed, r in rows if f == fe])
    print(f"\n{len(rows)} runs in {time.perf_counter() - t0:.0f} s")
    return 0


def table(fe: str, rows: list[tuple[str, int, dict[str, Any]]]) -> None:
    """One front-end's table: RMSEs, ratios, output NEES."""
    print(f"\nfront-end {fe}:\n")
    batch = all("batch final" in r for _, _, r in rows)
    print("| scene | seed | EKF pos m | smoother pos m | ratio | EKF hdg deg | smoother hdg deg | ratio | "
          "smoother online pos / hdg ratio | " + ("batch pos m / hdg deg, pos / hdg ratio | " if batch else "")
          + "output NEES EKF (x / y / yaw) | smoother |")
    print("|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|" + ("--:|" if batch else ""))
    ratios: dict[str, list[float]] = {"pos": [], "hdg": [], "pos_online": [], "hdg_online": []}
    if batch:
        ratios.update({"pos_batch": [], "hdg_batch": []})
    nees: dict[str, list[float]] = {"ekf": [], "smoother": []}
    for scene, seed, r in rows:
        ep, eh, _ = r["ekf final"]
        sp, sh, _ = r["smoother final"]
        op, oh, _ = r["smoother online"]
        ratios["pos"].append(sp / ep)
        ratios["hdg"].append(sh / eh)
        ratios["pos_online"].append(op / ep)
        ratios["hdg_online"].append(oh / eh)
        cells = []
        bcell = ""
        if batch:
            bp, bh, _ = r["batch final"]
            ratios["pos_batch"].append(bp / ep)
            ratios["hdg_batch"].append(bh / eh)
            bcell = f"{bp:.4f} / {bh:.3f}, {bp / ep:.2f} / {bh / eh:.2f} | "
        for be in ("ekf", "smoother"):
            n = r[f"{be} nees"]
            if n.get("n"):
                nees[be].append(n["nees_mean"])
                cells.append(f"{n['nees_mean']:.2f} ({n['nees_x']:.2f} / {n['nees_y']:.2f} / {n['nees_yaw']:.2f})")
            else:
                cells.append("-")
        print(f"| {scene} | {seed} | {ep:.4f} | {sp:.4f} | {sp / ep:.2f} | {eh:.3f} | {sh:.3f} | {sh / eh:.2f} | "
              f"{op / ep:.2f} / {oh / eh:.2f} | {bcell}{cells[0]} | {cells[1]} |")
    print()
    for k, v in ratios.items():
        print(f"{fe}: smoother / EKF {k}: median {statistics.median(v):.2f}, max {max(v):.2f} over {len(v)} runs")
    for be, v in nees.items():
        if v:
            print(f"{fe}: {be} output NEES (mean over the poses): median {statistics.median(v):.2f}, "
                  f"range {min(v):.2f}-{max(v):.2f} over {len(v)} runs (3 when honest)")


if __name__ == "__main__":
    sys.exit(main())
