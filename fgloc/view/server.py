"""The live view: a Foxglove WebSocket server (foxglove-sdk) fed without blocking the localizer.

:class:`FoxgloveServerSink` is a :class:`fgloc.view.feed.ViewSink`.  Its ``on_*`` methods
run on the localizer's thread and only put a reference into a bounded queue
(``put_nowait``: when the queue is full the item is dropped and counted, never waited
for); a publisher thread encodes the Foxglove messages and logs them to the server.
The SDK keeps a bounded outbox per client and drops the oldest data when a viewer
does not read (reported in ``stats['client_outbox_full']``), so neither a slow nor a
stalled nor a vanished viewer can hold the localizer up.

The map is not queued: it is encoded once and sent again to every client that
subscribes to it (a viewer that connects mid-run gets the map).

The server speaks the SDK's WebSocket protocol (subprotocol ``foxglove.sdk.v1``):
Foxglove (app or desktop) -> Open connection -> Foxglove WebSocket -> ``ws://HOST:PORT``.
It binds 127.0.0.1 unless told otherwise (``--view 0.0.0.0:8765`` to serve the network).
"""

from __future__ import annotations

import logging
import math
import queue
import threading
import time
from typing import Any

import numpy as np

from fgloc.errors import ConfigError, FglocError
from fgloc.io.log import stamp_to_ns
from fgloc.types import PoseFix
from fgloc.view import channels as ch
from fgloc.view.feed import ACCEPTED, REJECTED, ScanView, json_ready

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8765
STOP_TIMEOUT_S = 2.0
INSTALL_HINT = 'the Foxglove view needs foxglove-sdk: pip install "fgloc[view]"'


class ViewUnavailableError(FglocError):
    """foxglove-sdk is not installed."""


def require_foxglove() -> Any:
    """Import foxglove-sdk or raise a one-line hint (``pip install "fgloc[view]"``)."""
    try:
        import foxglove
        from foxglove import channels as _channels  # noqa: F401
    except ImportError:
        raise ViewUnavailableError(INSTALL_HINT) from None
    return foxglove


def parse_view_address(text: str | None, option: str = "--view") -> tuple[str, int]:
    """``[HOST:]PORT`` -> ``(host, port)``; empty -> 127.0.0.1:8765; IPv6 as ``[::1]:8765``."""
    s = (text or "").strip()
    if not s:
        return DEFAULT_HOST, DEFAULT_PORT
    host, port_s = DEFAULT_HOST, s
    if s.startswith("["):
        end = s.find("]")
        if end < 0 or not s[end + 1:].startswith(":"):
            raise ConfigError(f"{option} {text}: expected [HOST:]PORT, e.g. 8765 or 127.0.0.1:8765 or [::1]:8765")
        host, port_s = s[1:end], s[end + 2:]
    elif ":" in s:
        host, _, port_s = s.rpartition(":")
        if ":" in host:
            raise ConfigError(f"{option} {text}: write an IPv6 host in brackets, e.g. [::1]:8765")
    if not host or not port_s.isdigit() or not 0 <= int(port_s) <= 65535:
        raise ConfigError(f"{option} {text}: expected [HOST:]PORT with a port 0..65535, e.g. 8765 or 127.0.0.1:8765")
    return host, int(port_s)


class _SdkLogCounter(logging.Handler):
    """Counts the SDK's own reports (a client's outbox full, a client gone) instead of
    letting them reach the terminal as tracebacks or ERROR lines."""

    def __init__(self, stats: dict[str, int]) -> None:
        super().__init__(level=logging.DEBUG)
        self.stats = stats

    def emit(self, record: logging.LogRecord) -> None:
        msg = record.getMessage()
        if "outbox" in msg and "full" in msg:
            self.stats["client_outbox_full"] += 1
        elif "Registered client" in msg:
            self.stats["clients_connected"] += 1
        elif "Unregistered client" in msg:
            self.stats["clients_disconnected"] += 1
        elif record.levelno >= logging.ERROR:
            self.stats["client_errors"] += 1


_STOP = object()


