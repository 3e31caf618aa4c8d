"""Fused pose output: UDP JSON lines to other local processes.

Every datagram is one UTF-8 JSON object terminated by ``\\n`` (schema in
``docs/serial-protocol.md``, section "Pose stream")::

    {"type": "pose", "seq": 12, "stamp": 1732233600.123, "frame_id": "map",
     "x": 1.23, "y": -0.5, "yaw": 0.01, "cov": [9 floats, row-major x,y,yaw],
     "quality": 0.93, "source": "ekf", "latency_ms": 2.1, "status": "ok"}
    {"type": "status", "stamp": ..., "health": {"laser": "ok", ...}, "counters": {...}}
"""

from __future__ import annotations

import json
import math
import socket
from typing import Any
from urllib.parse import urlparse

import numpy as np

from fgloc.errors import ConfigError
from fgloc.types import PoseFix


def parse_udp_url(url: str) -> tuple[str, int]:
    u = urlparse(url)
    if u.scheme != "udp" or not u.hostname or not u.port:
        raise ConfigError(f"--publish {url}: expected udp://HOST:PORT (e.g. udp://127.0.0.1:5600)")
    return u.hostname, int(u.port)


def json_safe(v: Any) -> Any:
    """``v`` with every non-finite float as ``None`` and numpy scalars / arrays as Python
    numbers / lists, so ``json.dumps(..., allow_nan=False)`` gives standard JSON (RFC 8259
    has no NaN or Infinity: ``json.dumps`` would write the bare words ``NaN`` / ``Infinity``,
    which JSON parsers other than Python's reject)."""
    if isinstance(v, np.ndarray):
        return json_safe(v.tolist())
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, dict):
        return {str(k): json_safe(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [json_safe(x) for x in v]
    return v


def dumps(obj: Any, **kw: Any) -> str:
    """Standard JSON of ``obj`` (non-finite numbers as ``null``)."""
    return json.dumps(json_safe(obj), allow_nan=False, **kw)


def open_udp_sender(host: str, port: int) -> socket.socket:
    """A UDP socket connected to ``host:port`` and bound to the local address of the
    interface that reaches it, in the destination's address family (127.0.0.1 for
    127.0.0.1, ::1 for ::1, the LAN address for a LAN host), never the wildcard 0.0.0.0 that
    an unbound socket gets on its first ``sendto``.  The kernel picks the address from its
    routing table (a UDP ``connect`` sends nothing)."""
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM)
    except socket.gaierror as e:
        raise ConfigError(f"--publish udp://{host}:{port}: cannot resolve {host} ({e.strerror})") from None
    family, stype, proto, _, addr = infos[0]
    probe = socket.socket(family, stype, proto)
    try:
        probe.connect(addr)
        local = probe.getsockname()
    except OSError as e:
        raise ConfigError(f"--publish udp://{host}:{port}: no route ({e.strerror})") from None
    finally:
        probe.close()
    sock = socket.socket(family, stype, proto)
    sock.bind((local[0], 0, *local[2:]))  # IPv6: keep flowinfo and scope id
    sock.connect(addr)
    return sock


class UdpPublisher:
    """Sends pose and status JSON lines to one or more ``udp://host:port`` targets, one
    socket per target bound to the interface that reaches it (:func:`open_udp_sender`)."""

    def __init__(self, urls: list[str]) -> None:
        self.targets = [parse_udp_url(u) for u in urls]
        self.socks: list[socket.socket] = []
        try:
            for host, port in self.targets:
                self.socks.append(open_udp_sender(host, port))
        except ConfigError:
            self.close()
            raise
        self.seq = 0
        self.sent = 0
        self.errors = 0

    def local_addresses(self) -> list[tuple[str, int]]:
        """``(address, port)`` each target's socket sends from."""
        return [s.getsockname()[:2] for s in self.socks]

    def _send(self, obj: dict[str, Any]) -> None:
        data = (dumps(obj, separators=(",", ":")) + "\n").encode()
        for s in self.socks:
            try:
                s.send(data)
                self.sent += 1
            except OSError:  # e.g. ECONNREFUSED: nobody listens (yet) on that port
                self.errors += 1

    def pose(self, fix: PoseFix, latency_ms: float | None = None) -> None:
        self.seq += 1
        self._send(
            {
                "type": "pose",
                "seq": self.seq,
                "stamp": float(fix.stamp),
                "frame_id": fix.frame_id,
                "x": float(fix.pose[0]),
                "y": float(fix.pose[1]),
                "yaw": float(fix.pose[2]),
                "cov": [float(c) for c in fix.cov.reshape(-1)],
                "quality": float(fix.quality),
                "source": fix.source,
                "latency_ms": latency_ms,
                "status": fix.status or None,
            }
        )

    def status(self, stamp: float, health: dict[str, str], counters: dict[str, Any]) -> None:
        self._send({"type": "status", "stamp": stamp, "health": health, "counters": counters})

    def close(self) -> None:
        for s in self.socks:
            s.close()
