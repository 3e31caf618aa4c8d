"""``fgloc bench`` (paper replica, speed, fault scenarios) and ``fgloc demo``.

The CLI only parses and prints: the work is :mod:`fgloc.bench`.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import typer

from fgloc.errors import ConfigError

__all__ = ["register"]


def register(app: typer.Typer) -> None:
    bench = typer.Typer(help="Benchmarks: the paper replica, fault scenarios.", no_args_is_help=True)
    app.add_typer(bench, name="bench")

    @bench.command("paper")
    def bench_paper_cmd(
        seeds: int = typer.Option(5, "--seeds", help="simulated runs (seeds 0..N-1)"),
        outdir: Path | None = typer.Option(None, "-o", "--output", help="write plots, table.md, metrics.yaml"),
        config: Path | None = typer.Option(None, "--config", help="YAML overlaid on the defaults "
                                                       "(`fgloc config show`)"),
        jobs: int = typer.Option(2, "--jobs", "-j", help="parallel processes"),
        no_amcl: bool = typer.Option(False, "--no-amcl", help="skip the EKF+AMCL column"),
        force: bool = typer.Option(False, "--force", help="overwrite output files that fgloc did not write"),
    ) -> None:
        """The paper experiment over N seeds: the paper's numbers beside EKF, smoother and batch."""
        from rich.console import Console

        from fgloc.bench import bench_paper, claims, frontend_available, paper_variants
        from fgloc.eval.paper import show_comparison, styled_claim

        if seeds < 1:
            raise ConfigError("--seeds must be at least 1")
        con = Console()
        have_amcl = frontend_available("amcl")
        if not have_amcl and not no_amcl:
            con.print("[yellow]AMCL front-end not available: the EKF+AMCL column is left out[/yellow]")
        variants = paper_variants(no_amcl)
        import sys

        res = bench_paper(seeds, outdir, variants, config, jobs, quiet=not sys.stderr.isatty(), force=force)
        # a drawn table on a terminal; Markdown (pasteable into the README) into a pipe or a file
        show_comparison(res["rows"], title=f"paper replica: {seeds} seed(s), mean ± std over seeds")
        for line in claims(res["rows"]):
            con.print("  " + styled_claim(line), highlight=False)
        con.print("  wall time per run: " + ", ".join(f"{k} {v:.1f} s" for k, v in res["walls"].items()))
        if outdir is not None:
            con.print(f"  wrote {outdir}/table.md, metrics.yaml and {len(res['files'])} plots")

    @bench.command("speed")
    def bench_speed_cmd(
        workdir: Path = typer.Option(Path("fgloc-bench-speed"), "-w", "--workdir",
                                     help="where the generated logs and the runs' outputs go (logs reused)"),
        repeats: int = typer.Option(3, "--repeats", help="measurements per row (medians and ranges)"),
        logs: str = typer.Option("office,paper", "--logs", help="office (120 s, Willow Garage map), paper"),
        before: Path | None = typer.Option(None, "--before", help="a folder holding an older fgloc package: "
                                           "its fgloc run timed beside this one (before / after)"),
        after: Path | None = typer.Option(None, "--after", help="a folder holding the fgloc package to time as "
                                          "'after' (default: the one installed), e.g. a snapshot of a commit"),
        long_minutes: float | None = typer.Option(None, "--long-minutes",
                                                  help="also fgloc run on an N-minute office log (peak RSS)"),
        no_every1: bool = typer.Option(False, "--no-every1", help="skip the frontend_every: 1 rows"),
        no_kiss: bool = typer.Option(False, "--no-kiss", help="skip kiss-icp's odometry"),
        no_bytecode_cache: bool = typer.Option(False, "--no-bytecode-cache", help="start the children as the "
                                               "environment says (PYTHONDONTWRITEBYTECODE: compiling fgloc at "
                                               "every start) instead of from a bytecode cache in WORKDIR/pycache"),
    ) -> None:
        """The whole `fgloc run` command (a child process) beside reading the log, the in-memory
        pipeline and kiss-icp's odometry: x real time, ms per scan, start-up, peak RSS, I/O share."""
        from rich.console import Console

        from fgloc.bench.speed import bench_speed, report_lines

        if repeats < 1:
            raise ConfigError("--repeats must be at least 1")
        con = Console(stderr=True)
        with con.status("fgloc bench speed") as status:
            rep = bench_speed(workdir, repeats=repeats, logs=[s.strip() for s in logs.split(",") if s.strip()],
                              every1=not no_every1, before=before, kiss=not no_kiss, long_minutes=long_minutes,
                              say=lambda line: status.update(line), after=after,
                              bytecode_cache=not no_bytecode_cache)
        print("\n".join(report_lines(rep)))

    @bench.command("faults")
    def bench_faults_cmd(
        backend: str = typer.Option("smoother", "--backend"),
        frontend: str = typer.Option("native", "--frontend"),
        seeds: int = typer.Option(1, "--seeds", help="simulated runs per scenario (seeds 0..N-1)"),
        config: Path | None = typer.Option(None, "--config", help="YAML overlaid on the defaults "
                                                       "(`fgloc config show`)"),
    ) -> None:
        """Compass disturbance, wheel slip and kidnapping vs the fault-free paper run."""
        from rich.console import Console
        from rich.table import Table

        from fgloc.bench import bench_faults

        rows = bench_faults(backend, frontend, seeds, config)
        t = Table(title=f"fault scenarios ({backend} + {frontend})")
        for c in ("seed", "scenario", "RMSE fault-free (m)", "RMSE (m)", "increase (m)", "recovery (s)"):
            t.add_column(c, justify="right")
        for r in rows:
            if "error" in r:
                t.add_row(str(r["seed"]), r["scenario"], "-", "-", r["error"], "-")
                continue
            rec = r.get("recovery_s")
            t.add_row(str(r["seed"]), r["scenario"], f"{r['rmse0']:.4f}", f"{r['rmse']:.4f}",
                      f"{r['delta']:+.4f}", "-" if rec is None else f"{rec:.2f}")
        Console().print(t)

    @app.command("demo")
    def demo_cmd(
        outdir: Path = typer.Option(Path("fgloc-demo"), "-o", "--output", help="plots and trajectories"),
        force: bool = typer.Option(False, "--force", help="overwrite output files that fgloc did not write"),
    ) -> None:
        """The paper experiment (seed 0) localized by the paper's EKF and the smoother; table and plots."""
        import sys

        from rich.console import Console
        from tqdm import tqdm

        from fgloc.bench import frontend_available, localize_sim
        from fgloc.config import load_config
        from fgloc.eval.metrics import evaluate
        from fgloc.eval.paper import show_comparison
        from fgloc.eval.plots import plot_all
        from fgloc.io.tum import write_tum
        from fgloc.sim import simulate_paper, write_sim

        con = Console(stderr=True)
        tty = sys.stderr.isatty()
        t0 = time.perf_counter()

        def stage(text: str) -> None:  # a line per stage into a pipe or a log file; the bars say it on a terminal
            if not tty:
                print(f"fgloc demo: {text} ({time.perf_counter() - t0:.0f} s)", file=sys.stderr, flush=True)

        ekf_fe = "amcl" if frontend_available("amcl") else "native"
        runs = ((f"EKF+{ekf_fe} (paper's filter)", "ekf", ekf_fe), ("smoother+native", "smoother", "native"))
        from fgloc.eval.plots import plot_files
        from fgloc.io import stop
        from fgloc.io.outputs import Outputs
        from fgloc.sim.simulate import SIM_FILES

        outs = Outputs(outdir, (*(f"sim/{n}" for n in SIM_FILES), "ekf.tum", "smoother.tum", *plot_files()),
                       command="demo", force=force)
        outs.check()  # before the work: files fgloc did not write are refused at once
        stage(f"simulating the paper experiment (seed 0), then localizing it {len(runs)} times")
        with outs:  # a Ctrl-C stops between two messages (fgloc.io.stop); the folder stays as it was
            with tqdm(total=100, desc="simulating", unit="%", disable=not tty, leave=False,
                      bar_format="{desc}: {percentage:3.0f}%|{bar}| {elapsed}") as bar:
                def sim_progress(frac: float) -> None:
                    stop.checkpoint()
                    bar.update(max(0, round(100 * frac) - bar.n))

                sim = simulate_paper(seed=0, progress=sim_progress)
                write_sim(sim, outs.dir / "sim")
            config = load_config()
            trajs, rows = {}, {}
            for k, (label, backend, frontend) in enumerate(runs, start=1):
                stage(f"localizing {k}/{len(runs)}: {label}")
                final, _online, _loc, _ = localize_sim(
                    sim, backend, frontend, config,
                    progress=lambda msgs, label=label: _checked(tqdm(msgs, desc=f"localizing: {label}", unit="msg",
                                                                     disable=not tty, leave=False, mininterval=0.5)))
                trajs[label] = final
                rows[label] = [evaluate(final, sim.ground_truth)]
                write_tum(outs.path(f"{backend}.tum"), final)
            stage("plotting")
            show_comparison(rows, title="paper replica, seed 0: the paper's numbers vs fgloc")
            files = plot_all(trajs, sim.ground_truth, outs.dir, occ_map=sim.map, title="paper replica, seed 0")
        con.print(f"wrote {len(files)} plots, ekf.tum, smoother.tum and the simulated log to {outdir} "
                  f"in {time.perf_counter() - t0:.0f} s")


def _checked(messages: Any) -> Any:
    """``messages`` with a stop check before each (a Ctrl-C ends the demo between two messages)."""
    from fgloc.io.stop import checkpoint

    for m in messages:
        checkpoint()
        yield m
