"""What a long live run keeps grows no more once it is full: the gyro series in preallocated columns."""

from __future__ import annotations

import random
import tracemalloc
from bisect import bisect_right
from collections import deque

from fgloc.backends.health.gyro_bias import GyroBias, GyroSeries


def test_gyro_series_reads_as_a_bounded_deque():
    rng = random.Random(3)
    for n in (1, 2, 5, 64):
        d: deque[tuple[float, float, float, float]] = deque(maxlen=n)
        s = GyroSeries(n)
        t = 0.0
        for _ in range(6 * n + 7):  # wraps the columns several times
            t += rng.uniform(1e-3, 0.1)
            row = (t, rng.gauss(0, 1), rng.gauss(0, 1), rng.random())
            d.append(row)
            s.append(row)
            assert len(s) == len(d) and [s[i] for i in range(-len(d), len(d))] == list(d) * 2
            ts = [r[0] for r in d]
            for q in (ts[0], ts[-1], rng.uniform(ts[0] - 0.2, ts[-1] + 0.2)):
                lo = max(min(bisect_right(ts, q) - 1, len(ts) - 2), 0)
                assert s.bracket(q) == ((0, 0) if len(ts) < 2 else (lo, lo + 1))


def test_gyro_bias_memory_stops_growing_once_constructed():
    """20 Hz readings for 3x the history (5 min) with a heading source: the bytes Python holds after the
    first reading stay within 16 kB (the tuples of floats the series was before: ~180 bytes a reading,
    360 kB for 2000); the bias is estimated as before."""
    gb = GyroBias(history=2000)
    tracemalloc.start()
    try:
        gb.add_rate(0.0, 0.01, 1e-4)
        base = tracemalloc.get_traced_memory()[0]
        for i in range(1, 6_000):
            t = 0.05 * i
            gb.add_rate(t, 0.01, 1e-4)
            if i % 4 == 0:
                gb.add_heading("compass", t - 0.01, 0.0, 1e-4)
        grown = tracemalloc.get_traced_memory()[0] - base
    finally:
        tracemalloc.stop()
    assert len(gb.series) == 2000
    assert grown < 16_000, grown
    assert abs(gb.value() - 0.01) < 1e-3  # a gyro reading 0.01 rad/s while the heading stands still
