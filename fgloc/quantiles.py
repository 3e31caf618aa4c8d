"""Run-long latency percentiles in constant memory: a histogram of log-spaced bins.

A live node measures a latency per message for as long as it runs (days); keeping the samples grows
without bound, keeping the newest N forgets the rest of the run.  :class:`LogHistogram` counts each
sample in one of ``bins_per_decade`` bins per power of ten between ``lo`` and ``hi`` (values outside
are counted in the end bins; the exact minimum and maximum are kept), so a percentile is known to
within half a bin: ``10 ** (0.5 / bins_per_decade) - 1`` relative (0.6 % with 200 bins per decade),
for a fixed few kilobytes whatever the number of samples.
"""

from __future__ import annotations

import math

import numpy as np


class LogHistogram:
    """Counts of samples in log-spaced bins (see the module docstring).  ``add`` is O(1)."""

    def __init__(self, lo: float = 1e-3, hi: float = 1e6, bins_per_decade: int = 200) -> None:
        if not 0 < lo < hi:
            raise ValueError(f"need 0 < lo < hi, got {lo}, {hi}")
        self.lo = float(lo)
        self.per_decade = int(bins_per_decade)
        self._log_lo = math.log10(lo)
        self.n_bins = int(math.ceil((math.log10(hi) - self._log_lo) * self.per_decade))
        self.counts = np.zeros(self.n_bins, dtype=np.int64)
        self.count = 0
        self.min = math.inf
        self.max = -math.inf

    def __len__(self) -> int:
        return self.count

    def add(self, value: float) -> None:
        """Count one sample (NaN is ignored; values at or below ``lo`` go in the first bin)."""
        if value != value:  # NaN
            return
        k = int((math.log10(value) - self._log_lo) * self.per_decade) if value > self.lo else 0
        self.counts[min(max(k, 0), self.n_bins - 1)] += 1
        self.count += 1
        if value < self.min:
            self.min = value
        if value > self.max:
            self.max = value

    def percentile(self, q: float) -> float:
        """The ``q`` th percentile (0..100): the geometric centre of the bin holding it, clipped to the
        exact minimum and maximum (which 0 and 100 give); NaN without samples."""
        if self.count == 0:
            return math.nan
        if q <= 0 or q >= 100:
            return float(self.min if q <= 0 else self.max)
        rank = q / 100.0 * (self.count - 1)  # numpy's default (linear) percentile's lower sample
        k = int(np.searchsorted(np.cumsum(self.counts), math.floor(rank) + 1))
        centre = 10 ** (self._log_lo + (k + 0.5) / self.per_decade)
        return float(min(max(centre, self.min), self.max))

    def percentiles(self, *qs: float) -> tuple[float, ...]:
        return tuple(self.percentile(q) for q in qs)
