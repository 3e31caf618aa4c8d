"""``fgloc batch run --engine ray --address`` against a real Ray head node started for the test.

The head node runs as ``ray start --head --block`` in its own process group; at the end the
test ends exactly the processes it started (that group and its descendants, by pid), not
``ray stop``, which would stop every Ray instance of this user on the machine.
"""

from __future__ import annotations

import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

from fgloc.batch import read_summary_csv

from .helpers import CORRUPT, ROUTES, START, assert_identical


def _free_ports(n: int) -> list[int]:
    socks = []
    try:
        for _ in range(n):
            s = socket.socket()
            s.bind(("127.0.0.1", 0))
            socks.append(s)
        return [s.getsockname()[1] for s in socks]
    finally:
        for s in socks:
            s.close()


def _end_process_tree(proc: subprocess.Popen) -> None:
    """End ``ray start --block`` and everything it started, by pid, waiting for them to go.

    SIGTERM to ``ray start`` alone first: it stops its own processes in order (measured 2.5 s);
    SIGTERM to every process at once leaves the GCS server and the monitor waiting on each other
    (> 20 s).  Whatever is left after that gets SIGKILL (by pid and by the process group)."""
    import psutil

    try:
        tree = [psutil.Process(proc.pid), *psutil.Process(proc.pid).children(recursive=True)]
    except psutil.NoSuchProcess:
        tree = []
    proc.send_signal(signal.SIGTERM)
    _, alive = psutil.wait_procs(tree, timeout=20)
    for p in alive:
        try:
            p.kill()
        except psutil.NoSuchProcess:
            pass
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
    psutil.wait_procs(alive, timeout=15)
    proc.wait(timeout=15)


@pytest.fixture
def ray_head():
    """A Ray head node on 127.0.0.1 with 2 CPUs and its own ports and temp folder: yields HOST:PORT."""
    pytest.importorskip("ray")
    pytest.importorskip("psutil")
    ray_bin = Path(sys.executable).parent / "ray"
    if not ray_bin.exists():
        pytest.skip(f"no ray command beside {sys.executable}")
    ports = _free_ports(8)
    tmp = tempfile.mkdtemp(prefix="fgray")  # short: Ray's socket paths must stay < 108 characters
    log = Path(tmp) / "head.log"
    cmd = [str(ray_bin), "start", "--head", "--block", "--node-ip-address", "127.0.0.1", "--port", str(ports[0]),
           "--num-cpus", "2", "--include-dashboard=false", "--disable-usage-stats", "--temp-dir", tmp,
           "--ray-client-server-port", str(ports[1]), "--dashboard-agent-listen-port", str(ports[2]),
           "--dashboard-agent-grpc-port", str(ports[3]), "--runtime-env-agent-port", str(ports[4]),
           "--metrics-export-port", str(ports[5]), "--node-manager-port", str(ports[6]),
           "--object-manager-port", str(ports[7])]
    # a secured cluster, as Ray 2.5x sets them up: token authentication with a token of its own
    token = secrets.token_hex(32)
    env = {k: v for k, v in os.environ.items() if k not in ("RAY_ADDRESS", "RAY_AUTH_TOKEN_PATH")}
    env.update(RAY_AUTH_MODE="token", RAY_AUTH_TOKEN=token)
    with log.open("w") as fh:
        proc = subprocess.Popen(cmd, stdout=fh, stderr=subprocess.STDOUT, start_new_session=True, env=env)
    try:
        deadline = time.monotonic() + 120
        while "Ray runtime started" not in log.read_text():
            if proc.poll() is not None or time.monotonic() > deadline:
                pytest.fail(f"ray start --head did not come up:\n{log.read_text()[-2000:]}")
            time.sleep(0.2)
        yield f"127.0.0.1:{ports[0]}", token
    finally:
        _end_process_tree(proc)
        shutil.rmtree(tmp, ignore_errors=True)


def test_batch_on_a_ray_head_node_with_shipped_inputs(ray_head, batch_logs, references, tmp_path):
    """A manifest (each row its own map and start) through ``--address`` with ``--ship-inputs``, from
    a shell-like ``fgloc`` process holding the cluster's token: the workers read nothing from our
    folders, the outputs equal the single runs'."""
    address, token = ray_head
    man = tmp_path / "fleet.csv"
    rows = [f"{batch_logs['logs'] / (n + '.mcap')},{batch_logs['map']},{START[0]},{START[1]},{START[2]}"
            for n in batch_logs["names"]]
    man.write_text("log,map,x,y,yaw\n" + "\n".join(rows) + "\n")
    out = tmp_path / "out"
    env = {k: v for k, v in os.environ.items() if k not in ("RAY_ADDRESS", "RAY_AUTH_TOKEN_PATH")}
    env.update(RAY_AUTH_MODE="token", RAY_AUTH_TOKEN=token, COLUMNS="200")
    exe = Path(sys.executable).parent / "fgloc"
    p = subprocess.run([str(exe), "batch", "run", "--manifest", str(man), "-o", str(out), "--engine", "ray",
                        "--address", address, "--ship-inputs", "-q"], capture_output=True, text=True, env=env,
                       timeout=300)
    assert p.returncode == 1, p.stderr[-3000:]
    assert f"Ray cluster at {address}" in p.stdout
    assert_identical(out, references, ROUTES)
    summary = {r["log"]: r for r in read_summary_csv(out / "summary.csv")}
    assert [summary[n]["status"] for n in ROUTES] == ["ok"] * 3
    assert summary[CORRUPT]["status"] == "error"
    assert summary[CORRUPT]["error"] == references["errors"][CORRUPT]  # the original path, not a temp copy
    assert len({r["host"] for r in summary.values()}) >= 1 and all(r["host"] for r in summary.values())
