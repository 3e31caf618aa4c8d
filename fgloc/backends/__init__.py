"""Back-ends: the paper's EKF, the fixed-lag iSAM2 smoother and the batch smoother.

``make_backend(name, config)`` builds one from the ``ekf:`` / ``smoother:`` / ``batch:``
sections of ``config/fgloc.yaml`` (the whole mapping or just the section).
"""

from __future__ import annotations

from dataclasses import fields
from typing import Any

import numpy as np

from fgloc.backends.base import Backend
from fgloc.backends.ekf import EKFConfig
from fgloc.backends.ekf_backend import EKFBackend
from fgloc.backends.smoother import BatchSmoother, SlidingWindowSmoother, SmootherConfig
from fgloc.errors import ConfigError

BACKENDS = ("ekf", "smoother", "batch")

__all__ = ["Backend", "EKFBackend", "SlidingWindowSmoother", "BatchSmoother", "make_backend", "BACKENDS"]


def _deg(d: dict[str, Any], key: str) -> None:
    """Turn ``<name>_deg`` keys (human-friendly YAML) into radians under ``<name>``."""
    if key + "_deg" in d:
        d[key] = float(np.deg2rad(d.pop(key + "_deg")))


def _dataclass_kwargs(cls: type, section: dict[str, Any], where: str) -> dict[str, Any]:
    names = {f.name for f in fields(cls)}
    unknown = set(section) - names
    if unknown:
        raise ConfigError(f"config [{where}]: unknown keys {sorted(unknown)}")
    out = dict(section)
    for k, v in list(out.items()):
        if isinstance(v, list):
            out[k] = tuple(v)
    return out


def make_backend(name: str, config: dict | None = None) -> Backend:
    """A back-end by name (``ekf``, ``smoother``, ``batch``) from its config section."""
    cfg = dict(config or {})
    name = str(name).strip().lower()
    if name not in BACKENDS:
        raise ConfigError(f"unknown back-end '{name}' (choose ekf, smoother or batch)")
    if any(k in BACKENDS for k in cfg):
        cfg = dict(cfg.get(name) or ({} if name != "batch" else {}))
        if name == "batch":
            base = dict((config or {}).get("smoother") or {})
            base.update(cfg)
            cfg = base
    if name == "ekf":
        sec = dict(cfg)
        backend_keys = {}
        for k in ("encoder_sigmas", "compass_sigma", "compass_rate_sigma", "use_compass_yaw",
                  "calibration_fixes", "max_rejections"):
            if k in sec or k + "_deg" in sec:
                _deg(sec, k)
                if k in sec:
                    backend_keys[k] = sec.pop(k)
        _deg(sec, "map_min_sigma_theta")
        ekf_cfg = EKFConfig(**_dataclass_kwargs(EKFConfig, sec, "ekf"))
        if "encoder_sigmas" in backend_keys:
            backend_keys["encoder_sigmas"] = tuple(backend_keys["encoder_sigmas"])
        return EKFBackend(ekf_cfg, **backend_keys)
    sec = dict(cfg)
    max_iter = int(sec.pop("max_iterations", 50))
    for k in ("compass_sigma", "offset_rw_sigma", "offset_prior_sigma", "calibrated_offset_sigma",
              "fix_min_sigma_theta", "fix_gate_theta"):
        _deg(sec, k)
    sm_cfg = SmootherConfig(**_dataclass_kwargs(SmootherConfig, sec, name))
    if name == "batch":
        return BatchSmoother(sm_cfg, max_iterations=max_iter)
    return SlidingWindowSmoother(sm_cfg)
