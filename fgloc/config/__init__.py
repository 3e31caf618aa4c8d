"""fgloc's one typed configuration.

* :mod:`fgloc.config.schema` - the machinery every section uses (``setting``, ``section``,
  ``parse``, ``to_yaml``); import it from the modules that define sections.
* :mod:`fgloc.config.loader` - :class:`FglocConfig` (all sections composed),
  :func:`load_config`, :func:`parse_config`, :func:`config_yaml`.
* package data: ``scenarios/*.yaml`` (simulator scenarios), ``robots/*.yaml`` (ready-to-use
  configs of real robots, the repository's top-level ``config/``: ``--config husky`` finds
  ``robots/husky.yaml``, :func:`robot_config_path`), read with :func:`resource`
  (``importlib.resources``, so they are found in an installed wheel as in a checkout).

The loader is imported lazily here: the section modules import :mod:`fgloc.config.schema`,
and the loader imports the section modules.
"""

from __future__ import annotations

from importlib import resources
from importlib.abc import Traversable
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from fgloc.config.loader import FglocConfig, config_yaml, load_config, parse_config

__all__ = ["FglocConfig", "config_yaml", "load_config", "parse_config", "resource", "robot_config_path",
           "robot_names", "scenario_path", "scenario_names"]


def __getattr__(name: str) -> Any:
    if name in ("FglocConfig", "config_yaml", "load_config", "parse_config", "SECTIONS"):
        from fgloc.config import loader

        return getattr(loader, name)
    raise AttributeError(name)


def resource(*parts: str) -> Traversable:
    """A file shipped in the package (``resource("scenarios", "kidnap.yaml")``)."""
    t = resources.files("fgloc.config")
    for p in parts:
        t = t / p
    return t


def scenario_names() -> list[str]:
    """The shipped simulator scenarios (``fgloc simulate scenario NAME``)."""
    d = resource("scenarios")
    return sorted(p.name[:-5] for p in d.iterdir() if p.name.endswith(".yaml"))


def scenario_path(name: str) -> Traversable:
    """The shipped scenario ``name`` (without ``.yaml``)."""
    return resource("scenarios", f"{name}.yaml")


def robot_names() -> list[str]:
    """The shipped robot configs (``--config NAME``; the repository's ``config/``)."""
    d = resource("robots")
    return sorted(p.name[:-5] for p in d.iterdir() if p.name.endswith(".yaml"))


def robot_config_path(path: str | Path) -> Any:
    """``path`` itself, unless it is the bare name of a shipped robot config (no folder, no suffix,
    and no such file here): then that config (``husky`` -> ``robots/husky.yaml``)."""
    p = Path(path)
    if p.suffix or p.parent != Path(".") or p.exists() or str(p) not in robot_names():
        return path
    return resource("robots", f"{p}.yaml")