class FoxgloveServerSink:
    """A Foxglove WebSocket server publishing the view channels (see the module docstring).

    ``queue_size`` bounds what waits for the publisher thread (items, about 4 per scan);
    ``backlog`` bounds each client's outbox in the SDK (messages).
    """

    def __init__(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, name: str = "fgloc",
                 queue_size: int = 256, backlog: int = 256, max_rate_hz: float = 30.0) -> None:
        foxglove = require_foxglove()
        from foxglove import channels as fch
        from foxglove.websocket import Capability, ServerListener

        from fgloc.view import encode

        self._enc = encode
        self.stats: dict[str, int] = {"queued": 0, "published": 0, "dropped": 0, "encode_errors": 0,
                                      "map_sent": 0, "client_outbox_full": 0, "clients_connected": 0,
                                      "clients_disconnected": 0, "client_errors": 0, "subscriptions": 0,
                                      "thinned": 0, "stop_timed_out": 0}
        self._queue: queue.Queue[Any] = queue.Queue(maxsize=max(1, int(queue_size)))
        self._map_msg: Any = None
        self._map_wanted = threading.Event()
        self._map_lock = threading.Lock()
        self._closed = False
        self._last_ns = 0
        self._min_period_s = 1.0 / max_rate_hz if max_rate_hz > 0 else 0.0
        self._last_scan_t = -math.inf
        self._scan_sent = False
        self.ctx = foxglove.Context()
        c = self.ctx
        self.ch_map = fch.GridChannel(ch.MAP, context=c)
        self.ch_scan = fch.LaserScanChannel(ch.SCAN, context=c)
        self.ch_tf = fch.FrameTransformsChannel(ch.TF, context=c)
        self.ch_pose = fch.PoseInFrameChannel(ch.POSE, context=c)
        self.ch_cov = fch.SceneUpdateChannel(ch.POSE_COVARIANCE, context=c)
        self.ch_fix_ok = fch.PoseInFrameChannel(ch.FIX_ACCEPTED, context=c)
        self.ch_fix_bad = fch.PoseInFrameChannel(ch.FIX_REJECTED, context=c)
        self.ch_particles = fch.PosesInFrameChannel(ch.PARTICLES, context=c)
        self.ch_traj = fch.PosesInFrameChannel(ch.TRAJECTORY, context=c)
        self.ch_fused = foxglove.Channel(ch.FUSED, schema=encode.FUSED_SCHEMA, context=c)
        self.ch_fix = foxglove.Channel(ch.FIX, schema=encode.FIX_SCHEMA, context=c)
        self.ch_health = foxglove.Channel(ch.HEALTH, schema=encode.HEALTH_SCHEMA, context=c)
        map_id = self.ch_map.id()
        sink = self

        class _Listener(ServerListener):
            def on_subscribe(self, client: Any, channel: Any) -> None:
                sink.stats["subscriptions"] += 1
                if channel.id == map_id:
                    sink._map_wanted.set()
                    sink._wake()

        self._sdk_log = logging.getLogger("foxglove")
        self._log_handler = _SdkLogCounter(self.stats)
        self._old_log = (self._sdk_log.level, self._sdk_log.propagate)
        self._sdk_log.addHandler(self._log_handler)
        self._sdk_log.setLevel(logging.INFO)
        self._sdk_log.propagate = False
        try:
            self.server = foxglove.start_server(name=name, host=host, port=int(port), context=c,
                                                capabilities=[Capability.Time], server_listener=_Listener(),
                                                message_backlog_size=int(backlog))
        except RuntimeError as e:
            self._restore_logging()
            why = str(e).split("Failed to bind port:")[-1].strip() or str(e)
            raise ConfigError(f"--view {_fmt(host, port)}: cannot serve the Foxglove view: {why}") from None
        self.host = host
        self.port = int(self.server.port)
        self._thread = threading.Thread(target=self._run, name="fgloc-view", daemon=True)
        self._thread.start()

    @property
    def url(self) -> str:
        return f"ws://{_fmt(self.host, self.port)}"

    # ------------------------------------------------------------------ ViewSink (localizer thread)
    def _put(self, item: Any) -> None:
        if self._closed:
            return
        try:
            self._queue.put_nowait(item)
            self.stats["queued"] += 1
        except queue.Full:
            self.stats["dropped"] += 1

    def _wake(self) -> None:
        try:
            self._queue.put_nowait(None)
        except queue.Full:
            pass  # the thread is busy anyway and checks the flag after each item

    def on_map(self, occ_map: Any, stamp: float) -> None:
        msg = self._enc.grid_message(occ_map, stamp)
        with self._map_lock:
            self._map_msg = msg
        self._map_wanted.set()
        self._wake()

    def wants_scan(self) -> bool:
        """At most ``max_rate_hz`` scans a second (wall clock) reach the viewer: a replay as fast as
        possible would otherwise spend the localizer's time on frames nobody can see."""
        now = time.monotonic()
        self._scan_sent = now - self._last_scan_t >= self._min_period_s and not self._closed
        if self._scan_sent:
            self._last_scan_t = now
        else:
            self.stats["thinned"] += 1
        return self._scan_sent

    def on_scan(self, view: ScanView) -> None:
        self._put(("scan", view))

    def on_particles(self, stamp: float, frame_id: str, poses: np.ndarray) -> None:
        if self._scan_sent:  # with the scan they belong to
            self._put(("poses", self.ch_particles, stamp, frame_id, poses))

    def on_trajectory(self, stamp: float, frame_id: str, poses: np.ndarray) -> None:
        self._put(("poses", self.ch_traj, stamp, frame_id, poses))

    def on_health(self, stamp: float, health: dict[str, Any]) -> None:
        self._put(("health", stamp, health))

    def close(self) -> None:
        """Publish what is queued (up to 2 s), stop the thread and the server; idempotent."""
        if self._closed:
            return
        self._closed = True
        deadline = time.monotonic() + 2.0
        while True:
            try:
                self._queue.put(_STOP, timeout=0.1)
                break
            except queue.Full:
                if time.monotonic() > deadline:
                    break
        self._thread.join(timeout=max(0.1, deadline - time.monotonic()))
        # the SDK's stop() waits for every client's outbox to drain: a viewer that stopped
        # reading would hold it (and Ctrl-C) forever, so it gets STOP_TIMEOUT_S and is left behind
        stopper = threading.Thread(target=self.server.stop, name="fgloc-view-stop", daemon=True)
        stopper.start()
        stopper.join(STOP_TIMEOUT_S)
        if stopper.is_alive():
            self.stats["stop_timed_out"] = 1
        else:
            self._restore_logging()

    def __enter__(self) -> FoxgloveServerSink:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _restore_logging(self) -> None:
        self._sdk_log.removeHandler(self._log_handler)
        self._sdk_log.setLevel(self._old_log[0])
        self._sdk_log.propagate = self._old_log[1]

    # ------------------------------------------------------------------ publisher thread
    def _run(self) -> None:
        while True:
            item = self._queue.get()
            if self._map_wanted.is_set():
                self._map_wanted.clear()
                self._send_map()
            if item is _STOP:
                return
            if item is None:
                continue
            try:
                self._publish(item)
                self.stats["published"] += 1
            except Exception:  # noqa: BLE001 - a bad item must not kill the view thread
                self.stats["encode_errors"] += 1

    def _send_map(self) -> None:
        with self._map_lock:
            msg = self._map_msg
        if msg is not None:
            self.ch_map.log(msg, log_time=self._last_ns)
            self.stats["map_sent"] += 1

    def _publish(self, item: tuple[Any, ...]) -> None:
        enc = self._enc
        kind = item[0]
        if kind == "scan":
            v: ScanView = item[1]
            t = self._time(v.stamp)
            if self.ch_scan.has_sinks():
                self.ch_scan.log(enc.scan_message(v.scan), log_time=t)
            if v.transforms and self.ch_tf.has_sinks():
                st = v.fused.stamp if v.fused is not None else v.stamp
                self.ch_tf.log(enc.transforms_message(v.transforms, st), log_time=t)
            if v.fused is not None:
                self._fused(v.fused, t)
            if self.ch_fix.has_sinks():
                self.ch_fix.log(enc.fix_json(v.stamp, v.status, v.reason, v.fix, v.fused), log_time=t)
            if v.fix is not None and v.status in (ACCEPTED, REJECTED):
                c = self.ch_fix_ok if v.status == ACCEPTED else self.ch_fix_bad
                if c.has_sinks():
                    c.log(enc.pose_message(v.fix), log_time=t)
        elif kind == "poses":
            _, chan, stamp, frame_id, poses = item
            t = self._time(stamp)
            if chan.has_sinks():
                chan.log(enc.poses_message(stamp, frame_id, poses), log_time=t)
        elif kind == "health":
            _, stamp, health = item
            t = self._time(stamp)
            if self.ch_health.has_sinks():
                self.ch_health.log(json_ready({**health, "view": dict(self.stats)}), log_time=t)

    def _time(self, stamp: float) -> int:
        """Log time of a message = its stamp (ns); the viewer's clock follows the log's time."""
        ns = stamp_to_ns(stamp) if math.isfinite(stamp) and stamp >= 0 else self._last_ns
        if ns > self._last_ns:
            self._last_ns = ns
            self.server.broadcast_time(ns)
        return ns

    def _fused(self, fused: PoseFix, t: int) -> None:
        enc = self._enc
        if self.ch_pose.has_sinks():
            self.ch_pose.log(enc.pose_message(fused), log_time=t)
        if self.ch_cov.has_sinks():
            self.ch_cov.log(enc.covariance_scene(fused), log_time=t)
        if self.ch_fused.has_sinks():
            self.ch_fused.log(enc.fused_json(fused), log_time=t)


def _fmt(host: str, port: int) -> str:
    return f"[{host}]:{port}" if ":" in host else f"{host}:{port}"
