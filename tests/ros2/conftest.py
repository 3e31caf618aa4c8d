"""DDS tests: every participant on the loopback interface, in a domain of this test process's own."""

from __future__ import annotations

import itertools
import os
import time
from collections.abc import Callable

import pytest

pytest.importorskip("cyclonedds")

LOOPBACK = "lo"


def domain_for(offset: int = 0) -> int:
    """A DDS domain unlikely to be shared with another test process on this machine (0..232)."""
    return 1 + (os.getpid() * 7 + offset) % 200


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
