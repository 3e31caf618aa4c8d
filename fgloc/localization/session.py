"""One localization session: input routing in, sinks out.

A :class:`Session` wraps a :class:`~fgloc.localization.localizer.Localizer`.  It takes
``(topic, message)`` pairs (:meth:`Session.feed`; a log, a simulation) or ``(kind, message)``
(:meth:`Session.dispatch`; the live runner, whose sensor threads know what they read), routes
them to the localizer and tells every sink what happened.  ``fgloc run``, ``fgloc live`` and
the benches all drive the same session; only the sinks differ.

Routing is one layer, built once with the session: a table ``topic -> kind`` (:class:`Routes`)
and ``kind -> handler``, the handlers of :class:`~fgloc.localization.sources.SourceRouter`
(one per configured source, ``source:NAME``; ``scan``; ``tf``), each of which checks its
messages and hands them to the localizer or the back-end.  The routes given name the scan topic
and the default layout's odometry / IMU topics (``odom``, ``imu``); the config's ``sources:``
name the rest.  A message dispatched by kind ``odom`` / ``imu`` goes to the first source of that
type.

The sink protocol (:class:`Sink`; subclass :class:`BaseSink` and override what you need):

``on_message(topic, msg)``
    every input message, before it is routed (recording, progress);
``on_scan(stamp, scan, fix_or_reason, fused)``
    after each scan was localized: ``fix_or_reason`` is the front-end's
    :class:`~fgloc.types.PoseFix`, or a ``str`` saying why there is none; ``fused`` is the
    localizer's fused pose (``PoseFix`` in ``map`` / ``odom``, with its ``status``) or None
    before start-up;
``on_pose(stamp, fused)``
    a fused pose the localizer added without a scan: dead reckoning while the laser is silent,
    the poses of a log without scans (optional: a sink without it is not called);
``close()``
    once, at the end (:meth:`Session.finish`).

A sink must not raise; if one does, the session counts it in ``sink_errors`` and goes on.
A sink whose ``wants_fused`` is False (a progress bar) does not make the session compute the
fused pose, and those before the first sink that wants it are told before it is computed, with
``fused=None`` (a ROS 2 transform out before the marginal covariance); when no sink wants it,
``on_scan`` gets ``fused=None``.  A sink whose
``wants_messages`` is False (a recorder of the outputs only) is not called for each input
message.  Both are read when the sink is added (the session keeps the lists).

The fused pose's covariance: a smoother's is an iSAM2 marginal (not free), so the session
refreshes it at most every ``covariance_period_s`` of log time (default
:data:`COVARIANCE_PERIOD_S`; 0: at every scan).  In between, the fused pose is as
fresh as ever (the newest keyframe carried to the newest odometry) and its covariance is the
last marginal plus the odometry noise since that keyframe.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

from fgloc.localization.localizer import Localizer
from fgloc.types import LaserScan, PoseFix, StaticTransform, Trajectory

if TYPE_CHECKING:
    import numpy as np

    from fgloc.maps import OccupancyMap

DEFAULT_TOPICS = {"scan": "/scan", "odom": "/odom", "imu": "/imu"}
COVARIANCE_PERIOD_S = 1.0  # log time between two marginal covariances of the fused pose (0: every scan)


@runtime_checkable
class Sink(Protocol):
    """What a session feeds (see the module docstring)."""

    def on_message(self, topic: str, msg: object) -> None: ...

    def on_scan(self, stamp: float, scan: LaserScan, fix_or_reason: PoseFix | str, fused: PoseFix | None) -> None: ...

    def close(self) -> None: ...


class BaseSink:
    """A sink that does nothing: override the methods you need."""

    wants_fused = True  # False: this sink's on_scan does not need the fused pose
    wants_messages = True  # False: this sink's on_message does nothing (not called)

    def on_message(self, topic: str, msg: object) -> None:
        pass

    def on_scan(self, stamp: float, scan: LaserScan, fix_or_reason: PoseFix | str, fused: PoseFix | None) -> None:
        pass

    def on_pose(self, stamp: float, fused: PoseFix) -> None:
        """A fused pose without a scan (dead reckoning while the laser is silent; a log without scans)."""

    def close(self) -> None:
        pass


@dataclass
class Routes:
    """Which input kind each topic is.  ``Routes.default(topics)`` maps the scan/odom/imu topic
    names of a :class:`fgloc.io.topics.Topics` (or a mapping ``kind -> topic``) to their kinds."""

    table: dict[str, str] = field(default_factory=lambda: {v: k for k, v in DEFAULT_TOPICS.items()})

    @classmethod
    def default(cls, topics: Any = None) -> Routes:
        names = dict(DEFAULT_TOPICS)
        if isinstance(topics, dict):
            names.update({k: v for k, v in topics.items() if k in names})
        elif topics is not None:
            names.update({k: getattr(topics, k) for k in names if hasattr(topics, k)})
        return cls({topic: kind for kind, topic in names.items()})

    def kind(self, topic: str) -> str | None:
        return self.table.get(topic)

    def topics(self) -> set[str]:
        return set(self.table)


class Session:
    """A localizer, its input routing and its sinks (see the module docstring)."""

    def __init__(self, localizer: Localizer, routes: Routes | None = None, sinks: Iterable[Sink] = (),
                 covariance_period_s: float | None = None) -> None:
        self.loc = localizer
        self.routes = routes or Routes.default()
        self.sinks: list[Sink] = list(sinks)
        self._observers: list[Sink] = []  # the sinks that see every input message
        self._wants_fused = False  # some sink's on_scan needs the fused pose
        self._known: list[Sink] = []  # the sinks the two above were computed for
        self.sink_errors = 0
        self.closed = False
        self.last_fused: PoseFix | None = None
        self.covariance_period_s = COVARIANCE_PERIOD_S if covariance_period_s is None else float(covariance_period_s)
        self._cov_stamp: float | None = None  # scan stamp of the last marginal covariance
        # the inputs (fgloc.localization.sources): one handler per configured source, built once; the
        # odom / imu topics given name the default layout's sources and are routed to them
        from fgloc.localization.sources import SourceRouter
        from fgloc.localization.sources.router import DISPATCH_KINDS, TF_TOPICS

        given = self.routes.table
        self.sources = SourceRouter.from_config(localizer, {k: t for t, k in given.items() if k in DISPATCH_KINDS},
                                                self._localized)
        table = {t: k for t, k in given.items() if k not in DISPATCH_KINDS}
        table.update(self.sources.topic_kinds())
        for tf_topic in TF_TOPICS:
            table.setdefault(tf_topic, "tf")
        self.routes = Routes(table)
        #: kind -> handler: the scans, each source, the dispatch kinds (odom, imu) and tf
        self.handlers: dict[str, Callable[[object], None]] = self.sources.kinds()
        localizer.pose_listener = self._pose_added

    def add_sink(self, sink: Sink) -> None:
        self.sinks.append(sink)

    def _refresh(self) -> list[Sink]:
        """The sinks that see every message (and whether any wants the fused pose), recomputed
        when :attr:`sinks` changed (a message at a time, this is a list comparison)."""
        if self._known != self.sinks:
            self._known = list(self.sinks)
            self._observers = [s for s in self._known if getattr(s, "wants_messages", True)]
            self._wants_fused = any(getattr(s, "wants_fused", True) for s in self._known)
        return self._observers

    # ------------------------------------------------------------------ input
    def feed(self, topic: str, msg: object) -> None:
        """One input message by topic: shown to the sinks, then routed (unrouted topics: sinks only)."""
        if self._observers or self._known != self.sinks:
            self.observe(topic, msg)
        kind = self.routes.table.get(topic)
        if kind is not None:
            h = self.handlers.get(kind)
            if h is not None:
                h(msg)

    def observe(self, topic: str, msg: object) -> None:
        """Show a message to the sinks without localizing with it (e.g. a recorded, skipped scan)."""
        for s in self._observers if self._known == self.sinks else self._refresh():
            try:
                s.on_message(topic, msg)
            except Exception:  # noqa: BLE001 - a sink must never stop localization
                self.sink_errors += 1

    def dispatch(self, kind: str, msg: object) -> None:
        """One input message by kind (``odom``, ``imu``, ``scan``, ``tf`` or ``source:NAME``)."""
        h = self.handlers.get(kind)
        if h is not None:
            h(msg)

    def run(self, messages: Iterable[tuple[str, object]]) -> Trajectory:
        """Feed every ``(topic, message)`` pair, then :meth:`finish`."""
        for topic, msg in messages:
            self.feed(topic, msg)
        return self.finish()

    def finish(self) -> Trajectory:
        """The localizer's final (smoothed) trajectory; closes the sinks."""
        tr = self.loc.finish()
        self.sources.finish()
        self.close()
        return tr

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        for s in self.sinks:
            try:
                s.close()
            except Exception:  # noqa: BLE001
                self.sink_errors += 1

    # ------------------------------------------------------------------ scans
    def _localized(self, msg: LaserScan, fix: PoseFix | None) -> None:
        """After a scan was localized: the sinks are told (with the fused pose when one wants it)."""
        if not self.sinks:
            return  # nobody asks for the fused pose (its covariance is not free for a smoother)
        if self._known != self.sinks:
            self._refresh()
        what: PoseFix | str = fix if fix is not None else (self.loc.last_reason or "no fix")
        k = 0  # the sinks before the first that wants the fused pose are told before it is computed
        while self._wants_fused and k < len(self.sinks) and not getattr(self.sinks[k], "wants_fused", True):
            k += 1
        fused = None
        for i, s in enumerate(self.sinks):
            if i == k and self._wants_fused:
                fused = self._fused(float(msg.stamp))
                self.last_fused = fused
            try:
                s.on_scan(float(msg.stamp), msg, what, fused)
            except Exception:  # noqa: BLE001
                self.sink_errors += 1
        if not self._wants_fused:
            self.last_fused = None


    def _pose_added(self, stamp: float) -> None:
        """A pose without a scan (a silent laser, a log without scans): the sinks' ``on_pose``."""
        if not self.sinks:
            return
        if self._known != self.sinks:
            self._refresh()
        fused = self._fused(stamp) if self._wants_fused else None
        if fused is None:
            return
        self.last_fused = fused
        for s in self.sinks:
            on_pose = getattr(s, "on_pose", None)
            if on_pose is None:
                continue
            try:
                on_pose(stamp, fused)
            except Exception:  # noqa: BLE001
                self.sink_errors += 1

    def _fused(self, stamp: float) -> PoseFix | None:
        """The fused pose; its covariance a fresh marginal only every ``covariance_period_s``."""
        last = self._cov_stamp
        fresh = (self.covariance_period_s <= 0 or last is None or not math.isfinite(stamp)
                 or stamp < last or stamp - last >= self.covariance_period_s)
        fused = self.loc.current(covariance=fresh, at=stamp)
        if fresh and fused is not None:
            self._cov_stamp = stamp
        return fused


