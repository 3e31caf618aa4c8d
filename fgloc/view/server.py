"""The live view: a Foxglove WebSocket server (foxglove-sdk) fed without slowing the localizer.

:class:`FoxgloveServerSink` is a :class:`fgloc.view.feed.ViewSink`.  The server and all the
encoding live in a process of their own (:mod:`fgloc.view.serve`): a publisher *thread*
would share the interpreter lock with the localizer, and on a busy machine every hand-over
of that lock costs the localizer a scheduling delay.  On the localizer's thread an
``on_*`` call pickles a small snapshot and writes it to the server process's stdin without
blocking (``O_NONBLOCK``); what the pipe cannot take waits in a bounded buffer, and when
that is full the item is dropped and counted (``stats['dropped']``), never waited for.  At
most ``max_rate_hz`` scans a second (wall clock) are sent at all (``stats['thinned']``): a
replay as fast as possible would otherwise spend time on frames nobody can see.  The SDK
keeps a bounded outbox per client and drops the oldest data when a viewer does not read
(``stats['client_outbox_full']``), so neither a slow nor a stalled nor a vanished viewer
can hold the localizer up.

The map is sent once, kept by the server process and sent again to every client that
subscribes to it (a viewer that connects mid-run gets the map).

The server speaks the SDK's WebSocket protocol (subprotocol ``foxglove.sdk.v1``):
Foxglove (app or desktop) -> Open connection -> Foxglove WebSocket -> ``ws://HOST:PORT``.
It binds 127.0.0.1 unless told otherwise (``--view 0.0.0.0:8765`` to serve the network).
"""

from __future__ import annotations

import fcntl
import importlib.util
import json
import math
import os
import pickle
import select
import subprocess
import sys
import time
from typing import Any

import numpy as np

from fgloc.errors import ConfigError, FglocError
from fgloc.view.feed import PREDICTED, ScanView

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8765
STARTUP_TIMEOUT_S = 60.0
CLOSE_TIMEOUT_S = 5.0
PIPE_SIZE = 1 << 20
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


def foxglove_installed() -> bool:
    """foxglove-sdk importable (checked without importing it into this process)."""
    if "foxglove" in sys.modules:
        return sys.modules["foxglove"] is not None  # None: blocked (tests, embedders)
    try:
        return importlib.util.find_spec("foxglove") is not None
    except (ImportError, ValueError):
        return False


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


