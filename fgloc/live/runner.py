"""The live fusion loop: sensor threads -> one queue -> a localization session and its sinks.

Threads: :class:`SerialLink` and :class:`SickClient` read and decode in their own
threads and push ``(kind, msg, arrival)`` into a queue; the fusion loop (the caller's
thread, :meth:`LiveRunner.run`) feeds a :class:`fgloc.localization.Session` (the same
one ``fgloc run`` drives) whose sinks record every received message and the fused pose
(MCAP via ``LogWriter``) and publish the fused pose (UDP); the runner keeps sensor
health: a sensor with no message for ``silence_s`` is reported silent (the others keep
running) and reported back when it returns.

Latency is measured from the host arrival time of a scan (when its last byte was
read) to the moment the fused pose is available after ``Localizer.on_scan``.
"""

from __future__ import annotations

import heapq
import math
import queue
import struct
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fgloc import memory
from fgloc.localization.session import BaseSink, RecorderSink, Session, UdpSink
from fgloc.quantiles import LogHistogram
from fgloc.types import LaserScan, PoseFix, StaticTransform, Trajectory

SENSORS = ("odom", "imu", "scan")
LATENCIES_KEPT = 5_000  # the newest scans' latencies, one by one (200 s at 25 Hz; the status line's window)
EVENTS_KEPT = 1_000      # health events kept (the newest)
#: how often the fusion loop hands the C allocator's free memory back to the system (glibc's malloc_trim):
#: the sensor threads allocate each message in their own malloc arenas and the loop frees it in its own,
#: which leaves freed but unreturned pages growing for the first tens of minutes
TRIM_PERIOD_S = 60.0
#: what happened to the session (a sensor silent or back, a connection lost, a device clock's step),
#: recorded as ``std_msgs/msg/String`` beside the inputs, at the host time it was reported
EVENTS_TOPIC = "/fgloc/events"


def string_cdr(text: str) -> bytes:
    """A ``std_msgs/msg/String`` in CDR (little endian): the encapsulation, the length with its NUL, the text."""
    b = text.encode("utf-8", "replace")
    return b"\x00\x01\x00\x00" + struct.pack("<I", len(b) + 1) + b + b"\x00"


@dataclass
class SensorHealth:
    name: str
    state: str = "waiting"  # waiting | ok | silent
    count: int = 0
    last_arrival: float = float("nan")  # time.monotonic()
    silent_since: float = float("nan")
    arrivals: deque[float] = field(default_factory=lambda: deque(maxlen=400))

    def rate_hz(self, now: float, window: float = 2.0) -> float:
        n = sum(1 for t in self.arrivals if now - t <= window)
        return n / window


class TrajectoryBuffer:
    """Poses with increasing stamps in growing numpy arrays (32 bytes a pose, not a list of arrays at
    ~190); with ``window_s``, only the last ``window_s`` seconds of them (a live session that
    writes no trajectory keeps a bounded tail)."""

    def __init__(self, window_s: float | None = None, capacity: int = 1024) -> None:
        self.window_s = window_s
        self._t = np.empty(capacity)
        self._p = np.empty((capacity, 3))
        self._a = self._n = 0  # the kept poses are [_a, _n)
        self.total = 0  # every pose appended

    def __len__(self) -> int:
        return self._n - self._a

    def append(self, t: float, pose: Any) -> None:
        if self._n > self._a and not t > self._t[self._n - 1]:
            return
        if self._n == len(self._t):
            self._make_room()
        self._t[self._n] = t
        self._p[self._n] = pose
        self._n += 1
        self.total += 1

    def _make_room(self) -> None:
        if self.window_s is not None:  # forget what left the window
            self._a = int(np.searchsorted(self._t[self._a : self._n], self._t[self._n - 1] - self.window_s)) + self._a
        keep = self._n - self._a
        size = max(len(self._t), 2 * keep, 1024) if self.window_s is None or keep > len(self._t) // 2 else len(self._t)
        t, p = np.empty(size), np.empty((size, 3))
        t[:keep], p[:keep] = self._t[self._a : self._n], self._p[self._a : self._n]
        self._t, self._p, self._a, self._n = t, p, 0, keep

    @property
    def stamps(self) -> np.ndarray:
        return self._t[self._a : self._n]

    @property
    def poses(self) -> np.ndarray:
        return self._p[self._a : self._n]


