"""``fgloc ARGS`` run in this process, as the tests call the command line."""

from __future__ import annotations

import contextlib
import io


def run_cli(*args: object) -> tuple[int, str, str]:
    """``fgloc ARGS`` in this process: (exit status, stdout, stderr)."""
    from fgloc.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main([str(a) for a in args])
    return rc, out.getvalue(), err.getvalue()


def last_error_line(err: str) -> str:
    """The ``fgloc: error: ...`` line of stderr without its prefix, checked to be the last line (warnings may
    come before it) and no traceback."""
    lines = [ln for ln in err.strip().splitlines() if ln]
    assert lines and lines[-1].startswith("fgloc: error: "), err
    assert "Traceback" not in err
    return lines[-1].removeprefix("fgloc: error: ")
