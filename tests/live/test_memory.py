"""A live session's run-long records are bounded: the live trajectory without -o keeps a tail,
with -o every pose (compactly); latencies keep the newest and the whole run in a histogram, events the newest."""

from __future__ import annotations

import numpy as np

from fgloc import memory
from fgloc.live import runner as runner_mod
from fgloc.live.runner import LiveRunner, TrajectoryBuffer
from fgloc.localization import build_session
from fgloc.types import StaticTransform


def _poses(n: int, rate_hz: float = 25.0) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(n) / rate_hz
    return t, np.column_stack([t, -t, np.sin(t)])


def test_whole_trajectory_keeps_every_pose_in_order():
    buf = TrajectoryBuffer()
    t, p = _poses(5000)
    for ti, pi in zip(t, p, strict=True):
        buf.append(ti, pi)
    buf.append(t[10], p[10])  # not after the last: not kept
    assert len(buf) == buf.total == 5000
    assert np.array_equal(buf.stamps, t) and np.array_equal(buf.poses, p)
    assert len(buf._t) < 2 * 5000  # grows by doubling, not per pose


def test_windowed_trajectory_keeps_a_bounded_tail():
    buf = TrajectoryBuffer(window_s=10.0)
    t, p = _poses(25 * 3600)  # an hour at 25 Hz
    for ti, pi in zip(t, p, strict=True):
        buf.append(ti, pi)
    assert buf.total == len(t)
    # at least the last 10 s, at most twice the window's poses, stored in a fixed allocation
    assert buf.stamps[0] <= t[-1] - 10.0 and buf.stamps[-1] == t[-1]
    assert 250 <= len(buf) <= 2 * 251 and len(buf._t) <= 1024
    k = len(buf)
    assert np.array_equal(buf.stamps, t[-k:]) and np.array_equal(buf.poses, p[-k:])


def test_runner_latencies_and_events_are_bounded(monkeypatch):
    monkeypatch.setattr(runner_mod, "LATENCIES_KEPT", 100)
    monkeypatch.setattr(runner_mod, "EVENTS_KEPT", 10)
    session = build_session(None, StaticTransform("base_link", "laser", np.zeros(3)), backend="ekf")
    r = LiveRunner(session, silence_s=0.1)
    for i in range(1000):
        r.add_latency(float(i + 1))
        r._mark("odom", 10.0 * i)
        r.check_health(10.0 * i + 1.0)  # silent, then back at the next message
    assert len(r.latencies_ms) == 100 and len(r.events) == 10
    assert r.latency_percentiles(last=50) == tuple(np.percentile(np.arange(951, 1001), [50, 99]))
    # the summary's percentiles are the whole run's, in a fixed-size histogram (within half a bin)
    p50, p99 = r.latency_percentiles()
    want50, want99 = np.percentile(np.arange(1, 1001), [50, 99])
    assert abs(p50 / want50 - 1) < 0.006 and abs(p99 / want99 - 1) < 0.006
    assert r.latency_hist.count == 1000 and r.latency_hist.counts.nbytes < 20_000
    assert r.events[-1].kind == "silent" and r.events[0].t > 10.0 * 990