@dataclass
class HealthEvent:
    t: float  # time.monotonic()
    sensor: str
    kind: str  # "silent" | "back"
    gap_s: float


class _LiveTrack(BaseSink):
    """The runner's own sink: latency, the live trajectory and the fix count of each fused scan."""

    def __init__(self, runner: LiveRunner) -> None:
        self.r = runner

    def on_scan(self, stamp: float, scan: LaserScan, fix_or_reason: PoseFix | str, fused: PoseFix | None) -> None:
        r = self.r
        r.counters["scans_fused"] += 1
        if isinstance(fix_or_reason, PoseFix):
            r.counters["fixes"] += 1
        if fused is None:
            return
        r.add_latency((time.time() - r.scan_arrival) * 1e3)
        r.last_fix = fused
        r.trajectory.append(float(fused.stamp), fused.pose)

    def on_pose(self, stamp: float, fused: PoseFix) -> None:
        """A dead-reckoned pose while the laser is silent: the live pose and trajectory go on."""
        self.r.counters["poses_dead_reckoned"] += 1
        self.r.last_fix = fused
        self.r.trajectory.append(float(fused.stamp), fused.pose)


class LiveRunner:
    """Glue between the sensor threads and a localization session (built by
    :func:`fgloc.localization.build_session`; the runner adds its sinks to it).  Not tied to any I/O itself:
    ``recorder`` (``write(topic, msg, stamp)``), ``publisher`` (``pose(fix, latency_ms)``,
    ``status(...)``) and ``status_sink(line)`` are optional callables/objects; ``sinks`` are
    more :class:`fgloc.localization.Sink` s (a viewer)."""

    def __init__(
        self,
        session: Session,
        recorder: Any = None,
        publisher: Any = None,
        status_sink: Callable[[str], None] | None = None,
        event_sink: Callable[[str], None] | None = None,
        topics: dict[str, str] | None = None,
        laser_mount: StaticTransform | None = None,
        silence_s: float = 0.4,
        status_period_s: float = 0.25,
        sensors: tuple[str, ...] = SENSORS,
        reorder_s: float = 0.15,
        sinks: list[Any] | None = None,
        trajectory_window_s: float | None = None,
        queue_max_msgs: int | None = None,
    ) -> None:
        self.loc = session.loc
        self.recorder = recorder
        self.publisher = publisher
        self.status_sink = status_sink
        self.event_sink = event_sink or (lambda s: None)
        self.topics = {"odom": "/odom", "imu": "/imu", "scan": "/scan", "tf_static": "/tf_static",
                       "fused": "/fused_pose", "event": EVENTS_TOPIC}
        self.topics.update(topics or {})
        self.laser_mount = laser_mount
        self.silence_s = silence_s
        self.status_period_s = status_period_s
        if queue_max_msgs is None:
            from fgloc.live.config import HealthConfig

            queue_max_msgs = HealthConfig().queue_max_msgs
        # bounded: a host too slow for its input drops the oldest message (counted) rather than
        # holding ever more of them
        self.q: queue.Queue[tuple[str, Any, float]] = queue.Queue(maxsize=max(int(queue_max_msgs), 1))
        self.dropped: dict[str, int] = {}  # kind -> messages dropped from the full queue
        self._dropped_told = 0  # the drops the last event line told of
        self._drop_event_t = -math.inf  # when it was said (time.monotonic())
        self.health = {s: SensorHealth(s) for s in sensors}
        self.events: deque[HealthEvent] = deque(maxlen=EVENTS_KEPT)
        self.latencies_ms: deque[float] = deque(maxlen=LATENCIES_KEPT)  # the newest, one by one
        self.latency_hist = LogHistogram()  # every scan's latency, the whole run (the summary's percentiles)
        self.trajectory = TrajectoryBuffer(trajectory_window_s)  # the live trajectory (-o)
        self.counters: dict[str, int] = {"scans_fused": 0, "scans_skipped_backlog": 0, "fixes": 0,
                                         "poses_dead_reckoned": 0,  # while the laser is silent
                                         "record_errors": 0, "localizer_errors": 0,
                                         "queue_max": 0,  # the most messages seen waiting (a host too slow)
                                         "queue_dropped": 0}  # the oldest dropped from the full queue
        self.sources: dict[str, Callable[[], dict[str, Any]]] = {}  # name -> counters getter
        self._pending_scans = 0
        self._lock = threading.Lock()
        self.stop_event = threading.Event()
        self._last_status = 0.0
        self._last_trim = time.monotonic()
        self._last_pub_status = 0.0
        self._recorded_tf = False
        self.last_fix: PoseFix | None = None
        self.reorder_s = reorder_s
        self._reorder: list[tuple[float, int, str, Any]] = []
        self._seq = 0
        self.scan_arrival = 0.0  # host arrival time of the scan being fused (for its latency)
        self._last_arrival = 0.0  # host arrival time of the last message processed
        self.last_latency_ms = float("nan")
        self._rec_sink = RecorderSink(recorder, self.topics["fused"], tolerate=(Exception,)) \
            if recorder is not None else None
        out: list[Any] = [_LiveTrack(self)]
        if self._rec_sink is not None:
            out.append(self._rec_sink)
        if publisher is not None:
            out.append(UdpSink(publisher, lambda: self.last_latency_ms, close_publisher=False))
        self.session = session
        for sink in out + list(sinks or []):
            session.add_sink(sink)

    # ---------------------------------------------------------------- producer side
    def push(self, kind: str, msg: Any, arrival: float) -> None:
        """Thread-safe: called by the sensor threads.  Never blocks: when the queue is full its
        oldest message is dropped and counted (``queue_dropped``, by kind in :attr:`dropped`)."""
        with self._lock:
            if kind == "scan":
                self._pending_scans += 1
            while True:
                try:
                    self.q.put_nowait((kind, msg, arrival))
                    return
                except queue.Full:
                    pass
                try:
                    old_kind, _, _ = self.q.get_nowait()
                except queue.Empty:  # the fusion loop took one meanwhile
                    continue
                if old_kind == "scan":
                    self._pending_scans -= 1
                self.counters["queue_dropped"] += 1
                self.dropped[old_kind] = self.dropped.get(old_kind, 0) + 1

    # ---------------------------------------------------------------- consumer side
    def _record(self, topic: str, msg: Any, stamp: float) -> None:
        if self.recorder is None:
            return
        try:
            self.recorder.write(topic, msg, stamp)
        except Exception:  # noqa: BLE001 - a recorder failure must not stop localization
            self.counters["record_errors"] += 1

    def _record_event(self, text: str, t_host: float) -> None:
        if self.recorder is None or not hasattr(self.recorder, "write_raw"):
            return
        try:
            self.recorder.write_raw(self.topics["event"], "std_msgs/msg/String", b"string data\n", string_cdr(text),
                                    max(int(round(t_host * 1e9)), 0))
        except Exception:  # noqa: BLE001 - a recorder failure must not stop localization
            self.counters["record_errors"] += 1

    def _sync_record_errors(self) -> None:
        if self._rec_sink is not None:
            self.counters["record_errors"] += self._rec_sink.errors
            self._rec_sink.errors = 0

    def _mark(self, kind: str, now: float) -> None:
        h = self.health.get(kind)
        if h is None:
            return
        if h.state == "silent":
            gap = now - h.last_arrival
            self.events.append(HealthEvent(now, kind, "back", gap))
            self.event_sink(f"{kind}: back after {gap:.2f} s silent")
        h.state = "ok"
        h.count += 1
        h.last_arrival = now
        h.arrivals.append(now)

    def check_health(self, now: float | None = None) -> None:
        now = time.monotonic() if now is None else now
        for h in self.health.values():
            if h.state == "ok" and now - h.last_arrival > self.silence_s:
                h.state = "silent"
                h.silent_since = now
                self.events.append(HealthEvent(now, h.name, "silent", now - h.last_arrival))
                self.event_sink(f"{h.name}: SILENT (no message for {now - h.last_arrival:.2f} s)")

    def process(self, kind: str, msg: Any, arrival: float) -> None:
        """Ingest one message: health, recording, then fusion in stamp order.

        Odometry and compass messages wait in a small reorder buffer; a scan first
        releases every buffered message stamped before it, then is fused at once, so
        the localizer sees the same time order as ``fgloc run`` on the recording while
        scan latency is unaffected.  Buffered messages older than ``reorder_s`` (host
        clock) are released by :meth:`flush_reorder`.
        """
        if kind == "event":
            self._record_event(str(msg), arrival)
            return
        self._last_arrival = arrival
        now = time.monotonic()
        self._mark(kind, now)
        stamp = float(getattr(msg, "stamp", arrival))
        if self.recorder is not None and not self._recorded_tf and self.laser_mount is not None:
            self._record(self.topics["tf_static"], [self.laser_mount], stamp)
            self._recorded_tf = True
        self.session.observe(self.topics[kind], msg)
        self._sync_record_errors()
        if kind == "scan":
            with self._lock:
                self._pending_scans -= 1
                backlog = self._pending_scans
            self._release(lambda s: s <= stamp)
            if backlog > 0:
                # a newer scan is already queued: fusing this one would only add latency
                self.counters["scans_skipped_backlog"] += 1
                return
            self._fuse_scan(msg, arrival)
        else:
            self._seq += 1
            heapq.heappush(self._reorder, (stamp, self._seq, kind, msg))

    def _release(self, cond: Callable[[float], bool]) -> None:
        while self._reorder and cond(self._reorder[0][0]):
            _, _, kind, msg = heapq.heappop(self._reorder)
            try:
                self.session.dispatch(kind, msg)
            except Exception as e:  # noqa: BLE001 - keep running on a bad message, but count it
                self._loc_error(kind, e)

    def flush_reorder(self, all_: bool = False) -> None:
        # the horizon runs on the messages' arrival while a backlog is queued (a busy host releases
        # odometry in the order an idle one would: never ahead of a scan still in the queue), on the
        # host clock once the queue is empty (a silent laser does not hold odometry back)
        now = time.time() if self.q.empty() else self._last_arrival
        horizon = now - self.reorder_s
        self._release((lambda s: True) if all_ else (lambda s: s < horizon))

    def _loc_error(self, kind: str, e: Exception) -> None:
        self.counters["localizer_errors"] += 1
        if self.counters["localizer_errors"] <= 3:
            self.event_sink(f"localizer error on {kind}: {type(e).__name__}: {e}")

    def _fuse_scan(self, msg: LaserScan, arrival: float) -> None:
        self.scan_arrival = arrival
        try:
            self.session.dispatch("scan", msg)
        except Exception as e:  # noqa: BLE001
            self._loc_error("scan", e)
        self._sync_record_errors()

    @property
    def live_stamps(self) -> np.ndarray:
        """The live trajectory's stamps (a view: copy to keep)."""
        return self.trajectory.stamps

    @property
    def live_poses(self) -> np.ndarray:
        return self.trajectory.poses

    def live_trajectory(self) -> Trajectory:
        return Trajectory(self.live_stamps.copy(), self.live_poses.copy())

    def health_states(self) -> dict[str, str]:
        return {k: h.state for k, h in self.health.items()}

    def all_counters(self) -> dict[str, Any]:
        out: dict[str, Any] = dict(self.counters)
        out["queue_dropped_by_kind"] = dict(self.dropped)
        for name, get in self.sources.items():
            try:
                out[name] = get()
            except Exception:  # noqa: BLE001
                out[name] = {}
        stats = getattr(self.loc, "stats", None)
        if isinstance(stats, dict):
            out["localizer"] = dict(stats)
        return out

    def add_latency(self, ms: float) -> None:
        """One fused scan's latency (arrival -> fused pose), in ms."""
        self.last_latency_ms = ms
        self.latencies_ms.append(ms)
        self.latency_hist.add(ms)

    def latency_percentiles(self, last: int | None = None) -> tuple[float, float]:
        """p50 and p99 of the latency in ms: of the newest ``last`` scans (at most :data:`LATENCIES_KEPT`),
        else of the whole run (a log histogram: within 0.6 %, in constant memory)."""
        if not last:
            p50, p99 = self.latency_hist.percentiles(50, 99)
            return p50, p99
        if not self.latencies_ms:
            return float("nan"), float("nan")
        a = np.fromiter(self.latencies_ms, dtype=float, count=len(self.latencies_ms))[-last:]
        return float(np.percentile(a, 50)), float(np.percentile(a, 99))

    def status_line(self) -> str:
        now = time.monotonic()
        parts = []
        for k, h in self.health.items():
            mark = {"ok": "", "waiting": "?", "silent": "!SILENT"}[h.state]
            parts.append(f"{k} {h.rate_hz(now):5.1f}Hz{mark}")
        p50, p99 = self.latency_percentiles(last=200)
        pose = "pose --"
        if self.last_fix is not None:
            x, y, yaw = self.last_fix.pose
            pose = f"pose {x:7.2f} {y:7.2f} {np.degrees(yaw):6.1f}deg {self.last_fix.status or '?'}"
        c = self.all_counters()
        ser = c.get("serial", {})
        las = c.get("laser", {})
        err = (f"ser crc {ser.get('crc_errors', 0)} len {ser.get('length_errors', 0)} "
               f"junk {ser.get('garbage_bytes', 0)}B drop {ser.get('dropped', 0)} | "
               f"las bad {las.get('malformed', 0)} reconn {las.get('disconnects', 0)}")
        steps = ser.get("clock_steps", 0) + las.get("clock_steps", 0)
        if steps:  # a device clock that stepped (re-anchored; the events say by how much)
            err += f" | clock steps ser {ser.get('clock_steps', 0)} las {las.get('clock_steps', 0)}"
        skipped = las.get("other_layer", 0) + las.get("unsupported_device", 0)
        if skipped:  # scans of other layers (MRS1000) or of a clockwise device: said, not hidden
            err += f" skip {skipped}"
        from fgloc.localization.sources import status_line

        router = getattr(self.session, "sources", None)
        health = f" | {status_line(router.health())}" if router is not None else ""  # per source
        n_drop = self.counters["queue_dropped"]
        dropped = f" QUEUE FULL dropped {n_drop}" if n_drop else ""  # a host too slow for its input
        return (f"{' | '.join(parts)} | lat p50 {p50:4.1f} p99 {p99:4.1f} ms | {pose} | "
                f"fixes {self.counters['fixes']} skip {self.counters['scans_skipped_backlog']}{dropped} | "
                f"{err}{health}")

    def _tell_drops(self, now: float) -> None:
        """An event line when the full queue dropped messages (at most one every 10 s)."""
        n = self.counters["queue_dropped"]
        if n > self._dropped_told and now - self._drop_event_t >= 10.0:
            by_kind = ", ".join(f"{k} {v}" for k, v in sorted(self.dropped.items()))
            self.event_sink(f"input queue full ({self.q.maxsize} messages): {n - self._dropped_told} oldest "
                            f"dropped ({n} in all: {by_kind}); the host is too slow for the input")
            self._dropped_told, self._drop_event_t = n, now

    def step(self, timeout: float = 0.02) -> bool:
        """Process queued messages (up to ~50 ms worth); returns False if nothing came."""
        got = False
        t_end = time.monotonic() + 0.05
        self.counters["queue_max"] = max(self.counters["queue_max"], self.q.qsize())
        self._tell_drops(time.monotonic())
        while True:
            try:
                kind, msg, arrival = self.q.get(timeout=timeout if not got else 0.0)
            except queue.Empty:
                break
            got = True
            self.process(kind, msg, arrival)
            if time.monotonic() > t_end:
                break
        self.flush_reorder()
        self.check_health()
        now = time.monotonic()
        if now - self._last_trim >= TRIM_PERIOD_S:
            self._last_trim = now
            if memory.trim():  # its cost in the fusion loop: total and longest (us)
                us = int((time.monotonic() - now) * 1e6)
                c = self.counters
                c["malloc_trims"] = c.get("malloc_trims", 0) + 1
                c["malloc_trim_us"] = c.get("malloc_trim_us", 0) + us
                c["malloc_trim_us_max"] = max(c.get("malloc_trim_us_max", 0), us)
        if self.status_sink is not None and now - self._last_status >= self.status_period_s:
            self._last_status = now
            self.status_sink(self.status_line())
        if self.publisher is not None and now - self._last_pub_status >= 1.0:
            self._last_pub_status = now
            self.publisher.status(time.time(), self.health_states(), self.all_counters())
        return got

    def run(self, duration: float | None = None, until: Callable[[], bool] | None = None) -> None:
        """Loop until ``stop_event`` is set, ``duration`` passed or ``until()`` is true."""
        t0 = time.monotonic()
        while not self.stop_event.is_set():
            self.step()
            if duration is not None and time.monotonic() - t0 >= duration:
                break
            if until is not None and until():
                break

    def drain(self) -> None:
        """Process whatever is still queued (at shutdown)."""
        while True:
            try:
                kind, msg, arrival = self.q.get_nowait()
            except queue.Empty:
                break
            self.process(kind, msg, arrival)
        self.flush_reorder(all_=True)
