"""Whether a robot moves sideways, from its map fixes alone (a log of scans without odometry).

A filter with the paper's unicycle state ``[x, y, theta, v, w]`` cannot follow a base that moves
sideways (a holonomic base; a laser mounted off the axle with no transform to the base, whose frame
swings sideways in every turn): its predictions fall beside the fixes, which its gate then rejects
one after the other.  With odometry, the odometry's lateral velocity says so; without, the fixes'
chords do: a unicycle's chord between two poses runs along their mean heading, so its part across
that heading, beyond the fixes' noise, is sideways motion."""

from __future__ import annotations

import math

from fgloc.backends.base import FloatArray
from fgloc.geometry import wrap_scalar

#: s, two fixes compared are at least this far apart (over a shorter span their noise looks like motion)
SPAN_S = 1.0
#: m, a chord's part across the mean heading beyond this is sideways motion (the fixes' noise is centimetres)
SIDEWAYS_M = 0.1
#: spans in a row that moved sideways before the base is taken to
IN_A_ROW = 2


class SidewaysEvidence:
    """Feed the fixes in time order (:meth:`add`); True once :data:`IN_A_ROW` spans in a row of at
    least :data:`SPAN_S` each moved more than :data:`SIDEWAYS_M` across their mean heading."""

    def __init__(self) -> None:
        self._span_start: tuple[float, float, float, float] | None = None
        self._run = 0

    def add(self, t: float, pose: FloatArray) -> bool:
        x, y, th = (float(v) for v in pose[:3])
        ref = self._span_start
        if ref is None or t < ref[0]:
            self._span_start = (float(t), x, y, th)
            return False
        if t - ref[0] < SPAN_S:
            return False
        self._span_start = (float(t), x, y, th)
        mid = ref[3] + 0.5 * wrap_scalar(th - ref[3])
        across = -math.sin(mid) * (x - ref[1]) + math.cos(mid) * (y - ref[2])
        self._run = self._run + 1 if abs(across) > SIDEWAYS_M else 0
        return self._run >= IN_A_ROW
