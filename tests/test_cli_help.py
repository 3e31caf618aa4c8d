"""Every command's --help prints and exits 0 (a help text is plain text, never markup)."""

from __future__ import annotations

import pytest
import typer

from fgloc.cli import app, main


def _commands() -> list[list[str]]:
    root = typer.main.get_command(app)
    out: list[list[str]] = []

    def walk(cmd, path: list[str]) -> None:  # typer vendors click: match groups by shape
        out.append(path)
        if hasattr(cmd, "commands"):
            for name, sub in cmd.commands.items():
                walk(sub, [*path, name])

    walk(root, [])
    return out


COMMANDS = _commands()


def test_the_command_tree_is_complete():
    names = {" ".join(p) for p in COMMANDS}
    assert {"run", "map", "map-check", "batch run", "config show", "bench paper", "live"} <= names


@pytest.mark.parametrize("path", COMMANDS, ids=lambda p: " ".join(p) or "fgloc")
def test_help_prints_and_exits_0(path, capsys):
    assert main([*path, "--help"]) == 0
    out = capsys.readouterr().out
    assert "Usage:" in out and len(out) > 100


def test_exit_code_of_a_command_reaches_the_shell():
    # typer.Exit(code) inside a command must not be turned into 0
    assert main(["run", "does-not-exist.mcap"]) == 2


def test_simulate_scenario_by_shipped_name(tmp_path, capsys):
    assert main(["simulate", "scenario", "no_such_scenario", "-o", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "wheel_slip" in err
    assert main(["simulate", "list"]) == 0
    assert "kidnap" in capsys.readouterr().out.split()
