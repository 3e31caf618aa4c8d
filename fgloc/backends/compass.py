"""Compass-to-map heading offset calibration.

A real compass reads heading against magnetic north (or whatever its last
recalibration chose), not against the map's x axis; the paper assumes the two
agree.  We calibrate the offset ``compass_yaw = map_yaw + offset`` from the first
accepted map fixes: each fix is paired with the compass reading nearest in time
(within ``max_dt`` s, moved to the fix stamp with the compass yaw rate), and once
``n_fixes`` pairs are collected the offset is their circular median (robust to a
bad first fix); later fixes keep refining it as a running mean (the last ~500 fixes).
Until then a back-end uses the compass yaw rate only.  The
smoother keeps estimating the offset online as a slowly varying variable; the
EKF keeps this fixed value.
"""

from __future__ import annotations

from bisect import bisect_left
from collections import deque

import numpy as np

from fgloc.geometry import wrap_angle, wrap_scalar


class CompassCalibrator:
    """Collects (compass, map) heading pairs and returns the offset once calibrated."""

    def __init__(self, n_fixes: int = 5, max_dt: float = 0.1, offset: float | None = None,
                 refine: bool = True, max_window: int = 500, gate: float = float(np.deg2rad(3.0))) -> None:
        self.gate = float(gate)
        self.n_fixes = int(n_fixes)
        self.refine = bool(refine)
        self.max_window = int(max_window)
        self._n = 0
        self.max_dt = float(max_dt)
        self.offset: float | None = offset
        self._compass: deque[tuple[float, float, float]] = deque(maxlen=200)
        self._stamps: deque[float] = deque(maxlen=200)
        self._in_order = 0  # readings appended in stamp order since the last one out of order
        self._diffs: list[float] = []

    @property
    def calibrated(self) -> bool:
        return self.offset is not None

    @property
    def has_readings(self) -> bool:
        """Whether any compass reading has been seen (kept: the last 200)."""
        return bool(self._compass)

    def add_compass(self, t: float, yaw: float, rate: float | None) -> None:
        if self._compass and t < self._compass[-1][0]:
            self._in_order = 0
        else:
            self._in_order += 1
        self._compass.append((float(t), float(yaw), float(rate) if rate is not None else 0.0))
        self._stamps.append(float(t))

    def compass_at(self, t: float) -> float | None:
        """Compass yaw (compass frame) at ``t`` from the nearest reading within ``max_dt`` (the
        earliest of equally near ones)."""
        if not self._compass:
            return None
        if self._in_order >= len(self._compass):  # every kept reading in stamp order: bisect
            ts = self._stamps
            i = bisect_left(ts, t)
            if i == len(ts) or (i > 0 and t - ts[i - 1] <= ts[i] - t):
                i = bisect_left(ts, ts[i - 1])
            best = self._compass[i]
        else:
            best = min(self._compass, key=lambda c: abs(c[0] - t))
        if abs(best[0] - t) > self.max_dt:
            return None
        return wrap_scalar(best[1] + best[2] * (t - best[0]))

    def add_fix(self, t: float, map_yaw: float) -> bool:
        """Pair an accepted map fix with the compass; returns True when this calibrates.

        After calibration every further pair refines the offset as a running mean (weight
        ``1/n``, at least ``1/max_window``: slow drift is followed), unless ``refine`` is off.
        """
        c = self.compass_at(t)
        if c is None:
            return False
        d = wrap_scalar(c - map_yaw)
        if self.calibrated:
            # a pair far from the current offset is a disturbance, not drift: ignored
            if self.refine and self.offset is not None and abs(wrap_scalar(d - self.offset)) < self.gate:
                self._n += 1
                w = max(1.0 / self._n, 1.0 / self.max_window)
                self.offset = wrap_scalar(self.offset + w * wrap_scalar(d - self.offset))
            return False
        self._diffs.append(d)
        if len(self._diffs) >= self.n_fixes:
            ds = np.asarray(self._diffs)
            ref = float(np.arctan2(np.mean(np.sin(ds)), np.mean(np.cos(ds))))
            self.offset = float(wrap_angle(ref + np.median(wrap_angle(ds - ref))))
            self._n = len(self._diffs)
            return True
        return False

    def to_map(self, compass_yaw: float) -> float | None:
        """Compass yaw converted to the map frame, or None before calibration."""
        if self.offset is None:
            return None
        return float(wrap_angle(compass_yaw - self.offset))
