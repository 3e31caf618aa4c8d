"""What both back-ends keep per input source, written once (:class:`InputBook`).

Every input a back-end takes goes through the same preamble before its own maths: the source's
health record (accepted / gated / skipped, and why), the finite checks, the variance fallback
when a message claims none (:func:`twist_covariance` for an odometry's), the reading handed to
the noise arbiter (what the source shows against the others,
:class:`~fgloc.backends.health.Arbiter`), each gyro's bias estimated beside the estimator from
the absolute headings and standstill
(:class:`~fgloc.backends.health.GyroBias`), and the scans' latency
(:class:`~fgloc.backends.health.latency.ScanLatency`).  Core maths only.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from fgloc.backends.contract import FloatArray, SourceNoise
from fgloc.backends.health import Arbiter, GyroBias, SourceHealth
from fgloc.backends.health.latency import ScanLatency


def _no_reading(name: str, kind: str, rel_prior: float, t: float, value: float, var: float) -> None:
    """:attr:`InputBook.reading` where noise is not adapted."""


def _claimed_noise(name: str) -> tuple[float, float]:
    """:attr:`InputBook.noise` where noise is not adapted: as claimed."""
    return 1.0, 0.0


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


class InputBook:
    """Per-source health, noise arbitration, gyro biases and the scans' latency of one back-end.

    ``adapt_noise``: readings go to ``arbiter`` and :meth:`noise` reports what it found (else
    the claimed noise, ``(1, 0)``); ``latency`` / ``latency_s``: the scans' latency estimated,
    or known (``latency_s``, then nothing is estimated)."""

    def __init__(self, arbiter: Arbiter, adapt_noise: bool, latency: bool, latency_s: float | None) -> None:
        self.arb = arbiter
        self.adapt_noise = bool(adapt_noise)
        self.health: dict[str, SourceHealth] = {}
        self.gyro_bias: dict[str, GyroBias] = {}   # per gyro stream estimated beside the estimator
        self.latency = ScanLatency(latency, latency_s)
        #: ``reading(name, kind, rel_prior, t, value, var)``: one reading of stream ``name`` for the arbiter
        #: (registered at its first), when noise is adapted; else nothing (one call per reading)
        self.reading: Callable[[str, str, float, float, float, float], None] = (
            arbiter.add_reading if self.adapt_noise else _no_reading)
        #: ``noise(name)``: ``(k, c)``, stream ``name``'s claimed variance times ``k^2`` plus ``(c * increment)^2``
        #: (the arbiter's :meth:`~fgloc.backends.health.Arbiter.noise` when noise is adapted, else ``(1, 0)``)
        self.noise: Callable[[str], tuple[float, float]] = arbiter.noise if self.adapt_noise else _claimed_noise

    # ------------------------------------------------------------------ health, checks
    def source(self, name: str, kind: str) -> SourceHealth:
        """Stream ``name``'s health record (made at its first input)."""
        h = self.health.get(name)
        if h is None:
            h = self.health[name] = SourceHealth(name, kind)
        return h

    @staticmethod
    def finite(h: SourceHealth, *values: float) -> bool:
        """Whether every value is finite; if not, the input is skipped on ``h`` as "not finite"."""
        if all(math.isfinite(v) for v in values):
            return True
        h.skip("not finite")
        return False

    @staticmethod
    def variance(var: float, default_sigma: float) -> float:
        """The message's variance, or ``default_sigma^2`` when it claims none (not finite, or <= 0)."""
        return var if math.isfinite(var) and var > 0 else default_sigma**2

    # ------------------------------------------------------------------ noise arbitration
    def source_noise(self, name: str) -> SourceNoise | None:
        """What :meth:`fgloc.backends.contract.Backend.source_noise` reports."""
        if name not in self.arb.streams:
            return None
        k, c = self.arb.noise(name)
        return SourceNoise(k, c, self.arb.shown_sigma(name), self.arb.claimed_sigma(name))

    # ------------------------------------------------------------------ gyro biases
    def gyro(self, name: str, prior_sigma: float, rw: float) -> GyroBias:
        """Gyro stream ``name``'s bias estimate (made at its first reading)."""
        gb = self.gyro_bias.get(name)
        if gb is None:
            gb = self.gyro_bias[name] = GyroBias(prior_sigma, rw)
        return gb

    def heading(self, name: str, t: float, yaw: float, var: float) -> None:
        """An absolute heading of source ``name`` for every gyro's bias (only its increments count)."""
        for gb in self.gyro_bias.values():
            gb.add_heading(name, t, yaw, var)

    def standstill(self, t: float, still: bool) -> None:
        """Whether the wheels stand still at ``t`` (then each gyro reading measures its bias)."""
        for gb in self.gyro_bias.values():
            gb.set_still(t, still)