class FoxgloveServerSink:
    """The Foxglove WebSocket view (see the module docstring); a context manager.

    ``buffer_bytes`` bounds what waits for the server process beyond the pipe's own 1 MB;
    ``backlog`` bounds each client's outbox in the SDK (messages); ``max_rate_hz`` the scans
    sent per second of wall time (0: all).
    """

    def __init__(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, name: str = "fgloc",
                 buffer_bytes: int = 8 << 20, backlog: int = 256, max_rate_hz: float = 30.0) -> None:
        if not foxglove_installed():
            raise ViewUnavailableError(INSTALL_HINT)
        self.host = host
        self.stats: dict[str, Any] = {"queued": 0, "dropped": 0, "thinned": 0, "subscriptions": 0,
                                      "server_process_lost": 0}
        self.buffer_bytes = int(buffer_bytes)
        self._pending = bytearray()
        self._closed = False
        self._min_period_s = 1.0 / max_rate_hz if max_rate_hz > 0 else 0.0
        self._last_scan_t = -math.inf
        self._last_matched_t = -math.inf
        self._scan_sent = False
        self._out_buf = b""
        cmd = [sys.executable, "-m", "fgloc.view.serve", "--host", host, "--port", str(int(port)),
               "--name", name, "--backlog", str(int(backlog))]
        debug = bool(os.environ.get("FGLOC_VIEW_DEBUG"))
        self.proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=None if debug else subprocess.DEVNULL, start_new_session=True)
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self._in = self.proc.stdin.fileno()
        self._out = self.proc.stdout.fileno()
        first = self._read_line(STARTUP_TIMEOUT_S)
        if first is None or "ready" not in first:
            self._kill()
            why = (first or {}).get("error") or "the view's server process did not start"
            raise ConfigError(f"--view {_fmt(host, port)}: cannot serve the Foxglove view: {why}")
        self.port = int(first["ready"])
        os.set_blocking(self._in, False)
        os.set_blocking(self._out, False)
        try:
            fcntl.fcntl(self._in, getattr(fcntl, "F_SETPIPE_SZ", 1031), PIPE_SIZE)
        except OSError:
            pass  # the default pipe size (64 KiB) then

    @property
    def url(self) -> str:
        return f"ws://{_fmt(self.host, self.port)}"

    # ------------------------------------------------------------------ the server process
    def _read_line(self, timeout_s: float) -> dict[str, Any] | None:
        """The next JSON line from the server process (blocking up to ``timeout_s``), or None."""
        deadline = time.monotonic() + timeout_s
        while b"\n" not in self._out_buf:
            left = max(0.0, deadline - time.monotonic())
            if not select.select([self._out], [], [], left)[0]:
                return None
            try:
                chunk = os.read(self._out, 65536)
            except BlockingIOError:
                continue
            if not chunk:
                return None
            self._out_buf += chunk
        line, _, self._out_buf = self._out_buf.partition(b"\n")
        try:
            return json.loads(line)
        except ValueError:
            return {}

    def poll(self) -> None:
        """Take in what the server process said (subscriptions) without waiting."""
        while True:
            msg = self._read_line(0.0)
            if msg is None:
                return
            self._take(msg)

    def _take(self, msg: dict[str, Any]) -> bool:
        """One line of the server process: its subscription count, its stats (True: it had stats)."""
        if "subscriptions" in msg:
            self.stats["subscriptions"] = int(msg["subscriptions"])
        if "stats" in msg:
            self.stats.update(msg["stats"])
            return True
        return False

    def _send(self, item: tuple[Any, ...], essential: bool = False) -> None:
        if self._closed or self.stats["server_process_lost"]:
            return
        data = pickle.dumps(item, protocol=pickle.HIGHEST_PROTOCOL)
        if not essential and len(self._pending) + len(data) > self.buffer_bytes:
            self.stats["dropped"] += 1
            self._flush()
            return
        self._pending += len(data).to_bytes(4, "little")
        self._pending += data
        if item[0] != "close":
            self.stats["queued"] += 1
        self._flush()

    def _flush(self, block_s: float = 0.0) -> None:
        deadline = time.monotonic() + block_s
        while self._pending:
            try:
                n = os.write(self._in, self._pending[:PIPE_SIZE])
            except BlockingIOError:
                left = deadline - time.monotonic()
                if left <= 0:
                    return
                select.select([], [self._in], [], left)
                continue
            except (BrokenPipeError, OSError):
                self.stats["server_process_lost"] = 1
                self._pending.clear()
                return
            del self._pending[:n]

    # ------------------------------------------------------------------ ViewSink (localizer thread)
    def wants_scan(self, status: str = "") -> bool:
        """At most ``max_rate_hz`` scans a second (wall clock) reach the viewer: a replay as fast as
        possible would otherwise spend the localizer's time on frames nobody can see.

        A scan the front-end matched (any ``status`` but ``predicted``) is due on its own clock; an
        unmatched (predicted) one only when no scan at all was sent for a period.  A count-based
        thinning would alias with ``frontend_every``: at twice the rate with every other scan
        matched, the viewer would see only predictions and never a fix."""
        now = time.monotonic()
        if self._closed:
            self._scan_sent = False
        elif status == PREDICTED:
            self._scan_sent = now - max(self._last_scan_t, self._last_matched_t) >= self._min_period_s
        else:
            self._scan_sent = now - self._last_matched_t >= self._min_period_s
            if self._scan_sent:
                self._last_matched_t = now
        if self._scan_sent:
            self._last_scan_t = now
        else:
            self.stats["thinned"] += 1
        return self._scan_sent

    def on_map(self, occ_map: Any, stamp: float) -> None:
        self._send(("map", np.asarray(occ_map.data), float(occ_map.resolution),
                    np.asarray(occ_map.origin, dtype=float), float(stamp)), essential=True)
        self._flush(block_s=CLOSE_TIMEOUT_S)  # at start-up, before the localizer runs

    def on_scan(self, view: ScanView) -> None:
        self._send(("scan", view))

    def on_particles(self, stamp: float, frame_id: str, poses: np.ndarray) -> None:
        if self._scan_sent:  # with the scan they belong to
            self._send(("poses", "particles", stamp, frame_id, poses))

    def on_trajectory(self, stamp: float, frame_id: str, poses: np.ndarray) -> None:
        self._send(("poses", "trajectory", stamp, frame_id, poses))

    def on_health(self, stamp: float, health: dict[str, Any]) -> None:
        self._send(("health", stamp, {**health, "view": {k: v for k, v in self.stats.items()}}))

    def close(self) -> None:
        """Send what waits (up to a few seconds), stop the server process; idempotent."""
        if self._closed:
            return
        self._send(("close",), essential=True)
        self._closed = True
        self._flush(block_s=CLOSE_TIMEOUT_S)
        try:
            os.close(self._in)
        except OSError:
            pass
        if self.proc.stdin is not None:
            self.proc.stdin = None  # closed above
        deadline = time.monotonic() + CLOSE_TIMEOUT_S
        while time.monotonic() < deadline:
            msg = self._read_line(max(0.0, deadline - time.monotonic()))
            if msg is None or self._take(msg):
                break
        self._kill(wait_s=max(0.1, deadline - time.monotonic()))

    def _kill(self, wait_s: float = 0.5) -> None:
        try:
            self.proc.wait(timeout=wait_s)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        if self.proc.stdout is not None:
            self.proc.stdout.close()
        if self.proc.stdin is not None:
            self.proc.stdin.close()

    def __enter__(self) -> FoxgloveServerSink:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _fmt(host: str, port: int) -> str:
    return f"[{host}]:{port}" if ":" in host else f"{host}:{port}"