def test_a_bounded_history_keeps_the_last_seconds_and_changes_no_estimate():
    """The localizer's run-long records (fixes, the back-end's online trajectory, the smoother's smoothed
    keyframes and keyframe index) cut to ``keep_history(h)``: at most about 2 h of them held, and every
    pose the same as with the whole history."""
    from fgloc.testing.soak import feed_live, lap_world

    w = lap_world()
    runs = {}
    for h in (None, 2.0):
        session = build_session(w.map, w.mount, backend="smoother", frontend="native", initial_pose=w.pose(0.0))
        session.loc.keep_history(h)
        r = LiveRunner(session, trajectory_window_s=h)
        feed_live(r, w.messages(12.0))
        runs[h] = (session.loc, r, session.loc.online_trajectory(), session.loc.finish())
    loc_all, r_all, online_all, final_all = runs[None]
    loc, r, online, final = runs[2.0]
    be = loc.backend
    t_end = float(online_all.stamps[-1])
    for name, stamps in (("fixes", [f.stamp for f in loc.fixes]), ("online", online.stamps),
                         ("smoothed", [v[0] for v in be.smoothed.values()]), ("keyframes", be.kf_t)):
        assert 2.0 - 0.5 <= t_end - min(stamps) <= 2 * 2.0 + 0.5, name  # the last 2-4 s, not 12
    assert len(loc_all.fixes) > 2 * len(loc.fixes) and len(online_all) > 2 * len(online)
    # the same estimates where both have them
    k = np.searchsorted(online_all.stamps, online.stamps)
    assert np.array_equal(online_all.stamps[k], online.stamps) and np.array_equal(online_all.poses[k], online.poses)
    k = np.searchsorted(final_all.stamps, final.stamps)
    assert np.array_equal(final_all.stamps[k], final.stamps) and np.allclose(final_all.poses[k], final.poses, atol=1e-9)
    assert r.trajectory.total == r_all.trajectory.total == r.counters["scans_fused"] == 300
    # iSAM2 puts new factors into the slots marginalized ones left: its graph holds the window's
    # factors, not a slot for every factor of the session (756 slots for 129 factors after 12 s)
    for b in (be, loc_all.backend):
        g = b.isam.getFactors()
        assert g.size() <= 1.5 * g.nrFactors() + 20, (g.size(), g.nrFactors())


def test_the_fusion_loop_returns_the_c_heaps_free_pages(monkeypatch):
    """Every TRIM_PERIOD_S the loop hands glibc's freed pages back (messages allocated in the sensor
    threads' arenas, freed in the loop's); counted, and nothing else changes."""
    monkeypatch.setattr(runner_mod, "TRIM_PERIOD_S", 0.0)
    r = LiveRunner(build_session(None, StaticTransform("base_link", "laser", np.zeros(3)), backend="ekf"))
    for _ in range(3):
        r.step(timeout=0.0)
    assert r.counters.get("malloc_trims", 0) == (3 if memory.available() else 0)  # 3 with glibc
    assert r.counters["scans_fused"] == 0 and r.counters["queue_dropped"] == 0


def test_the_scan_latency_window_is_held_from_the_first_pair():
    """The latency estimator's pairs (its newest max_rows) take their memory at the first pair and never more:
    a live session's memory does not grow while the window fills; the estimate is the newest rows' fit."""
    import tracemalloc

    from fgloc.backends.health import LatencyEstimator

    rng = np.random.default_rng(0)
    x = rng.normal(size=7000)
    r = -0.04 * x + rng.normal(scale=0.01, size=x.size)
    ref = rng.normal(size=x.size)
    # only what the estimator's code holds (any frame in fgloc/backends/health): threads a previous test left
    # running in this process allocate too, and are not this test's subject
    only = [tracemalloc.Filter(True, "*fgloc*backends*health*", all_frames=True)]

    def held() -> int:
        return sum(s.size for s in tracemalloc.take_snapshot().filter_traces(only).statistics("filename"))

    tracemalloc.start(30)
    try:
        est = LatencyEstimator(max_rows=2000, refit_every=1, refit_share=0.0)
        est.add(x[0], r[0], 1e-4, ref[0], 0)
        first = held()
        for k in range(1, x.size):
            est.add(x[k], r[k], 1e-4, ref[k], k % 2)
        grown = held() - first
    finally:
        tracemalloc.stop()
    assert first >= 2000 * 5 * 8 and grown < 4096, (first, grown)  # the window's 2000 rows of 5 floats
    newest = LatencyEstimator(max_rows=2000, refit_every=1, refit_share=0.0)
    for k in range(x.size - 2000, x.size):
        newest.add(x[k], r[k], 1e-4, ref[k], k % 2)
    assert est.estimate() == newest.estimate() and abs(est.estimate()[0] + 0.04) < 0.005
