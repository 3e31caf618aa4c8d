#!/usr/bin/env python3
"""What the scan says about a biased fix: the share of its beams the map explains at the fix.

For each scene and seed of the same-AMCL bench (``tools/eval_amcl_ratio.py``'s simulations) this
localizes the run with ``--backend`` + AMCL and, for every AMCL fix, measures the share of the scan's
valid beams whose end point lies within ``--near-m`` of the map's nearest occupied cell at the fix
(furniture moved since mapping lowers it).  It prints the fixes' position RMSE by thirds of that share,
the correlation of the share with the fix's error, and the back-end's output RMSE.  ``--inflate``
tries the share as the fix's weight, the fix covariance scaled before the back-end takes it:

* ``none``: as the front-end gives it;
* ``share:P``: times ``share^-P``;
* ``pull:K``: plus ``K`` times the squared pull the beams off the map could put on the fit (the sum of
  their distances from ``--near-m`` to 4x that, over the beam count) on x and y.

A diagnostic: the fix covariance is changed by wrapping the front-end's ``match`` in this process.

Usage::

    python tools/eval_fix_share.py [--scenes paper willow obstacles] [--seeds 1] [--inflate none share:40]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from eval_amcl_ratio import SCENES, simulate  # noqa: E402


def beam_distances(occ: Any, mount: np.ndarray, scan: Any, pose: np.ndarray) -> np.ndarray:
    """Each valid beam's end point's distance (m) to the map's nearest occupied cell, the scan at ``pose``."""
    ok = scan.valid_mask()
    r = np.asarray(scan.ranges, dtype=float)[ok]
    a = scan.angles[ok]
    lx, ly = r * np.cos(a), r * np.sin(a)
    cm, sm = math.cos(mount[2]), math.sin(mount[2])
    bx, by = mount[0] + cm * lx - sm * ly, mount[1] + sm * lx + cm * ly
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return np.asarray(occ.distance_at(np.column_stack([pose[0] + c * bx - s * by, pose[1] + s * bx + c * by])))


def inflated(cov: np.ndarray, d: np.ndarray, near_m: float, how: str) -> np.ndarray:
    """``cov`` weighted by the beams' distances ``d`` as ``how`` says (see the module's doc)."""
    kind, _, arg = how.partition(":")
    if kind == "none" or len(d) == 0:
        return cov
    if kind == "share":
        share = float(np.mean(d < near_m))
        return cov * (1.0 / max(share, 1e-3)) ** float(arg)
    if kind == "pull":
        pull = float(np.sum(np.where((d >= near_m) & (d <= 4 * near_m), d, 0.0))) / len(d)
        out = np.array(cov, dtype=float)
        out[0, 0] += float(arg) * pull**2
        out[1, 1] += float(arg) * pull**2
        return out
    raise SystemExit(f"eval_fix_share: --inflate {how}: expected none, share:P or pull:K")


def one(scene: str, seed: int, backend: str, near_m: float, how: str) -> dict[str, Any]:
    """One simulated run localized with ``backend`` + AMCL, the fixes' share and error."""
    from fgloc.eval.metrics import evaluate
    from fgloc.localization import build_session

    sim = simulate(scene, seed)
    session = build_session(sim.map, sim.laser_mount, backend=backend, frontend="amcl",
                            initial_pose=sim.ground_truth.poses[0])
    fe = session.loc.frontend
    lm = fe.laser_mount
    mount = np.zeros(3) if lm is None else np.asarray(getattr(lm, "pose", lm), dtype=float).reshape(3)
    rows: list[tuple[float, float, np.ndarray]] = []
    match = fe.match

    def measured(scan: Any, guess: Any, odom_delta: Any = None) -> Any:
        res = match(scan, guess, odom_delta)
        if res.ok and res.pose is not None and res.cov is not None:
            d = beam_distances(sim.map, mount, scan, np.asarray(res.pose, dtype=float))
            rows.append((float(scan.stamp), float(np.mean(d < near_m)) if len(d) else 1.0,
                         np.array(res.pose, dtype=float)))
            res.cov = inflated(np.asarray(res.cov, dtype=float), d, near_m, how)
        return res

    fe.match = measured
    final = session.run(sim.messages)
    m = evaluate(final, sim.ground_truth)
    t = np.array([r[0] for r in rows])
    share = np.array([r[1] for r in rows])
    poses = np.array([r[2] for r in rows])
    err = np.hypot(*(poses[:, :2] - sim.ground_truth.interpolate(t)[:, :2]).T)
    q = np.quantile(share, [0.0, 1 / 3, 2 / 3, 1.0])
    thirds = [float(np.sqrt(np.mean(err[(share >= q[i]) & (share <= q[i + 1])] ** 2))) for i in range(3)]
    return {"out_m": m.position_rmse_m, "fixes_m": float(np.sqrt(np.mean(err**2))), "n": len(err),
            "share_median": float(np.median(share)), "share_p10": float(np.percentile(share, 10)),
            "corr": float(np.corrcoef(share, err)[0, 1]), "thirds": thirds, "bounds": q.tolist()}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", nargs="+", default=list(SCENES))
    ap.add_argument("--seeds", type=int, default=1)
    ap.add_argument("--backend", default="smoother", choices=["smoother", "ekf"])
    ap.add_argument("--near-m", type=float, default=0.05, help="a beam this close to the map is explained "
                    "(AMCL's sigma_hit)")
    ap.add_argument("--inflate", nargs="+", default=["none"], help="none, share:P, pull:K (each a run)")
    a = ap.parse_args(argv)
    from tqdm import tqdm

    t0 = time.perf_counter()
    tasks = [(s, k, h) for s in a.scenes for k in range(a.seeds) for h in a.inflate]
    print(f"| scene | seed | {a.backend} fix weight | output pos mm | fixes mm (n) | share median / p10 | "
          "corr(share, error) | fixes mm by share third (low / mid / high) |")
    print("|---|--:|---|--:|--:|--:|--:|--:|")
    for scene, seed, how in tqdm(tasks, desc="runs", file=sys.stderr):
        r = one(scene, seed, a.backend, a.near_m, how)
        th = " / ".join(f"{x * 1000:.2f}" for x in r["thirds"])
        print(f"| {scene} | {seed} | {how} | {r['out_m'] * 1000:.3f} | {r['fixes_m'] * 1000:.2f} ({r['n']}) | "
              f"{r['share_median']:.3f} / {r['share_p10']:.3f} | {r['corr']:.2f} | {th} |", flush=True)
    print(f"\n{len(tasks)} runs in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
