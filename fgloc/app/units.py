"""Angles on the command line with their unit: ``--initial-pose 2.5 3 90deg`` (or ``1.571rad``, or a
bare number in the option's own unit, which every help text names).

:func:`pose_value` is the option's parser (typer applies it to each of the three values; a value
that is not a number is click's usage error naming the option); :func:`pose_arg` checks the
triple."""

from __future__ import annotations

import math

from fgloc.errors import ConfigError

UNITS = {"deg": math.pi / 180.0, "°": math.pi / 180.0, "rad": 1.0}


class _Angle(float):
    """A value given with an angle unit (already in radians)."""


def pose_value(text: str | float) -> float:
    """One value of ``X Y YAW``: a number, or an angle with its unit (``90deg``, ``1.5708rad``: radians)."""
    if isinstance(text, float):
        return text
    s = str(text).strip().lower()
    unit = next((u for u in UNITS if s.endswith(u)), None)
    if unit is None:
        return float(s)  # ValueError: click's one-line usage error for the option
    return _Angle(float(s[: -len(unit)]) * UNITS[unit])


def pose_arg(values: tuple[float, float, float] | None, option: str = "--initial-pose"
             ) -> tuple[float, float, float] | None:
    """``X Y YAW`` as parsed by :func:`pose_value` (metres; the yaw in radians), None if absent."""
    if values is None:
        return None
    x, y, yaw = values
    if isinstance(x, _Angle) or isinstance(y, _Angle):
        raise ConfigError(f"{option}: X and Y are metres; only YAW takes a unit (e.g. {option} 2.5 3.0 90deg)")
    if not all(math.isfinite(v) for v in (x, y, yaw)):
        raise ConfigError(f"{option}: X Y YAW must be finite numbers")
    return float(x), float(y), float(yaw)
