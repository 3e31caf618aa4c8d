"""What both back-ends keep per input source, written once (:class:`InputBook`).

Every input a back-end takes goes through the same preamble before its own maths: the source's
health record (accepted / gated / skipped, and why), the finite checks, the variance fallback
when a message claims none, the reading handed to the noise arbiter (what the source shows
against the others, :class:`~fgloc.backends.health.Arbiter`), each gyro's bias estimated beside
the estimator from the absolute headings and standstill
(:class:`~fgloc.backends.health.GyroBias`), and the pairs of fixes the scans' latency is
estimated from (:class:`~fgloc.backends.health.LatencyEstimator`).  Core maths only.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from fgloc.backends.contract import FloatArray, SourceNoise, latency_fit_of
from fgloc.backends.health import Arbiter, GyroBias, LatencyEstimator, SourceHealth

#: a fix pair: (t_a, t_b, pose_a, pose_b, cov_a, cov_b)
FixPair = tuple[float, float, FloatArray, FloatArray, FloatArray, FloatArray]
#: s: consecutive fixes at most this far apart make a latency pair (turns starting / ending)
SHORT_PAIR_S = 0.3
#: s: once a second, a fix and one this far before it (a start from standstill: the lag is v * latency)
LONG_PAIR_S = (0.8, 1.2)


class InputBook:
    """Per-source health, noise arbitration, gyro biases and latency pairs of one back-end.

    ``adapt_noise``: readings go to ``arbiter`` and :meth:`noise` reports what it found (else
    the claimed noise, ``(1, 0)``); ``latency`` / ``latency_s``: the scans' latency estimated,
    or known (``latency_s``, then nothing is estimated)."""

    def __init__(self, arbiter: Arbiter, adapt_noise: bool, latency: bool, latency_s: float | None) -> None:
        self.arb = arbiter
        self.adapt_noise = bool(adapt_noise)
        self.health: dict[str, SourceHealth] = {}
        self.gyro_bias: dict[str, GyroBias] = {}   # per gyro stream estimated beside the estimator
        self.latency_on = bool(latency)
        self.latency_s = latency_s
        self.latency_est = LatencyEstimator()
        self.recent_fixes: deque[tuple[float, FloatArray, FloatArray]] = deque(maxlen=64)
        self.fix_pairs: list[FixPair] = []
        self._long_pair_t = -math.inf

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
    def reading(self, name: str, kind: str, rel_prior: float, t: float, value: float, var: float) -> None:
        """One reading of stream ``name`` for the arbiter (registered at its first), when noise is adapted."""
        if self.adapt_noise:
            self.arb.add_reading(name, kind, rel_prior, t, value, var)

    def noise(self, name: str) -> tuple[float, float]:
        """``(k, c)``: stream ``name``'s claimed variance times ``k^2`` plus ``(c * increment)^2``."""
        return self.arb.noise(name) if self.adapt_noise else (1.0, 0.0)

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

    # ------------------------------------------------------------------ latency
    @property
    def latency_estimated(self) -> bool:
        """Whether the scans' latency is estimated (on, and not configured)."""
        return self.latency_on and self.latency_s is None

    def latency(self) -> float:
        """The scans' latency (s) in use: configured, estimated once significant, or 0."""
        if self.latency_s is not None:
            return float(self.latency_s)
        return self.latency_est.value() if self.latency_on else 0.0

    def latency_fit(self) -> tuple[float, float] | None:
        return latency_fit_of(self.latency_est.estimate())

    def add_fix(self, t: float, pose: FloatArray, cov: FloatArray) -> None:
        """A fix used at scan stamp ``t``: latency pairs with the previous fix (within
        :data:`SHORT_PAIR_S`) and, once a second, with one :data:`LONG_PAIR_S` before it
        (:attr:`fix_pairs`, evaluated by the back-end once its references cover them)."""
        if not self.latency_estimated:
            return
        pose, cov = np.array(pose, dtype=float), np.array(cov, dtype=float)
        recent = self.recent_fixes
        if recent and 0.0 < t - recent[-1][0] <= SHORT_PAIR_S:
            f = recent[-1]
            self.fix_pairs.append((f[0], t, f[1], pose, f[2], cov))
        if t - self._long_pair_t >= 1.0:
            old = [f for f in recent if LONG_PAIR_S[0] <= t - f[0] <= LONG_PAIR_S[1]]
            if old:
                f = old[0]
                self.fix_pairs.append((f[0], t, f[1], pose, f[2], cov))
                self._long_pair_t = t
        recent.append((t, pose, cov))
