"""Angles on the command line with their unit: ``--initial-pose 2.5 3 90deg`` (or ``1.571rad``, or a
bare number in the option's own unit, which every help text names)."""

from __future__ import annotations

import math

from fgloc.errors import ConfigError

UNITS = {"deg": math.pi / 180.0, "°": math.pi / 180.0, "rad": 1.0}


def angle_rad(text: str | float, option: str, default_unit: str = "rad") -> float:
    """``text`` in radians: ``90deg``, ``90°``, ``1.5708rad`` or a bare number in ``default_unit``."""
    s = str(text).strip().lower()
    unit = next((u for u in UNITS if s.endswith(u)), default_unit)
    num = s[: -len(unit)] if s.endswith(unit) else s
    try:
        v = float(num)
    except ValueError:
        raise ConfigError(f"{option}: {text!r} is not an angle (a number, optionally with deg or rad: 90deg, "
                          "1.5708rad)") from None
    if not math.isfinite(v):
        raise ConfigError(f"{option}: the angle must be finite, got {text!r}")
    return v * UNITS[unit]


def pose_arg(values: tuple[str, str, str] | None, option: str = "--initial-pose") -> tuple[float, float, float] | None:
    """``X Y YAW`` of a command line (metres; the yaw in radians or with a unit) as floats, None if absent."""
    if values is None:
        return None
    x, y, yaw = values
    try:
        xy = (float(x), float(y))
    except ValueError:
        raise ConfigError(f"{option}: X and Y are metres (numbers), got {x!r} {y!r}") from None
    if not all(math.isfinite(v) for v in xy):
        raise ConfigError(f"{option}: X and Y must be finite, got {x!r} {y!r}")
    return xy[0], xy[1], angle_rad(yaw, option)
