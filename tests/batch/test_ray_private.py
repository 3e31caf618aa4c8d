"""The private Ray instance of ``--engine ray`` (no address) is the driver's alone: every socket of
every process of it listens on the loopback interface, its GCS refuses a client without the token
(a real Ray client, real gRPC), and none of its processes outlives the driver by more than 5 s,
whether the driver is killed with SIGKILL or shuts Ray down."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

pytest.importorskip("ray")
psutil = pytest.importorskip("psutil")

LOOPBACK = {"127.0.0.1", "::1", "::ffff:127.0.0.1"}

DRIVER = r"""
import os, sys, time
from fgloc.batch.engines import RayEngine
e = RayEngine(jobs=1)
e.connect()
import ray
pid = ray.get(ray.remote(lambda: os.getpid()).remote())  # a worker started too
print(ray.get_runtime_context().gcs_address, os.environ["RAY_AUTH_TOKEN"], pid, flush=True)
if sys.argv[1] == "shutdown":
    sys.stdin.readline()
    e.shutdown()
    print("SHUTDOWN", flush=True)
time.sleep(600)
"""

PROBE = r"""
import sys, ray._raylet as r
try:
    keys = r.GcsClient(address=sys.argv[1]).internal_kv_keys(b"", namespace=None, timeout=10)
    print("ANSWERED", len(keys))
except Exception as e:
    print("REFUSED", type(e).__name__, str(e).splitlines()[0][:200])
"""


def _driver(mode: str) -> tuple[subprocess.Popen, str, str, int]:
    p = subprocess.Popen([sys.executable, "-c", DRIVER, mode], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                         text=True)
    assert p.stdout is not None
    line = p.stdout.readline().split()
    assert len(line) == 3, line
    return p, line[0], line[1], int(line[2])


def _instance(driver: int) -> list:
    """The processes the driver started (the watchdog aside: it is not Ray's)."""
    out = []
    for c in psutil.Process(driver).children(recursive=True):
        try:
            if "raywatch.py" not in " ".join(c.cmdline()):
                out.append(c)
        except psutil.NoSuchProcess:
            pass
    return out


def _alive(procs: list) -> list:
    out = []
    for p in procs:
        try:
            if p.is_running() and p.status() != psutil.STATUS_ZOMBIE:
                out.append(p)
        except psutil.NoSuchProcess:
            pass
    return out


def _gone_within(procs: list, seconds: float) -> list:
    deadline = time.monotonic() + seconds
    while _alive(procs) and time.monotonic() < deadline:
        time.sleep(0.05)
    return _alive(procs)


def _probe(address: str, env: dict[str, str]) -> str:
    clean = {k: v for k, v in os.environ.items() if not k.startswith("RAY_AUTH")}
    q = subprocess.run([sys.executable, "-c", PROBE, address], capture_output=True, text=True, timeout=120,
                       env={**clean, **env})
    return q.stdout.strip()


def test_private_ray_listens_on_loopback_asks_a_token_and_dies_with_a_killed_driver():
    p, gcs, token, worker = _driver("kill")
    try:
        procs = _instance(p.pid)
        names = {x.name() for x in procs}
        assert "gcs_server" in names and "raylet" in names and worker in {x.pid for x in procs}, names
        listening = [(x.name(), c.laddr.ip, c.laddr.port) for x in [psutil.Process(p.pid), *procs]
                     for c in x.net_connections(kind="inet") if c.status == psutil.CONN_LISTEN]
        assert len(listening) >= 4 and int(gcs.rpartition(":")[2]) in {port for _, _, port in listening}
        assert all(ip in LOOPBACK for _, ip, _ in listening), listening
        # a client without the token, or with another, is refused by the GCS; with it, answered
        assert _probe(gcs, {}).startswith("REFUSED AuthenticationError")
        assert _probe(gcs, {"RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": "0" * 64}).startswith("REFUSED")
        assert _probe(gcs, {"RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": token}).startswith("ANSWERED")
    finally:
        os.kill(p.pid, signal.SIGKILL)
        p.wait()
    left = _gone_within(procs, 5.0)
    assert left == [], [(x.pid, x.name()) for x in left]


def test_private_ray_leaves_no_process_after_shutdown():
    p, _, _, _ = _driver("shutdown")
    try:
        procs = _instance(p.pid)
        assert len(procs) >= 4
        assert p.stdin is not None and p.stdout is not None
        p.stdin.write("\n")
        p.stdin.flush()
        assert p.stdout.readline().strip() == "SHUTDOWN"
        left = _gone_within(procs, 5.0)
        assert left == [], [(x.pid, x.name()) for x in left]
    finally:
        p.kill()
        p.wait()
