"""Which sinks the session calls: every input message only to the sinks that want it, the fused pose
only when some sink wants it; sinks added later (add_sink, or the list itself) are seen too."""

from __future__ import annotations

import numpy as np

from fgloc.localization import Localizer, Session
from fgloc.localization.session import BaseSink, RecorderSink
from fgloc.types import LaserScan, Odometry, StaticTransform


class Counting(BaseSink):
    def __init__(self, wants_messages: bool = True, wants_fused: bool = True) -> None:
        self.wants_messages = wants_messages
        self.wants_fused = wants_fused
        self.messages = 0
        self.fused: list[object] = []

    def on_message(self, topic: str, msg: object) -> None:
        self.messages += 1

    def on_scan(self, stamp, scan, fix_or_reason, fused) -> None:
        self.fused.append(fused)


class Writer:
    def __init__(self) -> None:
        self.written: list[str] = []

    def write(self, topic, msg, stamp=None, log_time_ns=None) -> None:
        self.written.append(topic)


def _messages(n: int = 30) -> list[tuple[str, object]]:
    out: list[tuple[str, object]] = []
    for k in range(n):
        t = 1.0 + 0.02 * k
        out.append(("/odom", Odometry(stamp=t, twist=np.array([0.1, 0.0, 0.0]), pose=np.array([0.1 * t, 0.0, 0.0]))))
        if k % 5 == 4:
            out.append(("/scan", LaserScan(stamp=t, angle_min=-1.0, angle_increment=0.01, range_min=0.1,
                                           range_max=10.0, ranges=np.full(201, 2.0, dtype=np.float32))))
    return out


def test_sinks_see_what_they_ask_for():
    loc = Localizer(None, StaticTransform("base_link", "laser", np.zeros(3)))  # odom-frame fusion
    quiet, blind = Counting(wants_messages=False), Counting(wants_fused=False)
    writer = Writer()
    rec = RecorderSink(writer, record_inputs=False)
    session = Session(loc, sinks=[quiet, blind, rec])
    msgs = _messages()
    for topic, msg in msgs[:10]:
        session.feed(topic, msg)
    late = Counting()
    session.add_sink(late)
    appended = Counting()
    session.sinks.append(appended)  # the list itself, as callers may
    for topic, msg in msgs[10:]:
        session.feed(topic, msg)
    session.finish()
    assert quiet.messages == 0 and blind.messages == len(msgs)
    assert late.messages == len(msgs) - 10 and appended.messages == len(msgs) - 10
    scans = sum(1 for t, _ in msgs if t == "/scan")
    assert len(quiet.fused) == len(blind.fused) == scans  # on_scan for every sink
    assert any(f is not None for f in quiet.fused)  # someone wants the fused pose: it is computed
    assert writer.written.count("/fused_pose") == sum(1 for f in quiet.fused if f is not None)
    assert "/odom" not in writer.written  # record_inputs=False: the inputs are not written


def test_no_sink_wants_the_fused_pose():
    loc = Localizer(None, StaticTransform("base_link", "laser", np.zeros(3)))
    blind = Counting(wants_fused=False)
    session = Session(loc, sinks=[blind])
    session.run(_messages())
    assert blind.fused and all(f is None for f in blind.fused)