def build_session(occ_map: OccupancyMap | None, laser_mount: StaticTransform, *, backend: str = "smoother",
                  frontend: str = "native", initial_pose: np.ndarray | None = None, config: Any = None,
                  routes: Routes | None = None, sinks: Iterable[Sink] = (),
                  covariance_period_s: float | None = None) -> Session:
    """The one way a session is built (``fgloc run``, ``fgloc live``, the benches): a
    :class:`Localizer` on ``occ_map`` (None: odom-frame fusion) with the laser at ``laser_mount``,
    the named back-end and front-end, ``initial_pose`` (None: global localization) and ``config``
    (a :class:`~fgloc.config.FglocConfig`, a mapping, or None: the defaults), driven by a
    :class:`Session` with ``routes`` (None: the default topics) and ``sinks``.  The localizer is
    ``session.loc``; more sinks may be added with :meth:`Session.add_sink`."""
    loc = Localizer(occ_map, laser_mount, backend=backend, frontend=frontend, initial_pose=initial_pose,
                    config=config)
    return Session(loc, routes, sinks, covariance_period_s=covariance_period_s)


# ---------------------------------------------------------------------- sinks
class RecorderSink(BaseSink):
    """Writes every input and the fused pose (``fused_topic``) to a writer with
    ``write(topic, msg, stamp=None, log_time_ns=None)`` (an :class:`fgloc.io.mcap_writer.LogWriter`);
    closes it if asked.

    ``record_inputs=False``: only what the localizer produces (``/fused_pose``), for a caller
    that copies the inputs itself (``fgloc run`` copies the log's own bytes,
    :meth:`fgloc.io.mcap_writer.LogWriter.copy`).  ``log_time_ns()``: the MCAP log time of
    what is written now (``fgloc run``: the log time of the input being processed, so the
    outputs sit beside the inputs on the input's recording clock); None: the header stamp.
    """

    def __init__(self, writer: Any, fused_topic: str = "/fused_pose", close_writer: bool = False,
                 tolerate: tuple[type[BaseException], ...] = (TypeError, ValueError), record_inputs: bool = True,
                 log_time_ns: Callable[[], int | None] | None = None) -> None:
        self.writer = writer
        self.fused_topic = fused_topic
        self.close_writer = close_writer
        self.tolerate = tolerate  # write errors counted in ``errors`` (others raise)
        self.record_inputs = record_inputs
        self.wants_messages = record_inputs
        self.log_time_ns = log_time_ns
        self.errors = 0

    def on_message(self, topic: str, msg: object) -> None:
        if not self.record_inputs:
            return
        try:
            self.writer.write(topic, msg, getattr(msg, "stamp", None))
        except self.tolerate:  # e.g. a message the writer has no schema for
            self.errors += 1

    def on_scan(self, stamp: float, scan: LaserScan, fix_or_reason: PoseFix | str, fused: PoseFix | None) -> None:
        if fused is not None:
            try:
                if self.log_time_ns is None:
                    self.writer.write(self.fused_topic, fused, float(fused.stamp))
                else:
                    self.writer.write(self.fused_topic, fused, float(fused.stamp), log_time_ns=self.log_time_ns())
            except self.tolerate:
                self.errors += 1

    def on_pose(self, stamp: float, fused: PoseFix) -> None:
        self.on_scan(stamp, None, "", fused)  # type: ignore[arg-type]  # the scan is not read

    def close(self) -> None:
        if self.close_writer:
            if hasattr(self.writer, "__exit__"):
                self.writer.__exit__(None, None, None)
            elif hasattr(self.writer, "close"):
                self.writer.close()


