"""The health estimators hold a bounded amount whatever the session's length, and estimate the same
as with everything kept."""

from __future__ import annotations

import math

import numpy as np

from fgloc.backends.health import Arbiter, LatencyEstimator
from fgloc.backends.health.arbiter import ABSOLUTE, ANGLE_ABSOLUTE, INSTANT_RATE, RATE


class _KeepsAll(Arbiter):
    """The arbiter as it was before it forgot processed readings (every reading kept)."""

    def _forget_before(self, t: float) -> None:
        pass


def _feed(arb: Arbiter, seconds: float, seed: int = 3) -> int:
    """Wheels (50 Hz), a gyro (100 Hz), a compass (20 Hz) and a scan heading (25 Hz, where the
    arbiter is updated) on a robot that alternates standing and turning; the most readings a
    stream held at an update."""
    rng = np.random.default_rng(seed)

    def rate(t: float) -> float:
        return 0.0 if (t // 7.0) % 2 == 0 else 0.4 * math.sin(0.3 * t)

    def yaw(t: float) -> float:  # the integral of rate(), numerically (the test needs only consistency)
        return 0.05 * t

    streams = [("odom", RATE, 0.02, 50.0, lambda t: rate(t) * 1.02 + rng.normal(0, 0.01), 1e-4),
               ("gyro", INSTANT_RATE, 0.01, 100.0, lambda t: rate(t) + 0.002 + rng.normal(0, 0.003), 1e-5),
               ("compass", ANGLE_ABSOLUTE, 0.005, 20.0, lambda t: yaw(t) + rng.normal(0, 0.01), 1e-4),
               ("scan", ABSOLUTE, 0.005, 25.0, lambda t: yaw(t) + rng.normal(0, 0.004), 2e-5)]
    events = sorted((k / hz + 0.001 * j, j) for j, (_, _, _, hz, _, _) in enumerate(streams)
                    for k in range(int(seconds * hz)))
    held = 0
    for t, j in events:
        name, kind, rel, _, value, var = streams[j]
        arb.add_reading(name, kind, rel, t, value(t), var)
        if name == "scan":
            arb.update(t)
            held = max(held, max(len(s.t) for s in arb.streams.values()))
    return held


def test_arbiter_holds_seconds_of_readings_and_estimates_the_same():
    """150 s of four streams (29,000 readings): each stream holds under half a second of readings
    (the processed blocks' are dropped, where all were kept: 15,000 of the gyro), and every
    estimate equals the one with all kept."""
    kept, bounded = _KeepsAll(long_blocks=(4, 16)), Arbiter(long_blocks=(4, 16))
    held_all = _feed(kept, 150.0)
    held = _feed(bounded, 150.0)
    assert held_all >= 14900          # every gyro reading of the session
    assert held <= 100 * (bounded.block_s + bounded.settle_s) + 5   # the 100 Hz gyro: < 0.45 s of it
    assert bounded.blocks == kept.blocks > 1000
    for name in kept.streams:
        assert bounded.noise(name) == kept.noise(name), name
        assert bounded.shown_k(name) == kept.shown_k(name), name
        assert bounded.shown_sigma(name) == kept.shown_sigma(name), name
    assert any(kept.noise(n) != (1.0, 0.0) for n in kept.streams)   # something was estimated


def test_latency_estimator_keeps_max_rows_in_one_array_and_fits_the_newest():
    """Past ``max_rows`` pairs the estimator holds one array of at most twice that many rows, and its
    fit is the fit of a fresh estimator given only the newest ``max_rows`` pairs."""
    rng = np.random.default_rng(5)
    n, cap = 5000, 800
    x = rng.normal(0, 0.5, n)
    ref = rng.normal(0, 0.3, n)
    r = 0.03 * x + rng.normal(0, 0.002, n)   # 30 ms late: r = delta * x
    est = LatencyEstimator(max_rows=cap)
    for i in range(n):
        est.add(float(x[i]), float(r[i]), 1e-5, float(ref[i]), i % 2)
    assert est.n == n and len(est._buf) <= 2 * cap + 2
    fresh = LatencyEstimator(max_rows=cap)
    for i in range(n - cap, n):
        fresh.add(float(x[i]), float(r[i]), 1e-5, float(ref[i]), i % 2)
    fresh.n = est.n   # the same refit schedule
    fresh._refit_after = 0
    est._refit_after = 0
    d, s = est.estimate()
    assert (d, s) == fresh.estimate()
    assert abs(d - 0.03) < 3 * s and s < 0.002


def test_step_median_is_the_median_period_of_a_growing_list():
    """The running median of a stamp list that grows at its end (one to a few stamps at a time, now and
    then more than the window) and loses its oldest (now and then, or all but a few) is, at every call,
    the median spacing of its last stamps as computed from scratch."""
    from fgloc.backends.health.latency import PERIOD_STAMPS, StepMedian, median_period

    rng = np.random.default_rng(5)
    ts: list[float] = []
    sm = StepMedian()
    t = 0.0
    calls = 0
    for _ in range(3000):
        for _ in range(int(rng.choice([0, 1, 1, 2, 3, PERIOD_STAMPS + 10]))):
            t += float(rng.choice([0.02, 0.02, 0.0201, 0.019, float(rng.uniform(1e-6, 0.05))]))
            ts.append(t)
        if rng.random() < 0.03 and len(ts) > 10:
            del ts[:int(rng.integers(1, len(ts) - 2))]
        got, want = sm.of(ts), median_period(ts)
        assert got == want or (math.isinf(got) and math.isinf(want))
        calls += 1
    assert calls == 3000 and len(ts) > PERIOD_STAMPS
