"""Back-ends: the paper's EKF, the fixed-lag iSAM2 smoother and the batch smoother.

``make_backend(name, config)`` builds one from its typed config section(s): the
``ekf:`` / ``smoother:`` / ``batch:`` sections of :class:`fgloc.config.FglocConfig`
(``EKFConfig``, ``SmootherConfig``, ``BatchConfig``, each defined beside the code that
uses it).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from fgloc.backends.base import Backend
from fgloc.backends.ekf import EKFConfig
from fgloc.backends.ekf_backend import EKFBackend
from fgloc.backends.smoother import BatchConfig, BatchSmoother, SlidingWindowSmoother, SmootherConfig
from fgloc.errors import ConfigError

BACKENDS = ("ekf", "smoother", "batch")

__all__ = ["Backend", "EKFBackend", "SlidingWindowSmoother", "BatchSmoother", "make_backend", "BACKENDS",
           "EKFConfig", "SmootherConfig", "BatchConfig"]


def make_backend(name: str, config: Any = None) -> Backend:
    """A back-end by name (``ekf``, ``smoother``, ``batch``).

    ``config``: the whole :class:`fgloc.config.FglocConfig` (its ``ekf`` / ``smoother`` /
    ``batch`` sections are used), or ``None`` for the defaults.  A plain mapping is parsed
    (and checked) as a config file would be.
    """
    key = str(name).strip().lower()
    if key not in BACKENDS:
        from fgloc.config.schema import suggest

        raise ConfigError(f"unknown back-end '{name}' (choose ekf, smoother or batch){suggest(key, BACKENDS)}")
    if isinstance(config, Mapping):
        from fgloc.config import parse_config

        config = parse_config(config)
    ekf = getattr(config, "ekf", None) or EKFConfig()
    sm = getattr(config, "smoother", None) or SmootherConfig()
    batch = getattr(config, "batch", None) or BatchConfig()
    if key == "ekf":
        return EKFBackend(ekf)
    if key == "batch":
        return BatchSmoother(sm, batch)
    return SlidingWindowSmoother(sm)
