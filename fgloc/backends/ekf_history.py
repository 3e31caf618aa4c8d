"""The EKF's measurements in stamp order: a late one is put in its place and the later ones re-applied.

A filter applies each measurement at its own stamp.  One older than the filter time (odometry whose
driver delivers it 0.3 s after its stamp, an IMU in bursts, a scan stamped late) cannot be applied
there without going back: applied at the filter time instead, a late odometry twist sets the velocity
the robot had 0.3 s ago as today's, the pose runs on with it while the robot accelerates or brakes,
and the filter's covariance, updated by every twist as if it were current, stays as small as ever.
Its fixes then lie outside its own gate (and the jump gate's prediction): they are rejected while
the pose drifts.

:class:`InOrder` keeps the filter's state before each measurement of the last ``history_s`` seconds,
with a function that applies that measurement again.  A measurement stamped before the filter time
but within the history is applied after the state the filter had at its stamp, and every later one is
applied again on top of it (as robot_localization's ``smooth_lagged_data`` does).  Each measurement
keeps the decision taken when it arrived (used or gated): replaying re-applies what was used, in
order, so the counters and the calibrations fed on arrival stay true.  Older than the history (or
across a change of the state's layout: a calibration state added, the switch to the omni state, a
restart) it is applied at the filter time as before (counted late).

Core maths only: no I/O.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeVar

import numpy as np

from fgloc.backends.ekf import EKF

R = TypeVar("R")


@dataclass
class _State:
    """The filter's time, state and covariance, and the layout they have."""

    t: float | None
    x: np.ndarray
    P: np.ndarray
    layout: tuple[int, bool]


@dataclass
class _Entry:
    t: float                       # the filter time after the measurement (its stamp, or later when it was late)
    before: _State                 # the filter before it
    replay: Callable[[], None]     # applies it again as decided on arrival
    record: float | None           # an online pose stamped here follows it (revised when it is re-applied)


class InOrder:
    """Measurements applied to ``ekf`` in stamp order over the last ``history_s`` seconds (module docstring).

    :meth:`apply` runs a measurement; :attr:`revised` maps the stamps of online poses recorded after a
    measurement (:meth:`apply`'s ``record``) to the pose and covariance the filter has there once later
    arrivals were put in their places."""

    def __init__(self, ekf: EKF, history_s: float) -> None:
        self.ekf = ekf
        self.history_s = float(history_s)
        self._entries: deque[_Entry] = deque()
        self._stamps: deque[float] = deque()
        self.revised: dict[float, tuple[np.ndarray, np.ndarray]] = {}
        self.stats = {"reordered": 0, "replayed": 0, "late": 0}

    def _layout(self) -> tuple[int, bool]:
        return self.ekf.n, bool(self.ekf.omni)

    def _state(self) -> _State:
        e = self.ekf
        return _State(e.t, e.x.copy(), e.P.copy(), self._layout())

    def _restore(self, s: _State) -> None:
        self.ekf.t, self.ekf.x, self.ekf.P = s.t, s.x.copy(), s.P.copy()

    def clear(self) -> None:
        """Forget the history (the filter was restarted or its state changed layout)."""
        self._entries.clear()
        self._stamps.clear()

    def _where(self, t: float) -> int | None:
        """The index of the first entry after stamp ``t`` whose state before is not after ``t``; None when
        ``t`` is not older than the filter time (apply now) ... or older than the history reaches (-1)."""
        ft = self.ekf.t
        if ft is None or t >= ft:
            return None
        if self.history_s <= 0 or not self._entries or self._entries[-1].before.layout != self._layout():
            return -1
        k = bisect_right(self._stamps, t)
        if k == len(self._entries):
            return -1  # the filter was carried past t without a recorded measurement
        b = self._entries[k].before.t
        return k if b is not None and b <= t else -1

    def in_history(self, t: float) -> bool:
        """Whether a measurement stamped ``t`` is applied at its stamp (not older than the history)."""
        return self._where(float(t)) != -1

    def apply(self, t: float, first: Callable[[], R], replay: Callable[[R], None],
              record: float | None = None) -> R:
        """Apply a measurement stamped ``t``: ``first()`` on arrival (it predicts the filter to ``t`` and
        decides), ``replay(result)`` each time it must be applied again after a late arrival before it.
        ``record``: the stamp of an online pose recorded right after it."""
        t = float(t)
        if self._entries and self._entries[-1].before.layout != self._layout():
            self.clear()
        k = self._where(t)
        later: list[_Entry] = []
        if k is not None and k >= 0:
            later = [self._entries[i] for i in range(k, len(self._entries))]
            for _ in range(len(self._entries) - k):
                self._entries.pop()
                self._stamps.pop()
            self._restore(later[0].before)
            self.stats["reordered"] += 1
        elif k == -1:
            self.stats["late"] += 1
        before = self._state()
        out = first()
        after = self.ekf.t if self.ekf.t is not None else t
        self._push(_Entry(after, before, lambda: replay(out), record))
        # online poses recorded after a measurement: revised from the state before the next one
        pending = [] if k is None or k < 0 or record is None else [record]
        for e in later:
            self._revise(pending, e.t)
            s = self._state()
            e.replay()
            self.stats["replayed"] += 1
            self._push(_Entry(self.ekf.t if self.ekf.t is not None else e.t, s, e.replay, e.record))
            if e.record is not None:
                pending.append(e.record)
        self._revise(pending, math.inf)
        self._trim()
        return out

    def _revise(self, pending: list[float], until: float) -> None:
        """The filter's pose at each of ``pending`` not after ``until`` (the next measurement's stamp)."""
        ft = self.ekf.t
        keep = []
        for r in pending:
            if r > until:
                keep.append(r)
            elif ft is not None and ft <= r:
                self.revised[r] = self.ekf.predict_pose(r)
        pending[:] = keep

    def _push(self, e: _Entry) -> None:
        if self.history_s <= 0:
            return
        if e.before.layout != self._layout():  # the measurement changed the layout: nothing before it replays
            self.clear()
            return
        self._entries.append(e)
        self._stamps.append(e.t)

    def _trim(self) -> None:
        if not self._stamps:
            return
        cut = self._stamps[-1] - self.history_s
        while len(self._stamps) > 1 and self._stamps[0] < cut:
            self._entries.popleft()
            self._stamps.popleft()
        if len(self.revised) > 4 * len(self._stamps) + 64:
            oldest = self._stamps[0] - self.history_s
            self.revised = {k: v for k, v in self.revised.items() if k >= oldest}

    def revise(self, stamps: np.ndarray, poses: np.ndarray, covs: np.ndarray | None) -> None:
        """Replace, in place, the poses (and covariances) at ``stamps`` that later arrivals revised."""
        if not self.revised:
            return
        index = {float(s): i for i, s in enumerate(stamps)}
        for s, (p, c) in self.revised.items():
            i = index.get(s)
            if i is not None and math.isfinite(s):
                poses[i] = p
                if covs is not None:
                    covs[i] = c


__all__ = ["InOrder"]
