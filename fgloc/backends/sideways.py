"""Whether a robot moves sideways, from its map fixes alone (a log of scans without odometry).

A filter with the paper's unicycle state ``[x, y, theta, v, w]`` cannot follow a base that moves
sideways (a holonomic base; a laser mounted off the axle with no transform to the base, whose frame
swings sideways in every turn): its predictions fall beside the fixes, which its gate then rejects
one after the other.  With odometry, the odometry's lateral velocity says so; without, the fixes'
chords do: a unicycle moves along its heading (forwards or backwards), so its chord between two
poses runs within the headings it had in between; a chord outside them, by more than the fixes'
noise, is sideways motion."""

from __future__ import annotations

import math

from fgloc.backends.base import FloatArray
from fgloc.geometry import wrap_scalar

#: s, two fixes compared are at least this far apart (over a shorter span their noise looks like motion)
SPAN_S = 1.0
#: m, a chord this far outside the headings the fixes had along it is sideways motion (their noise: centimetres)
SIDEWAYS_M = 0.1
#: spans in a row that moved sideways before the base is taken to
IN_A_ROW = 2


class SidewaysEvidence:
    """Feed the fixes in time order (:meth:`add`); True once :data:`IN_A_ROW` spans in a row of at
    least :data:`SPAN_S` each ended more than :data:`SIDEWAYS_M` outside the headings along them."""

    def __init__(self) -> None:
        self._span_start: tuple[float, float, float, float] | None = None
        self._turn = (0.0, 0.0, 0.0)   # the heading since the span's start: now, least, most (rad)
        self._run = 0

    def add(self, t: float, pose: FloatArray) -> bool:
        x, y, th = (float(v) for v in pose[:3])
        ref = self._span_start
        if ref is None or t < ref[0]:
            self._span_start, self._turn = (float(t), x, y, th), (0.0, 0.0, 0.0)
            return False
        now, lo, hi = self._turn
        now += wrap_scalar(th - ref[3] - now)
        self._turn = (now, min(lo, now), max(hi, now))
        if t - ref[0] < SPAN_S:
            return False
        self._span_start, self._turn = (float(t), x, y, th), (0.0, 0.0, 0.0)
        self._run = self._run + 1 if _outside(x - ref[1], y - ref[2], ref[3], lo, hi) > SIDEWAYS_M else 0
        return self._run >= IN_A_ROW


def _outside(dx: float, dy: float, th0: float, lo: float, hi: float) -> float:
    """How far (m) the chord ``(dx, dy)`` ends outside the directions ``th0 + [lo, hi]`` (or their
    reverse: a unicycle may back up): its length times the sine of its angle to the nearest of them."""
    chord = math.hypot(dx, dy)
    width = hi - lo
    if chord == 0.0 or width >= math.pi:   # turned half round or more: every chord is a unicycle's
        return 0.0
    a = math.atan2(dy, dx) - th0 - lo
    best = math.pi
    for b in (a, a + math.pi):   # forwards or backwards
        d = b % (2.0 * math.pi)   # from the least heading on, anticlockwise
        best = min(best, 0.0 if d <= width else min(d - width, 2.0 * math.pi - d))
    return chord * math.sin(min(best, 0.5 * math.pi))