class CallbackSink(BaseSink):
    """Calls ``on_message(topic, msg)`` / ``on_scan(stamp, scan, fix_or_reason, fused)`` if given."""

    def __init__(self, on_message: Callable[[str, object], None] | None = None,
                 on_scan: Callable[[float, LaserScan, PoseFix | str, PoseFix | None], None] | None = None) -> None:
        self._m = on_message
        self._s = on_scan
        self.wants_fused = on_scan is not None
        self.wants_messages = on_message is not None

    def on_message(self, topic: str, msg: object) -> None:
        if self._m is not None:
            self._m(topic, msg)

    def on_scan(self, stamp: float, scan: LaserScan, fix_or_reason: PoseFix | str, fused: PoseFix | None) -> None:
        if self._s is not None:
            self._s(stamp, scan, fix_or_reason, fused)


class UdpSink(BaseSink):
    """Publishes each fused pose with a :class:`fgloc.live.publish.UdpPublisher` (``pose(fix,
    latency_ms)``); ``latency_ms()`` gives the latency of the scan just fused (live runner)."""

    def __init__(self, publisher: Any, latency_ms: Callable[[], float] | None = None,
                 close_publisher: bool = True) -> None:
        self.publisher = publisher
        self.latency_ms = latency_ms or (lambda: float("nan"))
        self.close_publisher = close_publisher

    def on_scan(self, stamp: float, scan: LaserScan, fix_or_reason: PoseFix | str, fused: PoseFix | None) -> None:
        if fused is not None:
            self.publisher.pose(fused, self.latency_ms())

    def on_pose(self, stamp: float, fused: PoseFix) -> None:
        self.publisher.pose(fused, float("nan"))

    def close(self) -> None:
        if self.close_publisher:
            self.publisher.close()
