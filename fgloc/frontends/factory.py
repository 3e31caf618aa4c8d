"""``make_frontend``: build a scan-to-map front-end by name from a config dict.

``config`` may be either the section for that front-end (``{"max_iterations": 20,
...}``) or the whole ``config/frontends.yaml`` mapping (``{"native": {...}, "kiss":
{...}, "amcl": {...}}``); in the latter case the section named like the front-end
is used.  Missing keys take the documented defaults (the constructor defaults, the
same values ``config/frontends.yaml`` lists).  Unknown keys raise ``ConfigError``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from fgloc.errors import ConfigError
from fgloc.maps import OccupancyMap
from fgloc.types import StaticTransform

from .base import ScanMatcher

#: accepted names -> canonical section name
ALIASES: dict[str, str] = {
    "native": "native",
    "kiss": "kiss",
    "kiss-icp": "kiss",
    "kiss_icp": "kiss",
    "kissicp": "kiss",
    "amcl": "amcl",
}
FRONTENDS = ("native", "kiss", "amcl")

DEFAULT_CONFIG_PATH = Path(__file__).resolve().parents[2] / "config" / "frontends.yaml"


def load_frontends_config(path: str | Path | None = None) -> dict[str, Any]:
    """Read a front-ends YAML (default ``config/frontends.yaml``); ``{}`` if the default is absent."""
    p = Path(path) if path is not None else DEFAULT_CONFIG_PATH
    if not p.exists():
        if path is None:
            return {}
        raise ConfigError(f"{p}: front-ends config not found")
    try:
        data = yaml.safe_load(p.read_text())
    except (OSError, yaml.YAMLError) as e:
        raise ConfigError(f"{p}: front-ends config does not parse ({e.__class__.__name__})") from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ConfigError(f"{p}: front-ends config must be a mapping of front-end name -> settings")
    return data


def _section(canonical: str, config: dict | None) -> dict[str, Any]:
    if not config:
        return {}
    if not isinstance(config, dict):
        raise ConfigError(f"front-end config must be a mapping, got {type(config).__name__}")
    if any(k in FRONTENDS for k in config):
        sec = config.get(canonical) or {}
        if not isinstance(sec, dict):
            raise ConfigError(f"frontends config [{canonical}] must be a mapping")
        return dict(sec)
    return dict(config)


def make_frontend(
    name: str, occ_map: OccupancyMap, laser_mount: StaticTransform, config: dict | None = None
) -> ScanMatcher:
    """A front-end by name: ``native``, ``kiss`` (aliases ``kiss-icp``, ``kiss_icp``) or ``amcl``.

    Raises :class:`ConfigError` for an unknown name or a bad config value.
    """
    canonical = ALIASES.get(str(name).strip().lower())
    if canonical is None:
        raise ConfigError(f"unknown front-end '{name}' (choose native, kiss or amcl)")
    section = _section(canonical, config)
    if canonical == "native":
        from .native import NativeMatcher

        return NativeMatcher.from_config(occ_map, laser_mount, section)
    if canonical == "kiss":
        from .kiss import KissMatcher

        return KissMatcher.from_config(occ_map, laser_mount, section)
    try:
        from .amcl import AMCL
    except ImportError as e:
        raise ConfigError(f"front-end 'amcl' is not available ({e})") from None
    return AMCL.from_config(occ_map, laser_mount, section)  # type: ignore[no-any-return]
