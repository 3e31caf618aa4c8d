"""The live runner's input queue is bounded: sensor threads flooding a runner that does not keep up
never block and never grow it past its bound; the oldest messages are dropped, counted by kind, said
once on the event line and on the status line, and every scan is still fused or counted."""

from __future__ import annotations

import threading

import numpy as np

from fgloc.config import parse_config
from fgloc.live.app import LiveSession
from fgloc.live.runner import LiveRunner
from fgloc.localization import build_session
from fgloc.types import StaticTransform

from .streams import synthetic_messages


def _session():
    return build_session(None, StaticTransform("base_link", "laser", np.zeros(3)), backend="ekf")


def test_flooded_queue_drops_the_oldest_counted_and_every_scan_is_accounted_for():
    msgs = synthetic_messages(duration=8.0)  # 400 odom, 160 imu, 200 scans: 760
    kinds = {"/odom": "odom", "/imu": "imu", "/scan": "scan"}
    events: list[str] = []
    r = LiveRunner(_session(), event_sink=events.append, queue_max_msgs=50)
    # three producer threads push everything while nothing is consumed (a stalled fusion loop)
    parts = [[(kinds[t], m, float(m.stamp)) for t, m in msgs if kinds[t] == k] for k in ("odom", "imu", "scan")]
    threads = [threading.Thread(target=lambda p=p: [r.push(*x) for x in p]) for p in parts]
    for th in threads:
        th.start()
    for th in threads:
        th.join(10.0)
    assert not any(th.is_alive() for th in threads)  # push never blocks
    n = len(msgs)
    assert r.q.qsize() == 50
    c = r.all_counters()
    assert c["queue_dropped"] == n - 50
    assert sum(c["queue_dropped_by_kind"].values()) == n - 50
    # what is left is the newest of each producer (the oldest went first)
    left = list(r.q.queue)
    for k, p in zip(("odom", "imu", "scan"), parts, strict=True):
        kept = [m for kk, m, _ in left if kk == k]
        assert kept == [m for _, m, _ in p[len(p) - len(kept):]]
        assert c["queue_dropped_by_kind"].get(k, 0) == len(p) - len(kept)
    assert f"QUEUE FULL dropped {n - 50}" in r.status_line()

    r.step(timeout=0.0)
    r.drain()
    c = r.all_counters()
    n_scans = len(parts[2])
    assert c["scans_fused"] + c["scans_skipped_backlog"] + c["queue_dropped_by_kind"]["scan"] == n_scans
    assert c["scans_fused"] >= 1
    told = [e for e in events if e.startswith("input queue full")]
    assert len(told) == 1 and f"{n - 50} oldest dropped" in told[0] and "scan" in told[0]


def test_queue_below_its_bound_drops_nothing_and_the_bound_is_the_configs():
    r = LiveRunner(_session(), queue_max_msgs=1000)
    for t, m in synthetic_messages(duration=4.0):
        r.push({"/odom": "odom", "/imu": "imu", "/scan": "scan"}[t], m, float(m.stamp))
    r.drain()
    c = r.all_counters()
    assert c["queue_dropped"] == 0 and c["queue_dropped_by_kind"] == {}
    assert c["scans_fused"] + c["scans_skipped_backlog"] == 100
    assert "QUEUE FULL" not in r.status_line()

    cfg = parse_config({"health": {"queue_max_msgs": 123}})
    live = LiveSession(_session(), None, None, config=cfg)
    assert live.runner.q.maxsize == 123
    assert LiveRunner(_session()).q.maxsize == parse_config({}).health.queue_max_msgs
