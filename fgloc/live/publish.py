"""Fused pose output: UDP JSON lines to other local processes.

Every datagram is one UTF-8 JSON object terminated by ``\\n`` (schema in
``docs/serial-protocol.md``, section "Pose stream")::

    {"type": "pose", "seq": 12, "stamp": 1732233600.123, "frame_id": "map",
     "x": 1.23, "y": -0.5, "yaw": 0.01, "cov": [9 floats, row-major x,y,yaw],
     "quality": 0.93, "source": "ekf", "latency_ms": 2.1}
    {"type": "status", "stamp": ..., "health": {"laser": "ok", ...}, "counters": {...}}
"""

from __future__ import annotations

import json
import math
import socket
from typing import Any
from urllib.parse import urlparse

from fgloc.errors import ConfigError
from fgloc.types import PoseFix


def parse_udp_url(url: str) -> tuple[str, int]:
    u = urlparse(url)
    if u.scheme != "udp" or not u.hostname or not u.port:
        raise ConfigError(f"--publish {url}: expected udp://HOST:PORT (e.g. udp://127.0.0.1:5600)")
    return u.hostname, int(u.port)


def _clean(v: Any) -> Any:
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, dict):
        return {k: _clean(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [_clean(x) for x in v]
    return v


class UdpPublisher:
    """Sends pose and status JSON lines to one or more ``udp://host:port`` targets."""

    def __init__(self, urls: list[str]) -> None:
        self.targets = [parse_udp_url(u) for u in urls]
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.seq = 0
        self.sent = 0
        self.errors = 0

    def _send(self, obj: dict[str, Any]) -> None:
        data = (json.dumps(_clean(obj), separators=(",", ":")) + "\n").encode()
        for t in self.targets:
            try:
                self.sock.sendto(data, t)
                self.sent += 1
            except OSError:
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
            }
        )

    def status(self, stamp: float, health: dict[str, str], counters: dict[str, Any]) -> None:
        self._send({"type": "status", "stamp": stamp, "health": health, "counters": counters})

    def close(self) -> None:
        self.sock.close()
