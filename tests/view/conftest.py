"""Fixtures for the view tests: one short simulated run, free ports, a stalled viewer."""

from __future__ import annotations

import base64
import json
import os
import socket
import time
from pathlib import Path

import pytest

pytest.importorskip("foxglove", reason="the Foxglove view needs foxglove-sdk (pip install \"fgloc[view]\")")

SHORT_ROUTE = [[2.5, 3.0], [8.5, 3.0]]  # 6 m along the hall's south side, ~11 s


@pytest.fixture(scope="session")
def short_sim():
    from fgloc.sim import run_scenario

    return run_scenario({"route": SHORT_ROUTE, "laser": {"rate_hz": 10.0}}, seed=0)


@pytest.fixture(scope="session")
def short_dir(short_sim, tmp_path_factory) -> Path:
    """log.mcap, map.yaml/.pgm, ground_truth.tum of the short run."""
    from fgloc.sim import write_sim

    d = tmp_path_factory.mktemp("view_sim")
    write_sim(short_sim, d)
    return d


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _frame(buf: bytes) -> tuple[int, bytes, bytes] | None:
    """One unmasked server WebSocket frame off ``buf``: (opcode, payload, rest), or None if incomplete."""
    if len(buf) < 2:
        return None
    n, i = buf[1] & 0x7F, 2
    if n == 126:
        if len(buf) < 4:
            return None
        n, i = int.from_bytes(buf[2:4], "big"), 4
    elif n == 127:
        if len(buf) < 10:
            return None
        n, i = int.from_bytes(buf[2:10], "big"), 10
    if len(buf) < i + n:
        return None
    return buf[0] & 0x0F, buf[i:i + n], buf[i + n:]


def stalled_viewer(port: int, timeout_s: float = 20.0) -> socket.socket:
    """A Foxglove client that connects, subscribes to every advertised channel and then
    never reads again (a 4 KiB receive buffer, so the server's sends back up at once)."""
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            s = socket.socket()
            s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
            s.connect(("127.0.0.1", port))
            break
        except OSError:
            s.close()
            if time.monotonic() > deadline:
                raise
            time.sleep(0.05)
    key = base64.b64encode(os.urandom(16)).decode()
    s.sendall((f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
               f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
               "Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n").encode())
    s.settimeout(timeout_s)
    buf = b""
    while b"\r\n\r\n" not in buf:
        chunk = s.recv(65536)
        assert chunk, "server closed the connection during the handshake"
        buf += chunk
    head, _, buf = buf.partition(b"\r\n\r\n")
    assert b"101 Switching Protocols" in head and b"foxglove.sdk.v1" in head
    ids: set[int] = set()
    s.settimeout(0.5)
    while True:  # text frames (serverInfo, advertise ...) until the server has nothing more to say
        frame = _frame(buf)
        if frame is None:
            try:
                chunk = s.recv(65536)
            except TimeoutError:
                if ids:
                    break
                continue
            assert chunk, "server closed the connection before advertising"
            buf += chunk
            continue
        opcode, payload, buf = frame
        if opcode == 1:
            msg = json.loads(payload)
            if msg.get("op") == "advertise":
                ids.update(int(c["id"]) for c in msg["channels"])
    s.settimeout(timeout_s)
    payload = json.dumps({"op": "subscribe", "subscriptions": [{"id": i, "channelId": i}
                                                              for i in sorted(ids)]}).encode()
    mask = os.urandom(4)
    n = len(payload)
    hdr = bytes([0x81, 0x80 | 126]) + n.to_bytes(2, "big") if n >= 126 else bytes([0x81, 0x80 | n])
    s.sendall(hdr + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(payload)))
    return s
