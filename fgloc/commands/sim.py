"""``fgloc simulate paper|scenario``: write a simulated run (log.mcap, map, ground truth).

Usage::

    fgloc simulate paper -o DIR [--seed N]
    fgloc simulate scenario wheel_slip -o DIR [--seed N]   # shipped (fgloc simulate list) or a YAML file

DIR gets ``log.mcap`` (/scan, /odom, /imu, /tf_static, /ground_truth), ``map.yaml`` +
``map.pgm``, ``ground_truth.tum`` and ``scenario.yaml`` (the effective parameters).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import typer

simulate_app = typer.Typer(help="Simulate the paper's experiment or a YAML scenario.", no_args_is_help=True)


@contextmanager
def _progress(text: str):
    """A rich progress bar on stderr; yields a callback taking the done fraction (0..1)."""
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    with Progress(TextColumn("{task.description}"), BarColumn(), TextColumn("{task.percentage:>3.0f}%"),
                  TimeElapsedColumn(), console=Console(stderr=True), transient=True) as bar:
        task = bar.add_task(text, total=1.0)

        def update(frac: float) -> None:
            bar.update(task, completed=frac)

        yield update
        bar.update(task, completed=1.0)


FORCE_HELP = "overwrite output files that fgloc did not write"


def _simulate_and_write(run: Callable[[Callable[[float], None]], Any], label: str, out: Path, force: bool = False,
                        inputs: tuple[str, ...] = ()) -> None:
    from fgloc.io import stop
    from fgloc.io.outputs import Outputs, refuse_file_name
    from fgloc.sim import write_sim
    from fgloc.sim.simulate import SIM_FILES

    refuse_file_name(out, SIM_FILES, "simulate")
    outs = Outputs(out, SIM_FILES, command="simulate", inputs=inputs, force=force)
    outs.check()  # before simulating: a folder holding someone else's map.yaml is refused at once
    t0 = time.perf_counter()
    with _progress(f"simulating {label}") as update:
        def step(frac: float) -> None:
            stop.checkpoint()  # Ctrl-C / SIGTERM: between two simulated scans
            update(frac)

        result = run(step)
    t_sim = time.perf_counter() - t0
    with _progress(f"writing {out}") as update, outs:
        write_sim(result, outs.dir)
        update(1.0)
    counts: dict[str, int] = {}
    for topic, _ in result.messages:
        counts[topic] = counts.get(topic, 0) + 1
    gt = result.ground_truth
    print(f"{out}: {gt.duration:.1f} s, {gt.path_length():.1f} m, "
          + ", ".join(f"{k} {v}" for k, v in sorted(counts.items()))
          + _heading_offset(result)
          + f"; simulated in {t_sim:.1f} s")


def _heading_offset(result: Any) -> str:
    """The simulated heading source's offset from the map's north, as a summary clause ("" without one)."""
    sc = result.scenario
    source = "IMU yaw" if sc.get("imu") is not None else "compass" if sc.get("compass") is not None else None
    if source is None:
        return ""
    return f"; {source} offset {float(result.compass_offset_rad) * 57.29577951308232:.2f} deg"


@simulate_app.command("paper")
def paper(
    out: Path = typer.Option(None, "-o", "--output", help="output folder (required)"),
    out_old: Path = typer.Option(None, "--out", hidden=True, help="the old name of --output"),
    seed: int = typer.Option(0, help="random seed (same seed, same run)"),
    force: bool = typer.Option(False, "--force", help=FORCE_HELP),
) -> None:
    """The paper's run: mecanum robot, 78 m rectangle at 0.8 m/s, encoders + compass + 270 deg laser."""
    from fgloc.sim import simulate_paper

    dest = _output(out, out_old, "paper")
    _simulate_and_write(lambda cb: simulate_paper(seed=seed, progress=cb), "the paper run", dest, force)


def _output(out: Path | None, out_old: Path | None, what: str) -> Path:
    """``-o/--output`` (or the old ``--out``); a one-line error without either."""
    from fgloc.errors import ConfigError

    dest = out or out_old
    if dest is None:
        raise ConfigError(f"fgloc simulate {what}: give the output folder with -o / --output")
    return dest


@simulate_app.command("scenario")
def scenario(
    file: str = typer.Argument(..., help="a scenario YAML file, or the name of a shipped one "
                               "(paper, wheel_slip, compass_disturbance, kidnap, blackout, obstacles, willow, "
                               "skid_steer, ...: `fgloc simulate list`)"),
    out: Path = typer.Option(None, "-o", "--output", help="output folder (required)"),
    out_old: Path = typer.Option(None, "--out", hidden=True, help="the old name of --output"),
    seed: int = typer.Option(0, help="random seed"),
    force: bool = typer.Option(False, "--force", help=FORCE_HELP),
) -> None:
    """A YAML scenario: map, route, drive, noise and faults."""
    from fgloc.sim import run_scenario

    dest = _output(out, out_old, "scenario")
    path = _scenario_file(file)
    _simulate_and_write(lambda cb: run_scenario(path, seed=seed, progress=cb), file, dest, force, (path,))


def _scenario_file(name_or_path: str) -> str:
    """A path as given, or the shipped scenario of that name; one-line error listing the names otherwise."""
    from fgloc.config import scenario_names, scenario_path
    from fgloc.errors import ConfigError

    if Path(name_or_path).exists():
        return name_or_path
    names = scenario_names()
    if name_or_path in names:
        return str(scenario_path(name_or_path))
    from fgloc.config.schema import suggest

    raise ConfigError(f"{name_or_path}: no such scenario file, and no shipped scenario of that name"
                      f"{suggest(Path(name_or_path).stem, names)} (shipped: {', '.join(names)})")


@simulate_app.command("list")
def list_scenarios() -> None:
    """The shipped scenarios (use a name with `fgloc simulate scenario NAME -o DIR`)."""
    from fgloc.config import scenario_names

    for name in scenario_names():
        print(name)


def register(app: typer.Typer) -> None:
    app.add_typer(simulate_app, name="simulate")
