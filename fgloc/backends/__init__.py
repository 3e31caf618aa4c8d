"""Back-ends: the paper's EKF, the fixed-lag iSAM2 smoother and the batch smoother.

:data:`REGISTRY` names every back-end.  ``make_backend(name, config)`` builds one from its typed
config sections (:meth:`~fgloc.backends.contract.Backend.from_config`: the ``ekf:`` /
``smoother:`` / ``batch:`` sections of :class:`fgloc.config.FglocConfig`, ``EKFConfig``,
``SmootherConfig``, ``BatchConfig``, each defined beside the code that uses it).
``check_backend(name, *capabilities)`` checks a name a user gave, and that the back-end has what
the caller needs (``fgloc live``: ``Capability.LIVE``); callers select by capability, never by
comparing names.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from fgloc.backends.base import Backend, Capability
from fgloc.backends.ekf import EKFConfig
from fgloc.backends.ekf_backend import EKFBackend
from fgloc.backends.smoother import BatchConfig, BatchSmoother, SlidingWindowSmoother, SmootherConfig
from fgloc.errors import ConfigError

#: every back-end, by the name the command line and the configs use (a new back-end is added here)
REGISTRY: dict[str, type[Backend]] = {"ekf": EKFBackend, "smoother": SlidingWindowSmoother, "batch": BatchSmoother}
BACKENDS = tuple(REGISTRY)

__all__ = ["Backend", "Capability", "EKFBackend", "SlidingWindowSmoother", "BatchSmoother", "make_backend",
           "check_backend", "backend_names", "BACKENDS", "REGISTRY", "EKFConfig", "SmootherConfig", "BatchConfig"]


def backend_names(*needs: Capability) -> tuple[str, ...]:
    """The back-ends that have every capability in ``needs`` (all of them without)."""
    return tuple(n for n, c in REGISTRY.items() if all(x in c.capabilities for x in needs))


def _choices(names: tuple[str, ...]) -> str:
    return names[0] if len(names) == 1 else f"{', '.join(names[:-1])} or {names[-1]}"


def check_backend(name: str, *needs: Capability, option: str = "--backend") -> str:
    """The back-end ``name`` (its registry key), when there is one with every capability in
    ``needs`` (e.g. ``Capability.LIVE`` for ``fgloc live``); else a :class:`ConfigError` naming the
    choices (``option``: how the user gave it)."""
    key = str(name).strip().lower()
    if key not in REGISTRY:
        from fgloc.config.schema import suggest

        raise ConfigError(f"unknown back-end '{name}' (choose {_choices(BACKENDS)}){suggest(key, BACKENDS)}")
    ok = backend_names(*needs)
    if key not in ok:
        raise ConfigError(f"{option} {name}: expected {_choices(ok)}")
    return key


def make_backend(name: str, config: Any = None) -> Backend:
    """A back-end by name (``ekf``, ``smoother``, ``batch``).

    ``config``: the whole :class:`fgloc.config.FglocConfig` (its ``ekf`` / ``smoother`` /
    ``batch`` sections are used), or ``None`` for the defaults.  A plain mapping is parsed
    (and checked) as a config file would be.
    """
    key = check_backend(name)
    if isinstance(config, Mapping):
        from fgloc.config import parse_config

        config = parse_config(config)
    return REGISTRY[key].from_config(config)
