"""Replay pacing: hand a log's messages on at ``rate`` x real time (``fgloc run --realtime R``)."""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable, Iterator
from typing import TypeVar

from fgloc.errors import ConfigError

T = TypeVar("T")

MAX_SLEEP_S = 0.5  # sleep in slices so Ctrl-C is handled promptly


def check_rate(rate: float | None, option: str = "--realtime") -> float | None:
    """None (as fast as possible) or a finite factor > 0; anything else is a one-line error."""
    if rate is None:
        return None
    r = float(rate)
    if not math.isfinite(r) or r <= 0:
        raise ConfigError(f"{option} {rate}: expected a factor > 0 (1 = real time, 2 = twice as fast)")
    return r


def paced(messages: Iterable[tuple[str, T]], rate: float | None,
          clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep
          ) -> Iterator[tuple[str, T]]:
    """Yield ``(topic, msg)`` no earlier than ``(msg.stamp - first stamp) / rate`` after the first.

    ``rate`` None: no pacing.  Messages without a finite ``stamp`` (``/tf_static`` lists)
    and stamps that go back are passed on at once.  The schedule is anchored at the first
    message (as ``ros2 bag play``): a consumer that fell behind gets the next messages at
    once until it has caught up.
    """
    if rate is None:
        yield from messages
        return
    t0_log: float | None = None
    t0_wall = 0.0
    for topic, msg in messages:
        stamp = getattr(msg, "stamp", None)
        if isinstance(stamp, int | float) and math.isfinite(stamp):
            if t0_log is None:
                t0_log, t0_wall = float(stamp), clock()
            else:
                due = t0_wall + (float(stamp) - t0_log) / rate
                while (wait := due - clock()) > 0:
                    sleep(min(wait, MAX_SLEEP_S))
        yield topic, msg
