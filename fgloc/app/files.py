"""Output-file safety shared by the commands: never overwrite an input or a file that is not ours."""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

from fgloc.errors import FglocError


class OutputError(FglocError):
    """An output that would destroy an input or someone else's file."""


def same_file(a: str | Path, b: str | Path) -> bool:
    """Whether two paths name the same existing file (symlinks, hard links, ``..`` resolved)."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        return Path(a).resolve() == Path(b).resolve()


def check_not_input(output: str | Path, inputs: Iterable[str | Path | None]) -> None:
    """Refuse (one line) to write ``output`` when it is one of the ``inputs``."""
    for src in inputs:
        if src is not None and Path(output).exists() and same_file(output, src):
            raise OutputError(f"{output}: is an input of this command; refusing to overwrite it "
                              f"(choose another output)")


def write_text_output(path: str | Path, text: str, force: bool = False, what: str = "file") -> Path:
    """Write ``text`` to a new file; an existing one only with ``force``."""
    p = Path(path)
    if p.is_dir():
        raise OutputError(f"{p}: is a folder, expected a {what} file name")
    if p.exists() and not force:
        raise OutputError(f"{p}: exists; pass --force to overwrite it")
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(text)
    return p
