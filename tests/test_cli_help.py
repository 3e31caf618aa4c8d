"""Every command's --help prints and exits 0 (a help text is plain text, never markup)."""

from __future__ import annotations

import pkgutil

import pytest
import typer

from fgloc.cli import COMMANDS as LAZY
from fgloc.cli import app, main, registered


def _commands() -> list[list[str]]:
    root = typer.main.get_command(app)
    out: list[list[str]] = []

    def walk(cmd, path: list[str], ctx) -> None:  # typer vendors click: match groups by shape
        out.append(path)
        if hasattr(cmd, "list_commands"):
            for name in cmd.list_commands(ctx):
                walk(cmd.get_command(ctx, name), [*path, name], ctx)

    walk(root, [], typer.main.get_command(app).make_context("fgloc", [], resilient_parsing=True))
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


def test_the_lazy_root_lists_what_the_command_modules_register():
    """The root builds a command only when it is run (fgloc.cli.COMMANDS names each one's modules): the same
    commands, in the same order and with the same help, as every command module registered and built at once."""
    import fgloc.commands as pkg

    modules = sorted(m.name for m in pkgutil.iter_modules(pkg.__path__))
    assert sorted({m for ms in LAZY.values() for m in ms}) == modules
    eager = typer.main.get_group(registered(modules))
    assert list(eager.commands) == list(LAZY)
    for name, mods in LAZY.items():  # each command comes from the modules named for it
        assert name in typer.main.get_group(registered(list(mods))).commands
    root = typer.main.get_command(app)
    ctx = root.make_context("fgloc", [], resilient_parsing=True)
    lazy = ctx.make_formatter()
    root.format_commands(ctx, lazy)
    eager.commands = {"version": root.get_command(ctx, "version"), **eager.commands}
    built = ctx.make_formatter()
    eager.format_commands(ctx, built)
    assert lazy.getvalue() == built.getvalue() and lazy.getvalue().count("\n") == len(LAZY) + 2


def test_a_mistyped_command_gets_a_suggestion(capsys):
    assert main(["rn"]) == 2
    assert "Did you mean 'run'?" in capsys.readouterr().err


def test_exit_code_of_a_command_reaches_the_shell():
    # typer.Exit(code) inside a command must not be turned into 0
    assert main(["run", "does-not-exist.mcap"]) == 2


def test_simulate_scenario_by_shipped_name(tmp_path, capsys):
    assert main(["simulate", "scenario", "no_such_scenario", "-o", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "wheel_slip" in err
    assert main(["simulate", "list"]) == 0
    assert "kidnap" in capsys.readouterr().out.split()
