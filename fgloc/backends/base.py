"""Helpers both back-ends use; the contract itself (:class:`Backend`, :class:`Capability`) is
:mod:`fgloc.backends.contract`, re-exported here."""

from __future__ import annotations

import math

import numpy as np

from fgloc.backends.contract import Backend, Capability, Estimates, FloatArray, SourceNoise

__all__ = ["Backend", "Capability", "Estimates", "FloatArray", "SourceNoise", "twist_covariance",
           "twist_covariance_values"]


_DEFAULT_COV: dict[tuple[float, float, float], list[float]] = {}


def twist_covariance(cov: FloatArray | None, default_sigmas: tuple[float, float, float]) -> FloatArray:
    """The message's 3x3 twist covariance, or a diagonal default when absent / all zero / bad (a new array)."""
    return np.array(twist_covariance_values(cov, default_sigmas)).reshape(3, 3)


def twist_covariance_values(cov: FloatArray | None, default_sigmas: tuple[float, float, float]) -> list[float]:
    """:func:`twist_covariance`'s 9 entries (row by row) as floats, without the array (every odometry
    message of the smoother: one ``tolist`` instead of four numpy calls).  The default's list is
    shared between calls: read it, do not change it."""
    if cov is not None:
        if isinstance(cov, np.ndarray) and cov.dtype == np.float64 and cov.size == 9:
            v = cov.ravel().tolist()
        else:
            v = np.asarray(cov, dtype=float).reshape(3, 3).ravel().tolist()
        if v[0] > 0 and v[4] > 0 and v[8] > 0 and math.isfinite(sum(v)):
            return v
    d = _DEFAULT_COV.get(default_sigmas)
    if d is None:
        d = _DEFAULT_COV[default_sigmas] = np.diag(np.square(default_sigmas)).ravel().tolist()
    return d
