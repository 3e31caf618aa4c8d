"""The command line's plain coercion (fgloc.cli.PlainCoercion) takes a value only as typer's own
pydantic coercion gives it, and leaves every other value (and every error message) to typer."""

from __future__ import annotations

import math

import pytest
import typer
from typer._coercion import build_runtime_param

from fgloc.cli import PlainCoercion, app, main

NUMBERS = ["0", "-0", "1", "+1", "-1", "007", "1.5", "-2.25", ".5", "5.", "1e3", "1E-3", "-1e-400", "1e999",
           "0.1", "3.141592653589793238", "1_000", " 1", "1 ", "inf", "nan", "0x10", "1e", "", "abc", "90deg",
           "-0.0", "123456789012345678901234567890", "2.5e+02"]
TEXTS = ["", "a", "/odom", "x y", "-", "ü", "a\0b", ".", "..", "/", "does/not/exist"]


def _params() -> list[tuple[str, object, object]]:
    root = typer.main.get_command(app)
    ctx = root.make_context("fgloc", [], resilient_parsing=True)
    out = []

    def walk(cmd, path: str) -> None:
        for p in cmd.params:
            if isinstance(vars(p).get("_runtime_param"), PlainCoercion):
                out.append((f"{path} {p.name}", p, ctx))
        if hasattr(cmd, "list_commands"):  # typer vendors click: match groups by shape
            for name in cmd.list_commands(ctx):
                walk(cmd.get_command(ctx, name), f"{path} {name}".strip())

    walk(root, "")
    return out


PARAMS = _params()


def _same(a: object, b: object) -> bool:
    if isinstance(a, tuple) and isinstance(b, tuple):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, float) and isinstance(b, float):
        return (math.isnan(a) and math.isnan(b)) or (a == b and math.copysign(1, a) == math.copysign(1, b))
    return type(a) is type(b) and a == b


def test_every_plain_value_is_typers(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "file.txt").write_text("x")
    (tmp_path / "folder").mkdir()
    assert len(PARAMS) > 50 and any(name == "run initial_pose" for name, _, _ in PARAMS)
    taken = declined = 0
    for name, p, ctx in PARAMS:
        plain = p._runtime_param
        own = build_runtime_param(plain.descriptor)
        n = p.nargs if p.nargs > 1 else 1
        values = [*NUMBERS, *TEXTS, "file.txt", "folder", str(tmp_path / "file.txt")]
        cases = [v if n == 1 else tuple([v] * n) for v in values]
        if n > 1:
            cases += [tuple(["a", "b", *NUMBERS[:n - 2]]), tuple(NUMBERS[:n]), tuple(["1"] * (n - 1))]
        for v in cases:
            try:
                got = plain.plain(v, p, ctx)
            except Exception:  # noqa: BLE001  declined: typer's coercion answers
                declined += 1
                continue
            want = own.coerce(v, param=p, ctx=ctx)  # what typer gives for a value taken here: never an error
            assert _same(got, want), (name, v, got, want)
            taken += 1
    assert taken > 500 and declined > 500


def test_errors_are_typers(capsys):
    """A value the plain coercion declines gets typer's message (here, the option hint fgloc.cli adds)."""
    assert main(["run", "log.mcap", "-o", "out", "--initial-pose", "1", "x", "0"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--initial-pose needs three values" in err
    assert main(["run", "log.mcap", "-o", "out", "--realtime", "fast"]) == 2
    err = capsys.readouterr().err
    assert "Invalid value for '--realtime': Input should be a valid number" in err  # pydantic's words


@pytest.mark.parametrize("argv", [["run", "--help"], ["bench", "speed", "--help"]])
def test_help_needs_no_coercion(argv, capsys):
    assert main(argv) == 0
    assert "Usage:" in capsys.readouterr().out
