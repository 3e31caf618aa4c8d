"""Run-long percentiles in constant memory (fgloc live's and --ros2's latencies): within half a bin of numpy's."""

from __future__ import annotations

import math

import numpy as np

from fgloc.quantiles import LogHistogram


def test_percentiles_within_half_a_bin_of_the_samples() -> None:
    rng = np.random.default_rng(3)
    x = np.concatenate([rng.lognormal(0.7, 0.5, 20000), rng.lognormal(3.5, 0.4, 300)])  # ms: a body and a tail
    h = LogHistogram()
    for v in x:
        h.add(float(v))
    half_bin = 10 ** (0.5 / h.per_decade) - 1  # 0.58 %
    for q in (1, 50, 90, 99, 99.9):
        exact = float(np.percentile(x, q, method="lower"))
        assert abs(h.percentile(q) / exact - 1) <= half_bin + 1e-12, q
    assert h.percentile(0) == x.min() and h.percentile(100) == x.max()
    assert len(h) == len(x)


def test_memory_is_constant_and_edges_are_counted() -> None:
    h = LogHistogram(lo=1e-3, hi=1e3, bins_per_decade=100)
    size = h.counts.nbytes
    for v in (0.0, -1.0, 1e-9, 5e6, math.nan, 2.0):
        h.add(v)
    assert h.counts.nbytes == size == 600 * 8
    assert len(h) == 5 and h.counts[0] == 3 and h.counts[-1] == 1  # NaN not counted
    assert h.percentile(100) == 5e6 and h.percentile(0) == -1.0
    assert math.isnan(LogHistogram().percentile(50))
