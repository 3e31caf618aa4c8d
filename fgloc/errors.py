"""Exceptions the CLI turns into one-line messages (no traceback).

Every message names the file (when there is one) and the problem.
"""

from __future__ import annotations


class FglocError(Exception):
    """Base class: a user-facing error with a one-line message."""


class MapError(FglocError):
    """A map YAML or image that does not parse or is inconsistent."""


class LogError(FglocError):
    """A log that cannot be read: missing file, bad format, missing topic, empty."""


class ConfigError(FglocError):
    """A configuration file or value that is invalid."""
