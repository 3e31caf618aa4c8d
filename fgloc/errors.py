"""Exceptions the CLI turns into one-line messages (no traceback).

Every message names the file (when there is one) and the problem.
"""

from __future__ import annotations

from pathlib import Path


class FglocError(Exception):
    """Base class: a user-facing error with a one-line message."""


class MapError(FglocError):
    """A map YAML or image that does not parse or is inconsistent."""


class LogError(FglocError):
    """A log that cannot be read: missing file, bad format, missing topic, empty."""


class ConfigError(FglocError):
    """A configuration file or value that is invalid."""


def read_user_text(path: str | Path, what: str, error: type[FglocError] = LogError) -> str:
    """The text of a file the user named, or ``error`` with one line ``PATH: WHAT not found``,
    ``PATH: is a directory, not a WHAT`` or ``PATH: cannot read WHAT (why)``."""
    p = Path(path)
    try:
        return p.read_text()
    except (OSError, UnicodeDecodeError) as e:
        raise _file_error(p, what, error, e) from None


def read_user_head(path: str | Path, n: int, what: str = "log file", error: type[FglocError] = LogError) -> bytes:
    """The first ``n`` bytes of a file the user named (errors as :func:`read_user_text`)."""
    p = Path(path)
    try:
        with p.open("rb") as f:
            return f.read(n)
    except OSError as e:
        raise _file_error(p, what, error, e) from None


def _file_error(p: Path, what: str, error: type[FglocError], e: Exception) -> FglocError:
    if isinstance(e, FileNotFoundError):
        return error(f"{p}: {what} not found")
    if isinstance(e, IsADirectoryError):
        return error(f"{p}: is a directory, not a {what}")
    why = e.strerror if isinstance(e, OSError) and e.strerror else e
    return error(f"{p}: cannot read {what} ({why})")
