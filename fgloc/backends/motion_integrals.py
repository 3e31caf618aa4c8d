"""The EKF's reference motion: the yaw and the distance driven, integrated at their sensors' own
stamps (:class:`MotionIntegrals`).  The scans' latency is estimated against it
(:class:`~fgloc.backends.health.latency.LatencyReference`), and the front-ends' odometry increment
is turned by the gyro's rotation with it.  Core maths only."""

from __future__ import annotations

import math
from collections import deque
from itertools import islice

from fgloc.backends.health.latency import bracket, median_period

#: (t, integral, rate) samples
Series = deque[tuple[float, float, float]]


def series_at(m: Series, t: float, held: bool = False) -> tuple[float, float] | None:
    """Integral and rate at ``t`` (None outside the samples); ``held``: the rate is the mean since
    the previous sample (odometry), so the sample after ``t`` holds it."""
    if not m or m[0][0] > t or m[-1][0] < t:
        return None
    lo, hi = bracket(m, t)
    a, b = m[lo], m[hi]
    f = (t - a[0]) / (b[0] - a[0]) if b[0] > a[0] else 1.0
    rate = float(b[2]) if held else float(a[2] + f * (b[2] - a[2]))
    return float(a[1] + f * (b[1] - a[1])), rate


def _last_stamps(m: Series, n: int = 50) -> list[float]:
    """The stamps of the last ``n`` samples, oldest first (read from the deque's end: not a copy of
    its thousands of samples)."""
    out = [x[0] for x in islice(reversed(m), n)]
    out.reverse()
    return out


class MotionIntegrals:
    """The yaw (a gyro's, bias-corrected, or else the odometry's times its gain) and the distance
    (the odometry's) integrated over time, each at its own stamps."""

    def __init__(self, maxlen: int = 4000) -> None:
        self.yaw: Series = deque(maxlen=maxlen)
        self.dist: Series = deque(maxlen=maxlen)
        self._yaw_int = 0.0
        self._dist_int = 0.0
        self._last_rate: tuple[float, float] | None = None

    def add_odometry(self, t: float, speed: float, yaw_rate: float | None) -> None:
        """An odometry twist at ``t`` (the mean since the previous message, held backwards): its speed
        and, when no gyro gives the yaw, its (gain-corrected) yaw rate."""
        if self.dist and t > self.dist[-1][0]:
            t0 = self.dist[-1][0]
            self._dist_int += speed * (t - t0)
            if yaw_rate is not None:
                self._yaw_int += yaw_rate * (t - t0)
                self.yaw.append((float(t), self._yaw_int, yaw_rate))
        self.dist.append((float(t), self._dist_int, speed))

    def add_gyro(self, t: float, rate: float, bias: float) -> None:
        """A gyro reading at ``t`` with its bias (readings interpolated between stamps)."""
        if self._last_rate is not None and t > self._last_rate[0]:
            self._yaw_int += 0.5 * (self._last_rate[1] + rate - bias) * (t - self._last_rate[0])
        if self._last_rate is None or t > self._last_rate[0]:
            self._last_rate = (float(t), float(rate) - bias)
            self.yaw.append((float(t), self._yaw_int, float(rate) - bias))

    def rotation(self, t0: float, t1: float) -> float | None:
        """The yaw change over ``(t0, t1]``, or None where the yaw integral does not cover it."""
        ya, yb = series_at(self.yaw, t0), series_at(self.yaw, t1)
        if ya is None or yb is None:
            return None
        return yb[0] - ya[0]

    # ------------------------------------------------------------------ the latency's reference
    def reference_covered_until(self) -> float:
        if not self.yaw or not self.dist:
            return -math.inf
        return min(self.yaw[-1][0], self.dist[-1][0])

    def reference_periods(self) -> tuple[float, float]:
        return median_period(_last_stamps(self.dist)), median_period(_last_stamps(self.yaw))

    def _at(self, ta: float, tb: float) -> tuple[tuple[float, float], ...] | None:
        ya, yb = series_at(self.yaw, ta), series_at(self.yaw, tb)
        da, db = series_at(self.dist, ta, True), series_at(self.dist, tb, True)
        if ya is None or yb is None or da is None or db is None:
            return None
        return ya, yb, da, db

    def reference_yaw(self, ta: float, tb: float) -> tuple[float, float, float] | None:
        r = self._at(ta, tb)
        if r is None:
            return None
        ya, yb = r[0], r[1]
        return yb[0] - ya[0], -(yb[1] - ya[1]), 1e-8

    def reference_distance(self, ta: float, tb: float) -> tuple[float, float] | None:
        r = self._at(ta, tb)
        if r is None:
            return None
        return r[3][0] - r[2][0], 1e-6
