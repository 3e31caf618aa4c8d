"""Never blocks, never dies: each DDS fault counted and named, over real Cyclone DDS on loopback."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import threading

import numpy as np
import pytest

from fgloc.ros2 import codec, qos
from fgloc.ros2.transport import CycloneTransport
from fgloc.types import LaserScan, PoseFix

from .conftest import LOOPBACK, wait_for

SCAN = "sensor_msgs/msg/LaserScan"
ODOM = "nav_msgs/msg/Odometry"
POSE = "geometry_msgs/msg/PoseWithCovarianceStamped"


def _scan(t: float) -> bytes:
    return codec.encode(LaserScan(t, -2.0, 0.01, 0.1, 30.0, np.full(400, 3.0, np.float32), frame_id="laser"))[1]


@pytest.fixture
def pair(dds_domain: int):
    a, b = CycloneTransport(dds_domain, LOOPBACK), CycloneTransport(dds_domain, LOOPBACK)
    a.start()
    b.start()
    yield a, b
    a.close()
    b.close()


def test_a_topic_with_another_type_is_named(pair) -> None:
    a, b = pair
    got: list[bytes] = []
    h = b.subscribe("/scan", SCAN, qos.SENSOR_DATA, lambda d, t: got.append(d))
    a.publisher("/scan", ODOM, qos.SENSOR_DATA)
    assert wait_for(lambda: bool(h.other_type))
    assert h.other_type == {"nav_msgs::msg::dds_::Odometry_": 1}
    assert any("another type nav_msgs/msg/Odometry" in p for p in h.problems())
    assert h.matched == 0 and not got


@pytest.mark.parametrize("offered, requested, policy", [
    (qos.SENSOR_DATA, qos.DEFAULT, "RELIABILITY"),   # best-effort publisher, reliable subscriber
    (qos.DEFAULT, qos.MAP_SUB, "DURABILITY"),         # volatile map publisher, AMCL's latched subscription
])
def test_an_incompatible_qos_is_named(pair, offered, requested, policy) -> None:
    a, b = pair
    h = b.subscribe("/map", SCAN, requested, lambda d, t: None)
    w = a.publisher("/map", SCAN, offered)
    assert wait_for(lambda: h.incompatible_qos > 0 and w.health.incompatible_qos > 0)
    assert h.incompatible_policy == policy and w.health.incompatible_policy == policy
    assert h.matched == 0
    assert f"incompatible QoS ({policy})" in "; ".join(h.problems())


def test_a_publisher_that_vanishes_and_returns_is_counted(dds_domain: int) -> None:
    sub = CycloneTransport(dds_domain, LOOPBACK)
    got: list[bytes] = []
    h = sub.subscribe("/scan", SCAN, qos.SENSOR_DATA, lambda d, t: got.append(d))
    sub.start()
    try:
        for k in range(2):
            pub = CycloneTransport(dds_domain, LOOPBACK)
            w = pub.publisher("/scan", SCAN, qos.DEFAULT)
            assert wait_for(lambda: h.matched == 1)
            n = len(got)
            w.write(_scan(float(k)))
            assert wait_for(lambda n=n: len(got) > n)
            pub.close()  # the participant leaves: the subscription sees its publisher go at once
            assert wait_for(lambda k=k: h.lost == k + 1)
        assert (h.lost, h.returned, h.matched) == (2, 1, 0)
        assert "publisher vanished 2x, back 1x" in h.problems()
    finally:
        sub.close()


def test_handler_errors_are_counted_and_reading_goes_on(pair) -> None:
    a, b = pair
    seen: list[float] = []

    def handler(data: bytes, arrival: float) -> None:
        seen.append(arrival)
        if len(seen) % 2:
            raise RuntimeError("boom")

    h = b.subscribe("/scan", SCAN, qos.DEFAULT.with_depth(50), handler)
    w = a.publisher("/scan", SCAN, qos.DEFAULT.with_depth(50))
    assert wait_for(lambda: h.matched == 1)
    for k in range(10):
        w.write(_scan(k))
    assert wait_for(lambda: len(seen) == 10)
    assert h.callback_errors == 5 and h.messages == 10


READER = textwrap.dedent("""
    import sys, time
    from fgloc.ros2.transport import CycloneTransport
    from fgloc.ros2 import qos
    tr = CycloneTransport(int(sys.argv[1]), "lo")
    got = []
    tr.subscribe("/amcl_pose", "geometry_msgs/msg/PoseWithCovarianceStamped", qos.DEFAULT.with_depth(1000),
                 lambda d, t: got.append(d))
    tr.start()
    print("ready", flush=True)
    line = sys.stdin.readline()
    t_end = time.monotonic() + 60.0
    while not got and time.monotonic() < t_end:  # continued: the newest samples come (a loaded host: later)
        time.sleep(0.02)
    print(len(got), flush=True)
""")


def test_a_stalled_reliable_subscriber_never_blocks_the_publisher(dds_domain: int) -> None:
    """A reliable subscriber in another process is stopped (SIGSTOP: it neither reads nor acknowledges);
    fgloc's reliable keep-last writer goes on (its history keeps the newest samples), and the subscriber,
    continued, gets the newest."""
    p = subprocess.Popen([sys.executable, "-c", READER, str(dds_domain)], stdin=subprocess.PIPE,
                         stdout=subprocess.PIPE, text=True)
    tr = CycloneTransport(dds_domain, LOOPBACK)
    try:
        assert p.stdout is not None and p.stdin is not None
        assert p.stdout.readline().strip() == "ready"
        tr.start()
        w = tr.publisher("/amcl_pose", POSE, qos.DEFAULT)
        assert wait_for(lambda: w.health.matched == 1)
        os.kill(p.pid, signal.SIGSTOP)
        ok: list[bool] = []

        def burst() -> None:
            for k in range(3000):
                ok.append(w.write(codec.encode(PoseFix(float(k), np.zeros(3), np.eye(3), 1.0, "x", "map"))[1]))

        th = threading.Thread(target=burst, daemon=True)
        th.start()
        th.join(timeout=60.0)
        assert not th.is_alive(), "publishing blocked behind a stalled subscriber"
        assert len(ok) == 3000 and w.health.messages + w.health.dropped == 3000
        os.kill(p.pid, signal.SIGCONT)
        p.stdin.write("go\n")
        p.stdin.flush()
        got = int(p.stdout.readline())
        assert 1 <= got <= 3000
    finally:
        os.kill(p.pid, signal.SIGCONT)
        p.kill()
        p.wait()
        tr.close()
