"""``fgloc batch``: ``run`` / ``map`` many logs and ``bench paper`` many seeds, locally or on Ray.

    fgloc batch run runs/ --map hall.yaml --initial-pose 2.5 3 0 -o out/ -j 2
    fgloc batch run --manifest fleet.csv -o out/ --engine ray [--address HOST:PORT] [--ship-inputs]
    fgloc batch map logs/ -o maps/ --engine ray
    fgloc batch bench paper --seeds 100 --engine ray -o bench/

Exit status: 0 all logs done, 1 some logs failed or were lost (see the summary), 130 interrupted
(finished logs kept: run the same command again to do the rest), 2 a usage error.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from fgloc.app.units import pose_value

ENGINE = typer.Option("--engine", help="local (process pool) | ray")
JOBS = typer.Option("--jobs", "-j", help="worker processes (local) / CPUs of the local Ray instance; default all")
ADDRESS = typer.Option("--address", help="join this Ray cluster (HOST:PORT; default $RAY_ADDRESS); "
                                         "without: a private local Ray instance")
SHIP = typer.Option("--ship-inputs", help="send logs, maps and config to the workers as data (no shared "
                                          "storage needed); default: workers read them by path")
FORCE = typer.Option("--force", help="run again the logs whose outputs are complete")
QUIET = typer.Option("--quiet", "-q", help="no progress bar")


def _opts(engine: str, jobs: int | None, address: str | None, ship: bool, force: bool, quiet: bool):
    import sys

    from fgloc.batch import EngineOptions

    # a progress bar on a terminal only: a pipe or a log file gets no carriage-return lines
    return EngineOptions(engine, jobs, address, ship, force, not quiet and sys.stderr.isatty())


def _console():
    """Rich's console; into a file or pipe (no terminal width, no $COLUMNS) 160 columns, not 80, so
    the summary table keeps its error column readable in a saved log."""
    import os

    from rich.console import Console

    con = Console()
    return con if con.is_terminal or os.environ.get("COLUMNS") else Console(width=160)


def _report(rep, title: str) -> None:
    """Print the summary table and the totals; exit 130 when interrupted, 1 when a log failed."""
    from fgloc.batch import summary_table

    con = _console()
    con.print(summary_table(rep.rows, title))
    for r in rep.rows:
        if r.status == "error":
            con.print(f"[red]{r.log}[/red]: {r.error}", soft_wrap=True, highlight=False)
    n = len(rep.rows)
    ok = sum(r.status in ("ok", "done") for r in rep.rows)
    con.print(f"{ok}/{n} done ({rep.ran} ran, {rep.skipped} already done), {rep.failed} failed; "
              f"{rep.engine}; {rep.wall_s:.1f} s; summary: {rep.summary_csv}")
    if rep.interrupted:
        con.print("[yellow]interrupted[/yellow]: finished logs are kept; run the same command again for the rest")
        raise SystemExit(130)  # (typer.Exit's status is dropped by fgloc.cli.main's standalone_mode=False)
    if rep.failed:
        raise SystemExit(1)


def run_cmd(
    outdir: Annotated[Path, typer.Option("-o", "--output", help="OUTDIR: OUTDIR/<log>/ per log, summary.csv")],
    logs: Annotated[list[str] | None, typer.Argument(help="MCAP logs, folders, globs")] = None,
    manifest: Annotated[Path | None, typer.Option("--manifest", help="CSV 'log,map,x,y,yaw' (m, m, rad "
                                                               "or 90deg), one log per row")] = None,
    map_yaml: Annotated[Path | None, typer.Option("--map", help="map_server YAML for every log (manifest rows "
                                                                "may name their own)")] = None,
    backend: Annotated[str, typer.Option("--backend", help="ekf | smoother | batch")] = "smoother",
    frontend: Annotated[str, typer.Option("--frontend", help="amcl | kiss | native")] = "native",
    initial_pose: Annotated[tuple[float, float, float] | None, typer.Option(
        "--initial-pose", parser=pose_value,
        help="X Y YAW for every log (m, m and rad, or the yaw with its unit: 90deg; manifest "
                               "rows may give their own)")] = None,
    config: Annotated[Path | None, typer.Option("--config", help="YAML overriding the built-in config "
                                                                     "(`fgloc config show`)")] = None,
    scan_topic: Annotated[str | None, typer.Option("--scan-topic", help="as fgloc run's [default: /scan, else "
                                                                       "the log's only LaserScan topic]")] = None,
    odom_topic: Annotated[str | None, typer.Option("--odom-topic", help="as fgloc run's [default: /odom or the "
                                                                       "config's sources, else the log's only "
                                                                       "Odometry topic]")] = None,
    imu_topic: Annotated[str | None, typer.Option("--imu-topic", help="as fgloc run's [default: /imu or the "
                                                                     "config's sources, else the log's only Imu "
                                                                     "topic]")] = None,
    allow_lost: Annotated[bool, typer.Option("--allow-lost", help="a log whose localizer was lost (fgloc run "
                                                                 "exits 3) counts as done, not failed (finished "
                                                                 "logs are judged again, not re-run)")] = False,
    engine: Annotated[str, ENGINE] = "local",
    jobs: Annotated[int | None, JOBS] = None,
    address: Annotated[str | None, ADDRESS] = None,
    ship_inputs: Annotated[bool, SHIP] = False,
    force: Annotated[bool, FORCE] = False,
    quiet: Annotated[bool, QUIET] = False,
) -> None:
    """Localize many logs as `fgloc run` does each: OUTDIR/<log>/ and OUTDIR/summary.csv."""
    from fgloc.app.units import pose_arg
    from fgloc.batch import batch_run

    rep = batch_run(list(logs or []), outdir, _opts(engine, jobs, address, ship_inputs, force, quiet), manifest,
                    map_yaml, list(pose_arg(initial_pose) or ()) or None, config, backend, frontend,
                    scan_topic, odom_topic, imu_topic, allow_lost)
    _report(rep, f"fgloc batch run: {len(rep.rows)} log(s)")


def map_cmd(
    logs: Annotated[list[str], typer.Argument(help="CARMEN or MCAP logs, folders, globs")],
    outdir: Annotated[Path, typer.Option("-o", "--output", help="OUTDIR: OUTDIR/<log>/ per log, summary.csv")],
    resolution: Annotated[float, typer.Option(help="map cell size (m)")] = 0.05,
    config: Annotated[Path | None, typer.Option(help="YAML with mapping options")] = None,
    start: Annotated[float | None, typer.Option(help="first fraction of the scans to use (0..1)")] = None,
    end: Annotated[float | None, typer.Option(help="last fraction of the scans to use (0..1)")] = None,
    scan_topic: Annotated[str, typer.Option(help="scan topic (MCAP)")] = "/scan",
    odom_topic: Annotated[str, typer.Option(help="odometry topic (MCAP)")] = "/odom",
    engine: Annotated[str, ENGINE] = "local",
    jobs: Annotated[int | None, JOBS] = None,
    address: Annotated[str | None, ADDRESS] = None,
    ship_inputs: Annotated[bool, SHIP] = False,
    force: Annotated[bool, FORCE] = False,
    quiet: Annotated[bool, QUIET] = False,
) -> None:
    """Map many logs as `fgloc map` does each: OUTDIR/<log>/map.yaml ... and OUTDIR/summary.csv."""
    from fgloc.batch import batch_map

    rep = batch_map(list(logs), outdir, _opts(engine, jobs, address, ship_inputs, force, quiet), resolution,
                    config, start, end, scan_topic, odom_topic)
    _report(rep, f"fgloc batch map: {len(rep.rows)} log(s)")


def bench_paper_cmd(
    seeds: Annotated[int, typer.Option("--seeds", help="simulated runs (seeds 0..N-1)")] = 5,
    outdir: Annotated[Path, typer.Option("-o", "--output", help="OUTDIR/seed-NNN/ per seed; table.md, "
                                                                "metrics.yaml, plots, summary.csv")] = Path(
        "fgloc-batch-bench"),
    config: Annotated[Path | None, typer.Option("--config", help="YAML overlaid on the defaults "
                                                                 "(`fgloc config show`)")] = None,
    no_amcl: Annotated[bool, typer.Option("--no-amcl", help="skip the EKF+AMCL column")] = False,
    only: Annotated[list[str] | None, typer.Option("--only", help="only this column (repeatable), "
                                                                   "e.g. 'EKF+native'")] = None,
    no_plots: Annotated[bool, typer.Option("--no-plots", help="no seed-0 trajectories and plots")] = False,
    engine: Annotated[str, ENGINE] = "local",
    jobs: Annotated[int | None, JOBS] = None,
    address: Annotated[str | None, ADDRESS] = None,
    ship_inputs: Annotated[bool, SHIP] = False,
    force: Annotated[bool, FORCE] = False,
    quiet: Annotated[bool, QUIET] = False,
) -> None:
    """`fgloc bench paper` over N seeds as a batch: the same table, resumable, local or on Ray."""
    from fgloc.batch import batch_bench_paper
    from fgloc.batch.adapter import amcl_available

    con = _console()
    if not amcl_available() and not no_amcl:
        con.print("[yellow]AMCL front-end not available: the EKF+AMCL column is left out[/yellow]")
    res = batch_bench_paper(seeds, outdir, _opts(engine, jobs, address, ship_inputs, force, quiet), config,
                            no_amcl, list(only) if only else None, not no_plots)
    if res.table:
        from fgloc.eval.paper import show_comparison, styled_claim

        # as `fgloc bench paper` prints it: drawn on a terminal, Markdown into a pipe or a file
        show_comparison(res.rows, title=f"paper replica: {len(next(iter(res.rows.values())))} seed(s), mean ± std "
                        "over seeds")
        for line in res.claims:
            con.print("  " + styled_claim(line), highlight=False)
        con.print("  wall time per run: " + ", ".join(f"{k} {v:.1f} s" for k, v in res.walls.items()))
        con.print(f"  wrote {outdir}/table.md, metrics.yaml and {max(0, len(res.files) - 2)} plots")
    elif not res.batch.interrupted:
        con.print("[red]no seed finished[/red]: no table")
    _report(res.batch, f"fgloc batch bench paper: {seeds} seed(s)")


def register(app: typer.Typer) -> None:
    batch = typer.Typer(help="Many logs or seeds with the single-log code: local process pool or Ray.",
                        no_args_is_help=True)
    app.add_typer(batch, name="batch")
    batch.command("run")(run_cmd)
    batch.command("map")(map_cmd)
    bench = typer.Typer(help="Benchmarks over many seeds.", no_args_is_help=True)
    batch.add_typer(bench, name="bench")
    bench.command("paper")(bench_paper_cmd)
