"""Fault scenarios (``fgloc bench faults``): compass disturbance, wheel slip, kidnapping,
against the fault-free paper run; the scenarios ship in the package (``fgloc.config``)."""

from __future__ import annotations

import math
from importlib.resources import as_file
from typing import Any

import numpy as np

from fgloc.bench.common import localize_sim

FAULTS = ("compass_disturbance", "wheel_slip", "kidnap")


def bench_faults(backend: str = "smoother", frontend: str = "native", seeds: int = 1, config: Any = None,
                 quiet: bool = False) -> list[dict[str, Any]]:
    """Fault scenarios vs the fault-free paper run: position RMSE increase, kidnap recovery time."""
    from fgloc.config import FglocConfig, load_config, scenario_path
    from fgloc.eval.metrics import evaluate
    from fgloc.localization.stats import RunStats
    from fgloc.sim import run_scenario, simulate_paper

    cfg = config if isinstance(config, FglocConfig) else load_config(config)
    out = []
    for seed in range(seeds):
        base = simulate_paper(seed=seed)
        f0, *_ = localize_sim(base, backend, frontend, cfg)
        rmse0 = evaluate(f0, base.ground_truth).position_rmse_m
        for name in FAULTS:
            res = scenario_path(name)
            if not res.is_file():
                out.append({"seed": seed, "scenario": name, "error": f"scenario {name} is not shipped"})
                continue
            with as_file(res) as path:
                sim = run_scenario(path, seed=seed)
            final, online, loc, _ = localize_sim(sim, backend, frontend, cfg)
            m = evaluate(final, sim.ground_truth)
            row: dict[str, Any] = {"seed": seed, "scenario": name, "rmse0": rmse0, "rmse": m.position_rmse_m,
                                   "delta": m.position_rmse_m - rmse0,
                                   "relocalizations": RunStats.of(loc.stats).relocalizations}
            if name == "kidnap":
                row.update(kidnap_recovery(sim, online))
            out.append(row)
    return out


def kidnap_recovery(sim: Any, online: Any, tol: float = 0.2) -> dict[str, Any]:
    """Time from the teleport (largest ground-truth jump) until the online error stays < ``tol``."""
    gt = sim.ground_truth
    steps = np.linalg.norm(np.diff(gt.poses[:, :2], axis=0), axis=1)
    i = int(np.argmax(steps))
    t_kid = float(gt.stamps[i + 1])
    if steps[i] < 0.5:
        return {"kidnap_t": None, "recovery_s": None}
    mask = online.stamps >= t_kid
    ts = online.stamps[mask]
    err = np.linalg.norm(online.poses[mask, :2] - gt.interpolate(ts)[:, :2], axis=1)
    bad = np.nonzero(err >= tol)[0]
    if len(ts) == 0:
        return {"kidnap_t": t_kid, "recovery_s": None}
    if len(bad) == 0:
        rec = float(ts[0] - t_kid)
    elif bad[-1] + 1 < len(ts):
        rec = float(ts[bad[-1] + 1] - t_kid)
    else:
        rec = math.inf
    return {"kidnap_t": t_kid, "recovery_s": rec, "jump_m": float(steps[i])}
