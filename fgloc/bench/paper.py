"""The paper replica (``fgloc bench paper``): simulate the paper's run over seeds, localize it
with the paper's EKF + AMCL and with fgloc's variants, compare with the paper's numbers."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from fgloc.bench.common import frontend_available, localize_variants

PAPER_VARIANTS = (
    # (column label, backend, frontend, which trajectory)
    ("EKF+AMCL (paper)", "ekf", "amcl", "final"),
    ("EKF+native", "ekf", "native", "final"),
    ("smoother online", "smoother", "native", "online"),
    ("smoother fixed-lag", "smoother", "native", "final"),
    ("batch", "batch", "native", "final"),
)


def paper_variants(no_amcl: bool = False) -> tuple[tuple[str, str, str, str], ...]:
    """The columns of :data:`PAPER_VARIANTS` whose front-end imports here (AMCL's dependencies may
    be missing), without the AMCL front-end's (``--no-amcl``) when ``no_amcl``."""
    return tuple(v for v in PAPER_VARIANTS if frontend_available(v[2]) and not (no_amcl and v[2] == "amcl"))


def _bench_one_seed(args: tuple[int, list[tuple[str, str, str, str]], Any, bool]) -> dict[str, Any]:
    from fgloc.eval.metrics import evaluate
    from fgloc.sim import simulate_paper

    seed, variants, config, keep = args
    sim = simulate_paper(seed=seed)
    out: dict[str, Any] = {"seed": seed, "metrics": {}, "wall": {}, "traj": {}}
    for label, (tr, wall) in localize_variants(sim, variants, config).items():
        out["metrics"][label] = evaluate(tr, sim.ground_truth)
        out["wall"][label] = wall
        if keep:
            out["traj"][label] = tr
    if keep:
        out["gt"] = sim.ground_truth
        out["map"] = sim.map
    return out


def bench_paper(seeds: int, outdir: Path | None, variants: Any = PAPER_VARIANTS, config: Any = None,
                jobs: int = 1, quiet: bool = False, force: bool = False) -> dict[str, Any]:
    """Simulate the paper run ``seeds`` times, localize with each variant, compare with the paper.

    ``config``: a :class:`fgloc.config.FglocConfig`, a YAML path, or None (the defaults).
    Returns ``{"rows": {label: [Metrics per seed]}, "walls": {label: mean s}, "files", "seeds"}``.
    ``outdir``'s files are checked first and published together at the end
    (:class:`fgloc.io.outputs.Outputs`; files fgloc did not write only with ``force``).
    """
    from fgloc.config import FglocConfig, load_config
    from fgloc.io.yamlio import write_yaml

    outs = None
    if outdir is not None:
        from fgloc.eval.plots import plot_files
        from fgloc.io.outputs import Outputs

        outs = Outputs(outdir, ("table.md", "metrics.yaml", *plot_files()), command="bench paper", force=force)
        outs.check()
    cfg = config if isinstance(config, FglocConfig) else load_config(config)
    tasks = [(s, list(variants), cfg, s == 0 and outdir is not None) for s in range(seeds)]
    results: list[dict[str, Any]] = []
    from tqdm import tqdm

    if jobs > 1 and seeds > 1:
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(max_workers=jobs) as ex:
            for r in tqdm(ex.map(_bench_one_seed, tasks), total=seeds, desc="seeds", disable=quiet, leave=False):
                results.append(r)
    else:
        for t in tqdm(tasks, desc="seeds", disable=quiet, leave=False):
            results.append(_bench_one_seed(t))
    rows = {label: [r["metrics"][label] for r in results] for label, *_ in variants}
    walls = {label: float(np.mean([r["wall"][label] for r in results])) for label, *_ in variants}
    files: list[Path] = []
    if outs is not None:
        from fgloc.eval.paper import comparison_text
        from fgloc.eval.plots import plot_all

        with outs:
            r0 = results[0]
            staged = plot_all(r0["traj"], r0["gt"], outs.dir, occ_map=r0["map"], title="paper replica, seed 0")
            outs.path("table.md").write_text(comparison_text(rows, title=f"paper replica, {seeds} seeds") + "\n")
            summary = {label: {k: [m.to_dict()[k] for m in ms] for k in ("position_rmse_m", "heading_rmse_deg")}
                       for label, ms in rows.items()}
            write_yaml(outs.path("metrics.yaml"), summary)
        files = [outs.final(p.name) for p in staged]
    return {"rows": rows, "walls": walls, "files": files, "seeds": seeds}


def claims(rows: dict[str, list[Any]]) -> list[str]:
    """The replica's accuracy targets, each as one line with the measured value and whether it is met
    (``met`` / ``MISSED`` after each target)."""
    def mean(label: str, key: str) -> float:
        return float(np.mean([getattr(m, key) for m in rows[label]]))

    def mark(ok: bool) -> str:
        return "met" if ok else "MISSED"

    out = []
    if "smoother fixed-lag" in rows:
        p, h = mean("smoother fixed-lag", "position_rmse_m"), mean("smoother fixed-lag", "heading_rmse_deg")
        out.append(f"smoother fixed-lag: position RMSE {p:.4f} m (target <= 0.010: {mark(p <= 0.010)}), "
                   f"heading RMSE {h:.3f} deg (target <= 0.30: {mark(h <= 0.30)})")
        for ekf in ("EKF+AMCL (paper)", "EKF+native"):
            if ekf in rows:
                e = mean(ekf, "position_rmse_m")
                gain = 1 - p / e
                out.append(f"smoother vs {ekf}: {100 * gain:.0f} % lower position RMSE (target >= 30 %: "
                           f"{mark(gain >= 0.30)})")
        if "batch" in rows:
            b = mean("batch", "position_rmse_m")
            out.append(f"fixed-lag / batch position RMSE: {p / b:.2f}x (target <= 1.2x: {mark(p / b <= 1.2)})")
    return out
