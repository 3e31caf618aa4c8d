"""``fgloc simulate paper|scenario``: write a simulated run (log.mcap, map, ground truth)."""

from __future__ import annotations

from pathlib import Path

import typer

simulate_app = typer.Typer(help="Simulate the paper's experiment or a YAML scenario.", no_args_is_help=True)


def _write(result, out: Path) -> None:
    from fgloc.sim import write_sim

    with _spinner(f"writing {out}"):
        write_sim(result, out)
    counts: dict[str, int] = {}
    for topic, _ in result.messages:
        counts[topic] = counts.get(topic, 0) + 1
    gt = result.ground_truth
    print(f"{out}: {gt.duration:.1f} s, {gt.path_length():.1f} m, "
          + ", ".join(f"{k} {v}" for k, v in sorted(counts.items()))
          + f"; compass offset {float(result.compass_offset_rad) * 57.29577951308232:.2f} deg")


def _spinner(text: str):
    from rich.console import Console

    return Console(stderr=True).status(text)


@simulate_app.command("paper")
def paper(
    out: Path = typer.Option(..., "-o", "--out", help="output folder"),
    seed: int = typer.Option(0, help="random seed (same seed, same run)"),
) -> None:
    """The paper's run: mecanum robot, 78 m rectangle at 0.8 m/s, encoders + compass + 270 deg laser."""
    from fgloc.sim import simulate_paper

    with _spinner("simulating the paper run"):
        result = simulate_paper(seed=seed)
    _write(result, out)


@simulate_app.command("scenario")
def scenario(
    file: Path = typer.Argument(..., help="scenario YAML (see config/scenarios/)"),
    out: Path = typer.Option(..., "-o", "--out", help="output folder"),
    seed: int = typer.Option(0, help="random seed"),
) -> None:
    """A YAML scenario: map, route, drive, noise and faults."""
    from fgloc.sim import run_scenario

    with _spinner(f"simulating {file}"):
        result = run_scenario(file, seed=seed)
    _write(result, out)


def register(app: typer.Typer) -> None:
    app.add_typer(simulate_app, name="simulate")
