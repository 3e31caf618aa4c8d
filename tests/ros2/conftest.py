"""DDS tests: every participant on the loopback interface, in a domain of this test process's own."""

from __future__ import annotations

import itertools
import os
import time
from collections.abc import Callable

import pytest

pytest.importorskip("cyclonedds")

LOOPBACK = "lo"


#: ROS 2's advice: domains 0-101 keep every RTPS port (7400 + 250 d + ...) below Linux's ephemeral
#: range (32768-60999), where any other socket of the machine may already hold it
MAX_DOMAIN = 101


def domain_for(offset: int = 0) -> int:
    """A DDS domain unlikely to be shared with another test process on this machine (1..100): each
    pytest-xdist worker draws from its own half, a process outside xdist from its pid."""
    worker = os.environ.get("PYTEST_XDIST_WORKER", "")
    if worker.startswith("gw") and worker[2:].isdigit():
        half = int(worker[2:]) % 2
        return 1 + half * 50 + (os.getpid() * 7 + offset) % 50
    return 1 + (os.getpid() * 7 + offset) % (MAX_DOMAIN - 1)


_NEXT = itertools.count(1)


@pytest.fixture
def dds_domain() -> int:
    """A domain of its own for each test (a process configures a domain once)."""
    return domain_for(next(_NEXT))


def wait_for(cond: Callable[[], bool], timeout: float = 60.0, step: float = 0.02) -> bool:
    """Poll ``cond`` until it holds; ``timeout`` bounds a hung peer only (a loaded machine is slower, not wrong)."""
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        if cond():
            return True
        time.sleep(step)
    return cond()
