"""The view's server process: ``python -m fgloc.view.serve --host H --port P`` (started by
:class:`fgloc.view.server.FoxgloveServerSink`, not by users).

It owns the Foxglove WebSocket server (foxglove-sdk) and does all the encoding, so none of
it competes with the localizer for the parent's interpreter lock.  Input, on stdin: frames
``<uint32 little-endian length><pickle>`` of ``("map", data, resolution, origin, stamp)``,
``("scan", ScanView)``, ``("poses", "particles" | "trajectory", stamp, frame_id, poses)``,
``("health", stamp, dict)``, ``("close",)``; end of stdin is a close too.  Output, on stdout,
JSON lines: ``{"ready": port}`` or ``{"error": "..."}`` first, ``{"subscriptions": n}`` as
viewers subscribe, ``{"stats": {...}}`` last.  SIGINT is ignored (the parent decides when
to stop: Ctrl-C must not kill the view before the run has closed it).
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
import pickle
import select
import signal
import struct
import sys
import threading
from types import SimpleNamespace
from typing import Any

from fgloc.io.ros import stamp_to_ns
from fgloc.view import channels as ch
from fgloc.view.feed import ACCEPTED, REJECTED, ScanView, json_ready

STOP_TIMEOUT_S = 2.0
FRAME = struct.Struct("<I")


class _SdkLogCounter(logging.Handler):
    """Counts the SDK's own reports (a client's outbox full, clients coming and going)."""

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


class Publisher:
    """The Foxglove server and its channels; ``handle(item)`` encodes and logs one item."""

    def __init__(self, host: str, port: int, name: str = "fgloc", backlog: int = 256) -> None:
        import foxglove
        from foxglove import channels as fch
        from foxglove import messages as fm
        from foxglove.websocket import Capability, ServerListener

        from fgloc.view import encode, wire

        self.enc = encode
        self.wire = wire
        self.stats: dict[str, int] = {"published": 0, "encode_errors": 0, "map_sent": 0, "client_outbox_full": 0,
                                      "clients_connected": 0, "clients_disconnected": 0, "client_errors": 0,
                                      "subscriptions": 0, "stop_timed_out": 0}
        log = logging.getLogger("foxglove")
        log.addHandler(_SdkLogCounter(self.stats))
        log.setLevel(logging.INFO)
        log.propagate = False
        self.map_msg: Any = None
        self.map_wanted = threading.Event()
        self.last_ns = 0
        c = self.ctx = foxglove.Context()
        self.ch_map = fch.GridChannel(ch.MAP, context=c)
        # the scan's protobuf bytes written from the array (fgloc.view.wire), the SDK's schema
        self.ch_scan = foxglove.Channel(ch.SCAN, schema=fm.LaserScan.get_schema(), message_encoding="protobuf",
                                        context=c)
        self.ch_tf = fch.FrameTransformsChannel(ch.TF, context=c)
        self.ch_pose = fch.PoseInFrameChannel(ch.POSE, context=c)
        self.ch_cov = fch.SceneUpdateChannel(ch.POSE_COVARIANCE, context=c)
        self.ch_fix_ok = fch.PoseInFrameChannel(ch.FIX_ACCEPTED, context=c)
        self.ch_fix_bad = fch.PoseInFrameChannel(ch.FIX_REJECTED, context=c)
        self.ch_poses = {"particles": fch.PosesInFrameChannel(ch.PARTICLES, context=c),
                         "trajectory": fch.PosesInFrameChannel(ch.TRAJECTORY, context=c)}
        self.ch_fused = foxglove.Channel(ch.FUSED, schema=encode.FUSED_SCHEMA, context=c)
        self.ch_fix = foxglove.Channel(ch.FIX, schema=encode.FIX_SCHEMA, context=c)
        self.ch_health = foxglove.Channel(ch.HEALTH, schema=encode.HEALTH_SCHEMA, context=c)
        map_id = self.ch_map.id()
        pub = self

        class _Listener(ServerListener):
            def on_subscribe(self, client: Any, channel: Any) -> None:
                pub.stats["subscriptions"] += 1
                if channel.id == map_id:
                    pub.map_wanted.set()

        self.server = foxglove.start_server(name=name, host=host, port=int(port), context=c,
                                            capabilities=[Capability.Time], server_listener=_Listener(),
                                            message_backlog_size=int(backlog))
        self.port = int(self.server.port)

    def _time(self, stamp: float) -> int:
        """Log time of a message = its stamp (ns); the viewer's clock follows the log's time."""
        ns = stamp_to_ns(stamp) if math.isfinite(stamp) and stamp >= 0 else self.last_ns
        if ns > self.last_ns:
            self.last_ns = ns
            self.server.broadcast_time(ns)
        return ns

    def send_map(self) -> None:
        self.map_wanted.clear()
        if self.map_msg is not None:
            self.ch_map.log(self.map_msg, log_time=self.last_ns)
            self.stats["map_sent"] += 1

    def handle(self, item: tuple[Any, ...]) -> None:
        try:
            self._handle(item)
            self.stats["published"] += 1
        except Exception:  # noqa: BLE001 - a bad item must not stop the view
            self.stats["encode_errors"] += 1

    def _handle(self, item: tuple[Any, ...]) -> None:
        enc = self.enc
        kind = item[0]
        if kind == "map":
            _, data, resolution, origin, stamp = item
            self.map_msg = enc.grid_message(SimpleNamespace(data=data, resolution=resolution, origin=origin), stamp)
            self.send_map()
        elif kind == "scan":
            v: ScanView = item[1]
            t = self._time(v.stamp)
            if self.ch_scan.has_sinks():
                self.ch_scan.log(self.wire.laser_scan(v.scan), log_time=t)
            if v.transforms and self.ch_tf.has_sinks():
                st = v.fused.stamp if v.fused is not None else v.stamp
                self.ch_tf.log(enc.transforms_message(v.transforms, st), log_time=t)
            if v.fused is not None:
                if self.ch_pose.has_sinks():
                    self.ch_pose.log(enc.pose_message(v.fused), log_time=t)
                if self.ch_cov.has_sinks():
                    self.ch_cov.log(enc.covariance_scene(v.fused), log_time=t)
                if self.ch_fused.has_sinks():
                    self.ch_fused.log(enc.fused_json(v.fused), log_time=t)
            if self.ch_fix.has_sinks():
                self.ch_fix.log(enc.fix_json(v.stamp, v.status, v.reason, v.fix, v.fused), log_time=t)
            if v.fix is not None and v.status in (ACCEPTED, REJECTED):
                c = self.ch_fix_ok if v.status == ACCEPTED else self.ch_fix_bad
                if c.has_sinks():
                    c.log(enc.pose_message(v.fix), log_time=t)
        elif kind == "poses":
            _, which, stamp, frame_id, poses = item
            chan = self.ch_poses[which]
            t = self._time(stamp)
            if chan.has_sinks():
                chan.log(enc.poses_message(stamp, frame_id, poses), log_time=t)
        elif kind == "health":
            _, stamp, health = item
            t = self._time(stamp)
            if self.ch_health.has_sinks():
                view = {**health.pop("view", {}), **self.stats}
                self.ch_health.log(json_ready({**health, "view": view}), log_time=t)

    def stop(self) -> None:
        """Stop the server; the SDK waits for every client's outbox to drain, so a viewer that
        stopped reading would hold this forever: it gets STOP_TIMEOUT_S and is left behind."""
        stopper = threading.Thread(target=self.server.stop, name="fgloc-view-stop", daemon=True)
        stopper.start()
        stopper.join(STOP_TIMEOUT_S)
        if stopper.is_alive():
            self.stats["stop_timed_out"] = 1


def _emit(obj: dict[str, Any]) -> None:
    try:
        sys.stdout.write(json.dumps(obj) + "\n")
        sys.stdout.flush()
    except (OSError, ValueError):  # the parent is gone: nothing to tell
        pass


def serve(host: str, port: int, name: str, backlog: int) -> int:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        pub = Publisher(host, port, name, backlog)
    except RuntimeError as e:
        why = str(e).split("Failed to bind port:")[-1].strip() or str(e)
        _emit({"error": why})
        return 2
    _emit({"ready": pub.port})
    fd = sys.stdin.buffer.fileno()
    buf = bytearray()
    told = 0
    running = True
    while running:
        readable, _, _ = select.select([fd], [], [], 0.1)
        if pub.map_wanted.is_set():
            pub.send_map()
        if pub.stats["subscriptions"] != told:
            told = pub.stats["subscriptions"]
            _emit({"subscriptions": told})
        if not readable:
            continue
        chunk = os.read(fd, 1 << 20)
        if not chunk:
            break
        buf += chunk
        while len(buf) >= FRAME.size:
            (n,) = FRAME.unpack_from(buf, 0)
            if len(buf) < FRAME.size + n:
                break
            item = pickle.loads(bytes(buf[FRAME.size:FRAME.size + n]))
            del buf[:FRAME.size + n]
            if item[0] == "close":
                running = False
                break
            pub.handle(item)
    pub.stop()
    _emit({"stats": pub.stats})
    return 0


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--host", required=True)
    ap.add_argument("--port", type=int, required=True)
    ap.add_argument("--name", default="fgloc")
    ap.add_argument("--backlog", type=int, default=256)
    a = ap.parse_args(argv)
    code = serve(a.host, a.port, a.name, a.backlog)
    sys.stdout.flush()
    os._exit(code)  # a server thread stuck on a stalled viewer must not hold the exit


if __name__ == "__main__":
    main()
