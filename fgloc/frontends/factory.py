"""``make_frontend``: build a scan-to-map front-end by name from its typed config section.

The ``frontends:`` section of :class:`fgloc.config.FglocConfig` is a
:class:`FrontendsConfig` with one sub-section per front-end (``native``, ``kiss``,
``amcl``), each a dataclass defined beside its front-end (:class:`NativeConfig`,
:class:`KissConfig`, :class:`AMCLConfig`) holding the only copy of its defaults.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from fgloc.config.schema import parse, section, suggest
from fgloc.errors import ConfigError
from fgloc.maps import OccupancyMap
from fgloc.types import StaticTransform

from .amcl import AMCLConfig
from .base import ScanMatcher
from .kiss import KissConfig
from .native import NativeConfig

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


@dataclass(frozen=True)
class FrontendsConfig:
    """``frontends:`` one sub-section per scan-to-map front-end."""

    native: NativeConfig = section(NativeConfig, "native matcher: robust LM on the map's surface distance field "
                                   "after a correlative search")
    kiss: KissConfig = section(KissConfig, "KISS-ICP registration against the map as a static voxel map")
    amcl: AMCLConfig = section(AMCLConfig, "AMCL particle filter (nav2_amcl names)")


def canonical_name(name: str) -> str:
    """``native``, ``kiss`` or ``amcl`` for an accepted name; :class:`ConfigError` otherwise."""
    key = str(name).strip().lower()
    canonical = ALIASES.get(key)
    if canonical is None:
        raise ConfigError(f"unknown front-end '{name}' (choose native, kiss or amcl){suggest(key, ALIASES)}")
    return canonical


def _section(canonical: str, config: Any) -> Any:
    """The typed section of front-end ``canonical`` from whatever the caller holds."""
    if config is None:
        return None
    if hasattr(config, "frontends") and not isinstance(config, Mapping):  # the whole FglocConfig
        config = config.frontends
    if isinstance(config, FrontendsConfig):
        return getattr(config, canonical)
    if isinstance(config, (NativeConfig, KissConfig, AMCLConfig)):
        return config
    if isinstance(config, Mapping):
        if any(k in FRONTENDS for k in config):  # {"native": {...}, "kiss": {...}}
            return getattr(parse(FrontendsConfig, config, where="frontends"), canonical)
        cls = {"native": NativeConfig, "kiss": KissConfig, "amcl": AMCLConfig}[canonical]
        return parse(cls, config, where=f"frontends.{canonical}")
    raise ConfigError(f"front-end config must be a config section, got {type(config).__name__}")


def make_frontend(name: str, occ_map: OccupancyMap, laser_mount: StaticTransform, config: Any = None) -> ScanMatcher:
    """A front-end by name: ``native``, ``kiss`` (aliases ``kiss-icp``, ``kiss_icp``) or ``amcl``.

    ``config``: :class:`fgloc.config.FglocConfig`, :class:`FrontendsConfig`, the front-end's
    own section, or ``None`` (the defaults).  A plain mapping is checked like a YAML file.
    Raises :class:`ConfigError` for an unknown name or a bad config value.
    """
    canonical = canonical_name(name)
    sec = _section(canonical, config)
    if canonical == "native":
        from .native import NativeMatcher

        return NativeMatcher(occ_map, laser_mount, sec)
    if canonical == "kiss":
        from .kiss import KissMatcher

        return KissMatcher(occ_map, laser_mount, sec)
    from .amcl import AMCL

    return AMCL(occ_map, laser_mount, sec)  # type: ignore[return-value]

