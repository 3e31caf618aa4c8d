"""Library functions behind ``fgloc batch run | map | bench paper`` (the CLI only parses and prints)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fgloc.batch import adapter
from fgloc.batch.engines import make_engine
from fgloc.batch.inputs import (
    MAP_SUFFIXES,
    RUN_SUFFIXES,
    bench_paper_jobs,
    discover_logs,
    map_jobs,
    read_manifest,
    run_jobs,
)
from fgloc.batch.jobs import Job
from fgloc.batch.runner import BatchReport, run_batch
from fgloc.errors import ConfigError


@dataclass
class EngineOptions:
    """How to run: ``engine`` local | ray (| inline), ``jobs`` workers / local Ray CPUs, Ray
    ``address``, ``ship`` inputs as data, ``force`` re-running finished jobs, ``progress`` bar."""

    engine: str = "local"
    jobs: int | None = None
    address: str | None = None
    ship: bool = False
    force: bool = False
    progress: bool = True


def _engine(opts: EngineOptions) -> Any:
    """The engine, already starting when it has a start-up (Ray: joining or starting the cluster in
    the background while the caller finds the logs, fingerprints them and reads the markers)."""
    if opts.jobs is not None and opts.jobs < 1:
        raise ConfigError("-j must be at least 1")
    engine = make_engine(opts.engine, opts.jobs, opts.address)
    if hasattr(engine, "start"):
        engine.start()
    return engine


def _run(prepare: Callable[[], list[Job]], outdir: Path, opts: EngineOptions, desc: str) -> BatchReport:
    """Start the engine, then ``prepare()`` the jobs meanwhile, then run them (an error while
    preparing stops the engine again)."""
    engine = _engine(opts)
    try:
        jobs = prepare()
    except BaseException:
        if hasattr(engine, "shutdown"):
            engine.shutdown()
        raise
    return run_batch(jobs, outdir, engine, ship=opts.ship, force=opts.force, progress=opts.progress, desc=desc)


def batch_run(logs: list[str], outdir: Path, opts: EngineOptions, manifest: Path | None = None,
              map_yaml: Path | None = None, initial_pose: list[float] | None = None, config: Path | None = None,
              backend: str = "smoother", frontend: str = "native", scan_topic: str | None = None,
              odom_topic: str | None = None, imu_topic: str | None = None, allow_lost: bool = False) -> BatchReport:
    """Localize every log (``fgloc run`` each) into ``outdir/<name>/``; ``outdir/summary.csv``."""
    from fgloc.backends import check_backend

    backend = check_backend(backend)  # the registry's names, a "did you mean" for a typo
    if not logs and manifest is None:
        raise ConfigError("give LOGS (files, folders, globs) or --manifest FILE")

    def prepare() -> list[Job]:
        paths = discover_logs(logs, RUN_SUFFIXES, exclude=outdir) if logs else []
        rows = read_manifest(manifest) if manifest is not None else None
        return run_jobs(paths, outdir, map_yaml, initial_pose, config, backend, frontend, scan_topic, odom_topic,
                        imu_topic, rows, allow_lost)

    return _run(prepare, outdir, opts, "localizing logs")


def batch_map(logs: list[str], outdir: Path, opts: EngineOptions, resolution: float = 0.05,
              config: Path | None = None, start: float | None = None, end: float | None = None,
              scan_topic: str = "/scan", odom_topic: str = "/odom") -> BatchReport:
    """Map every log (``fgloc map`` each) into ``outdir/<name>/``; ``outdir/summary.csv``."""
    if not logs:
        raise ConfigError("give LOGS (files, folders, globs)")
    if not (resolution > 0):
        raise ConfigError(f"resolution must be positive, got {resolution}")

    def prepare() -> list[Job]:
        if config is not None:
            adapter.mapper_options(config)  # a bad mapping config fails once, up front
        paths = discover_logs(logs, MAP_SUFFIXES, exclude=outdir)
        return map_jobs(paths, outdir, resolution, config, start, end, scan_topic, odom_topic)

    return _run(prepare, outdir, opts, "mapping logs")


@dataclass
class BenchReport:
    """``fgloc batch bench paper``: the batch report and the same aggregates ``fgloc bench paper`` prints."""

    batch: BatchReport
    seeds: int
    variants: list[tuple[str, str, str, str]]
    rows: dict[str, list[Any]] = field(default_factory=dict)      # label -> [Metrics per finished seed]
    walls: dict[str, float] = field(default_factory=dict)         # label -> mean wall time per run (s)
    files: list[Path] = field(default_factory=list)
    table: str = ""
    claims: list[str] = field(default_factory=list)


def batch_bench_paper(seeds: int, outdir: Path, opts: EngineOptions, config: Path | None = None,
                      no_amcl: bool = False, only: list[str] | None = None, plots: bool = True) -> BenchReport:
    """``fgloc bench paper --seeds N`` as a batch: one job per seed, resumable, on any engine.

    Writes ``outdir/seed-NNN/metrics.json`` per seed, then (over the finished seeds) the same
    ``table.md``, ``metrics.yaml`` and (``plots``) seed-0 plots as ``fgloc bench paper -o``.
    """
    import numpy as np

    from fgloc.eval.plots import plot_files
    from fgloc.io.outputs import Outputs

    variants = adapter.paper_variants(no_amcl, only)
    jobs = bench_paper_jobs(seeds, outdir, variants, config, keep_seed0=plots)
    outs = Outputs(outdir, ("table.md", "metrics.yaml", *plot_files()), command="bench paper", force=opts.force)
    outs.check()  # before the seeds run: a table.md fgloc did not write is refused at once
    rep = _run(lambda: jobs, outdir, opts, "seeds")
    done = [j for j in jobs if any(r.log == j.name and r.status in ("ok", "done") for r in rep.rows)]
    docs = [adapter.load_seed_metrics(Path(j.outdir)) for j in done]
    out = BenchReport(rep, seeds, variants)
    if not docs:
        return out
    out.rows = {label: [d["metrics"][label] for d in docs] for label, *_ in variants}
    out.walls = {label: float(np.mean([d["wall_s"][label] for d in docs])) for label, *_ in variants}
    n = len(docs)
    out.table = adapter.paper_table(out.rows, n)
    out.claims = adapter.paper_claims(out.rows)
    seed0 = next((Path(j.outdir) for j in done if j.params.get("keep")), None) if plots else None
    with outs:
        staged = adapter.paper_outputs(out.rows, n, outs.dir, seed0, variants)
    out.files = [outs.final(p.name) for p in staged]
    return out
