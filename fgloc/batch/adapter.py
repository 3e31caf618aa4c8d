"""The one place where ``fgloc batch`` calls the single-log library code: one function per job kind.

``localize_log`` (:func:`fgloc.app.run.run_log`, what ``fgloc run`` does), ``map_log``
(:func:`fgloc.mapping.build.build_map`, ``fgloc map``) and ``bench_paper_seed`` (one seed of
:mod:`fgloc.bench.paper`) take plain arguments and return a small typed outcome.  When a
library function moves, only this module changes; nothing else in :mod:`fgloc.batch` imports
``fgloc.app``, ``fgloc.bench`` or ``fgloc.mapping``.

Nothing here prints, and the only files written are the single-log commands' own
outputs in ``outdir``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fgloc.errors import ConfigError

#: one column of the paper benchmark: (label, backend, frontend, which trajectory: final | online)
Variant = tuple[str, str, str, str]


@dataclass
class LocalizeOutcome:
    """What one ``fgloc run`` produced (files are in its output folder)."""

    mode: str                      # "map" or "odom"
    poses: int
    log_s: float                   # duration of the final trajectory (log time)
    wall_s: float                  # localization wall time (as ``fgloc run`` prints it)
    lost_s: float                  # time the localizer was lost (no pose, or no accepted fix for a while)
    failure: str | None            # why ``fgloc run`` would exit 3 (lost / no pose), None when usable
    position_rmse_m: float | None = None
    heading_rmse_deg: float | None = None
    note: str | None = None        # e.g. why the ground-truth evaluation was skipped
    written: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)  # what ``fgloc run`` warns the result may be wrong about


@dataclass
class MapOutcome:
    """What one ``fgloc map`` produced."""

    scans: int
    keyframes: int
    loops: int
    duration_s: float              # log time spanned by the mapped scans
    wall_s: float                  # total mapping time (read, SLAM, occupancy, write)
    position_rmse_m: float | None = None   # of the scan trajectory vs /ground_truth (SE(2)-aligned)
    heading_rmse_deg: float | None = None


@dataclass
class SeedOutcome:
    """One seed of the paper benchmark: per-variant metrics (``Metrics.to_dict()``) and wall times."""

    seed: int
    metrics: dict[str, dict[str, Any]]
    wall_s: dict[str, float]
    duration_s: float
    poses: dict[str, int]
    written: list[str] = field(default_factory=list)


# ---------------------------------------------------------------------------- outputs
def output_names(kind: str, params: dict[str, Any]) -> tuple[tuple[str, ...], Callable[[Path], Iterable[str]]]:
    """The files a job of ``kind`` writes in its folder, and the function naming those an earlier
    version wrote there (see :class:`fgloc.io.outputs.Outputs`)."""
    if kind == "run":
        from fgloc.app.run import OUTPUT_FILES, legacy_outputs

        return OUTPUT_FILES, legacy_outputs
    if kind == "map":
        from fgloc.mapping.build import MAP_FILES, legacy_map_files

        return MAP_FILES, legacy_map_files
    labels = [v[0] for v in params.get("variants", [])]
    names = ("metrics.json", "ground_truth.tum", "map.yaml", "map.pgm", *(f"{variant_slug(x)}.tum" for x in labels))
    return names, lambda folder: ()


# ---------------------------------------------------------------------------- localize
def localize_log(log: Path, outdir: Path, map_yaml: Path | None, initial_pose: list[float] | None,
                 config_path: Path | None, backend: str, frontend: str,
                 scan_topic: str | None, odom_topic: str | None, imu_topic: str | None) -> LocalizeOutcome:
    """``fgloc run LOG [--map] [--initial-pose] ... -o OUTDIR`` as a library call (no progress bar).
    A topic None is not named: :func:`fgloc.app.run.run_log` resolves it as ``fgloc run`` does
    (the default name, the config's sources, else the log's only topic of that type)."""
    from fgloc.app.run import RunRequest, run_log
    from fgloc.backends import check_backend

    backend = check_backend(backend)  # the registry's names, a "did you mean" for a typo
    pose = None if initial_pose is None else (float(initial_pose[0]), float(initial_pose[1]), float(initial_pose[2]))
    r = run_log(RunRequest(log=log, outdir=outdir, map_yaml=map_yaml, backend=backend, frontend=frontend,
                           initial_pose=pose, config=config_path, scan_topic=scan_topic, odom_topic=odom_topic,
                           imu_topic=imu_topic))
    out = LocalizeOutcome(mode=r.mode, poses=int(r.poses), log_s=float(r.log_s), wall_s=float(r.wall_s),
                          lost_s=float(r.lost_s), failure=r.failure(), note=r.eval_error, written=list(r.written),
                          warnings=list(r.warnings))
    sp = r.by_status  # over the poses the run vouches for, as fgloc run's table; every pose if too few
    m = sp.metrics if sp is not None and sp.metrics is not None else r.metrics
    if m is not None:
        out.position_rmse_m = float(m.position_rmse_m)
        out.heading_rmse_deg = float(m.heading_rmse_deg)
    if sp is not None and sp.metrics is not None and sp.n_left_out:
        out.warnings.append(f"RMSE over the {sp.n_vouched} poses the run vouches for; left out {sp.left_out_errors()})")
    return out


# ---------------------------------------------------------------------------- map
def mapper_options(config_path: Path | None) -> dict[str, Any]:
    """The mapping options of a ``--config`` YAML (its ``mapping:`` section or the whole file),
    as ``fgloc map`` reads them."""
    import yaml

    from fgloc.config.schema import load_yaml

    if config_path is None:
        return {}
    try:
        opts = load_yaml(Path(config_path).read_text()) or {}
    except (OSError, yaml.YAMLError) as e:
        raise ConfigError(f"{config_path}: cannot read mapping config ({e.__class__.__name__})") from None
    if not isinstance(opts, dict):
        raise ConfigError(f"{config_path}: mapping config must be a mapping")
    return dict(opts.get("mapping", opts))


def map_log(log: Path, outdir: Path, resolution: float, config_path: Path | None,
            start: float | None, end: float | None, scan_topic: str, odom_topic: str) -> MapOutcome:
    """``fgloc map LOG -o OUTDIR [--resolution] [--config] [--start] [--end]`` as a library call."""
    from fgloc.mapping.build import build_map
    from fgloc.mapping.slam import MapperConfig

    if not (resolution > 0):
        raise ConfigError(f"resolution must be positive, got {resolution}")
    opts = mapper_options(config_path)
    opts["resolution"] = resolution
    cfg = MapperConfig.from_dict(opts)
    from fgloc.io.topics import resolve_name

    scan_topic, odom_topic = resolve_name(scan_topic), resolve_name(odom_topic)
    out = build_map(log, outdir, cfg, start, end, None, scan_topic, odom_topic)
    traj = out.slam.scan_trajectory
    res = MapOutcome(scans=out.n_scans, keyframes=int(out.slam.stats.get("keyframes", len(out.slam.keyframes))),
                     loops=len(out.slam.loops), duration_s=float(traj.duration),
                     wall_s=float(out.timings["total_s"]))
    gt = _ground_truth(log, scan_topic, odom_topic)
    if gt is not None and len(traj) > 1:
        from fgloc.errors import LogError
        from fgloc.eval.metrics import evaluate

        try:
            m = evaluate(traj, gt, align=True)
            res.position_rmse_m, res.heading_rmse_deg = float(m.position_rmse_m), float(m.heading_rmse_deg)
        except LogError:
            pass
    return res


def _ground_truth(log: Path, scan_topic: str, odom_topic: str):
    """``/ground_truth`` of the log (any format :func:`fgloc.io.open_log` reads), None without it."""
    from fgloc.io import open_log
    from fgloc.io.topics import Topics

    with open_log(log, Topics(scan=scan_topic, odom=odom_topic)) as source:
        return source.ground_truth()


# ---------------------------------------------------------------------------- paper bench
def paper_variants(no_amcl: bool = False, only: list[str] | None = None) -> list[Variant]:
    """The columns of ``fgloc bench paper`` (without EKF+AMCL when asked or when AMCL is missing),
    optionally only those whose label is in ``only``."""
    from fgloc.bench import paper_variants as columns

    out = list(columns(no_amcl))
    if only:
        labels = [v[0] for v in out]
        bad = [o for o in only if o not in labels]
        if bad:
            raise ConfigError(f"unknown variant {bad[0]!r} (choose from {', '.join(labels)})")
        out = [v for v in out if v[0] in only]
    return [(str(a), str(b), str(c), str(d)) for a, b, c, d in out]


def amcl_available() -> bool:
    """Whether the AMCL front-end imports (``fgloc bench paper`` leaves its column out otherwise)."""
    from fgloc.bench import frontend_available

    return frontend_available("amcl")


def bench_paper_seed(seed: int, variants: list[Variant], config_path: Path | None, outdir: Path,
                     keep: bool) -> SeedOutcome:
    """One seed of ``fgloc bench paper``: simulate the paper run with ``seed`` and localize it with
    each variant (one localization per back-end/front-end pair, as the single command does).

    Writes ``outdir/metrics.json`` (per variant: every :class:`Metrics` field, wall time, poses);
    with ``keep`` also each variant's trajectory (``<label>.tum``), ``ground_truth.tum`` and the
    map, from which the batch draws the same plots as ``fgloc bench paper -o``.

    Local adapter for the private ``fgloc.bench.paper._bench_one_seed`` (same calls, same order).
    """
    from fgloc.bench import localize_sim
    from fgloc.config import load_config
    from fgloc.eval.metrics import evaluate
    from fgloc.io.tum import write_tum
    from fgloc.sim import simulate_paper

    config = load_config(config_path)
    sim = simulate_paper(seed=seed)
    metrics: dict[str, dict[str, Any]] = {}
    walls: dict[str, float] = {}
    poses: dict[str, int] = {}
    trajs: dict[str, Any] = {}
    cache: dict[tuple[str, str], Any] = {}
    for label, backend, frontend, which in variants:
        key = (backend, frontend)
        if key not in cache:
            cache[key] = localize_sim(sim, backend, frontend, config)
        final, online, _loc, wall = cache[key]
        tr = online if which == "online" else final
        metrics[label] = evaluate(tr, sim.ground_truth).to_dict()
        walls[label] = float(wall)
        poses[label] = len(tr)
        trajs[label] = tr
    outdir.mkdir(parents=True, exist_ok=True)
    written = ["metrics.json"]
    if keep:
        for label, tr in trajs.items():
            written.append(write_tum(outdir / f"{variant_slug(label)}.tum", tr).name)
        written.append(write_tum(outdir / "ground_truth.tum", sim.ground_truth).name)
        sim.map.save(outdir / "map.yaml")
        written += ["map.yaml", "map.pgm"]
    doc = {"seed": seed, "duration_s": float(sim.ground_truth.duration),
           "variants": [list(v) for v in variants],
           "metrics": metrics, "wall_s": walls, "poses": poses}
    # JSON keeps every float exactly (repr round trip); NaN is stored as null by Metrics.to_dict
    (outdir / "metrics.json").write_text(json.dumps(doc, indent=1) + "\n")
    return SeedOutcome(seed, metrics, walls, float(sim.ground_truth.duration), poses, written)


def variant_slug(label: str) -> str:
    """A file name for a variant label ('smoother fixed-lag' -> 'smoother_fixed-lag')."""
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in label).strip("_")


def load_seed_metrics(outdir: Path) -> dict[str, Any]:
    """``metrics.json`` of a finished seed, metrics turned back into :class:`Metrics` objects."""
    from fgloc.eval.metrics import Metrics

    doc = json.loads((outdir / "metrics.json").read_text())
    out: dict[str, Metrics] = {}
    for k, d in doc["metrics"].items():
        fields: dict[str, Any] = {f: (math.nan if v is None else v) for f, v in d.items()}
        out[k] = Metrics(**fields)
    doc["metrics"] = out
    return doc


def paper_table(rows: dict[str, list[Any]], seeds: int) -> str:
    """The Markdown table ``fgloc bench paper`` prints (same title, same cells)."""
    from fgloc.eval.paper import comparison_text

    return comparison_text(rows, title=f"paper replica: {seeds} seed(s), mean ± std over seeds")


def paper_outputs(rows: dict[str, list[Any]], seeds: int, outdir: Path, seed0_dir: Path | None,
                  variants: list[Variant]) -> list[Path]:
    """What ``fgloc bench paper -o OUTDIR`` writes: table.md, metrics.yaml and (from seed 0) the plots."""
    from fgloc.eval.paper import comparison_text
    from fgloc.io.yamlio import write_yaml

    outdir.mkdir(parents=True, exist_ok=True)
    (outdir / "table.md").write_text(comparison_text(rows, title=f"paper replica, {seeds} seeds") + "\n")
    summary = {label: {k: [m.to_dict()[k] for m in ms] for k in ("position_rmse_m", "heading_rmse_deg")}
               for label, ms in rows.items()}
    write_yaml(outdir / "metrics.yaml", summary)
    files = [outdir / "table.md", outdir / "metrics.yaml"]
    if seed0_dir is not None and (seed0_dir / "ground_truth.tum").exists():
        from fgloc.eval.plots import plot_all
        from fgloc.io.tum import read_tum
        from fgloc.maps import OccupancyMap

        trajs = {label: read_tum(seed0_dir / f"{variant_slug(label)}.tum") for label, *_ in variants
                 if (seed0_dir / f"{variant_slug(label)}.tum").exists()}
        gt = read_tum(seed0_dir / "ground_truth.tum")
        occ = OccupancyMap.load(seed0_dir / "map.yaml")
        files += plot_all(trajs, gt, outdir, occ_map=occ, title="paper replica, seed 0")
    return files


def paper_claims(rows: dict[str, list[Any]]) -> list[str]:
    """The target lines ``fgloc bench paper`` prints under its table."""
    from fgloc.bench import claims

    return claims(rows)
