"""Whether the fused heading still follows the heading sources it fuses.

A smoother going wrong leaves its own inputs: its heading turns away from the gyro's integral,
the wheels' and the compass's all at once (it follows none of them), where a filter or a smoother
that is right follows at least one of them within the noise that source claims.  Each keyframe
hands :class:`HeadingConsistency` the fused heading and what each heading source says about it:
a relative source (gyro, wheels) its increment since the previous keyframe and its variance, an
absolute one (compass, IMU orientation, the scan fixes) its reading and variance.  Over a
sliding window the fused heading's change is compared with each source's change over the same
keyframes; the smallest disagreement, in units of that source's sigma over the window (floored
by ``floor_rad``: a source claiming less than that is still allowed that much), is the
*divergence* over that window; over several windows (``windows_s``: a fast departure and a slow
one) the largest.  Above ``threshold`` the fused heading follows none of its sources (until it
comes down to half of that).

Core maths only: no I/O.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from dataclasses import dataclass

from fgloc.geometry import wrap_scalar

#: a source's value at a keyframe: (cumulative heading, cumulative variance) for a relative source,
#: (unwrapped reading, its variance) for an absolute one
_Value = tuple[float, float]


@dataclass(frozen=True)
class HeadingDivergence:
    """The fused heading against its sources over the window ending at ``t``."""

    t: float
    window_s: float
    nearest: str          # the source the fused heading's change is closest to (in its sigmas)
    off_rad: float        # the fused heading's change minus that source's change
    score: float          # |off_rad| / that source's sigma over the window (floored)

    @property
    def off_deg(self) -> float:
        return math.degrees(self.off_rad)


class HeadingConsistency:
    """The fused heading's divergence from its heading sources, keyframe by keyframe."""

    def __init__(self, windows_s: tuple[float, ...] = (20.0, 120.0), threshold: float = 4.0,
                 floor_rad: float = math.radians(2.0), check_every_s: float = 0.5) -> None:
        self.windows_s = tuple(sorted(float(w) for w in windows_s))
        self.check_every_s = float(check_every_s)   # the windows are compared this often (log time)
        self._checked = -math.inf
        self.threshold = float(threshold)
        self.floor_rad = float(floor_rad)
        # per keyframe: stamps, unwrapped fused headings, {source: value} (the longest window's)
        self._t: list[float] = []
        self._f: list[float] = []
        self._v: list[dict[str, _Value]] = []
        self._cum: dict[str, _Value] = {}
        self._relative: set[str] = set()
        self._since: dict[str, float] = {}   # per relative source: the first keyframe of its current unbroken run
        self._abs_last: dict[str, float] = {}   # per absolute source: its last reading, unwrapped
        self._fused: float | None = None
        self._last_yaw = 0.0
        self.latest: HeadingDivergence | None = None
        self.worst: HeadingDivergence | None = None
        #: s of log time during which the divergence was above the threshold, and how many spans
        self.diverged_s = 0.0
        self.spans = 0
        self._over_since: float | None = None

    def add(self, t: float, fused_yaw: float, increments: dict[str, tuple[float, float]],
            readings: dict[str, tuple[float, float]]) -> HeadingDivergence | None:
        """A keyframe at ``t`` with the fused heading ``fused_yaw`` (rad), each relative source's
        ``(increment, variance)`` since the previous keyframe and each absolute source's
        ``(reading, variance)`` at ``t``; the worst over the windows ending here of the fused
        heading's divergence from its nearest source, every ``check_every_s`` (None in between
        and while no source covers a window)."""
        t = float(t)
        if self._fused is None:
            self._fused = float(fused_yaw)
        else:
            self._fused += wrap_scalar(float(fused_yaw) - self._last_yaw)
        self._last_yaw = float(fused_yaw)
        prev = self._v[-1] if self._v else {}
        row: dict[str, _Value] = {}
        for name, (d, v) in increments.items():
            self._relative.add(name)
            c, cv = self._cum.get(name, (0.0, 0.0)) if name in prev else (0.0, 0.0)
            row[name] = self._cum[name] = (c + float(d), cv + float(v))
        for name in row:
            if name not in prev:   # a relative source that missed the previous keyframe: no gap is bridged
                self._since[name] = t
        for name, (y, v) in readings.items():
            # an absolute source's change between any two of its readings holds across a keyframe it missed
            p = self._abs_last.get(name)
            row[name] = (float(y) if p is None else p + wrap_scalar(float(y) - p), float(v))
            self._abs_last[name] = row[name][0]
            self._since.setdefault(name, t)
        self._t.append(t)
        self._f.append(self._fused)
        self._v.append(row)
        horizon = t - self.windows_s[-1]
        if len(self._t) > 64 and self._t[32] < horizon:   # trim, keeping the longest window's first keyframe
            cut = bisect_right(self._t, horizon) - 1
            if cut > 0:
                del self._t[:cut], self._f[:cut], self._v[:cut]
        if t - self._checked < self.check_every_s:
            return None
        self._checked = t
        got: HeadingDivergence | None = None
        for w in self.windows_s:
            i = bisect_right(self._t, t - w) - 1
            if i < 0:
                break
            b = self._nearest(i, t, row)
            if b is not None and (got is None or b.score > got.score):
                got = b
        if got is None:
            return None
        self.latest = got
        if self.worst is None or got.score > self.worst.score:
            self.worst = got
        if got.score > self.threshold:
            if self._over_since is None:
                self._over_since = t
                self.spans += 1
        elif self._over_since is not None and got.score <= 0.5 * self.threshold:   # hysteresis: no flicker
            self.diverged_s += t - self._over_since
            self._over_since = None
        return got

    def _nearest(self, i: int, t: float, row: dict[str, _Value]) -> HeadingDivergence | None:
        """The source whose change since keyframe ``i`` the fused heading's is nearest (in its sigmas)."""
        t0, f0, row0 = self._t[i], self._f[i], self._v[i]
        df = (self._fused or 0.0) - f0
        floor2 = self.floor_rad * self.floor_rad
        best: tuple[float, str, float] | None = None
        for name in (*row, *(n for n in self._abs_last if n not in row)):
            got = row0.get(name)
            if name in self._relative:
                if got is None or self._since.get(name, t) > t0:
                    continue
                y1, v1 = row[name]
                var, d0 = v1 - got[1], df
            else:   # an absolute source: from its first reading in the window to its last
                j0, j1 = i, len(self._t) - 1
                while got is None and j0 < j1:
                    j0 += 1
                    got = self._v[j0].get(name)
                last = self._v[j1].get(name)
                while last is None and j1 > j0:
                    j1 -= 1
                    last = self._v[j1].get(name)
                if got is None or last is None or j1 <= j0:
                    continue
                (y1, v1), var = last, last[1] + got[1]
                d0 = self._f[j1] - self._f[j0]
            off = d0 - (y1 - got[0])
            score = abs(off) / math.sqrt(max(var, 0.0) + floor2)
            if best is None or score < best[0]:
                best = (score, name, off)
        return None if best is None else HeadingDivergence(t, t - t0, best[1], best[2], best[0])

    def restart(self) -> None:
        """The estimate was re-initialized (a jump of its own): compare from here on, totals kept."""
        if self._over_since is not None and self._t:
            self.diverged_s += self._t[-1] - self._over_since
        self._over_since = None
        self._t.clear()
        self._f.clear()
        self._v.clear()
        self._cum.clear()
        self._since.clear()
        self._abs_last.clear()
        self._fused = None
        self._checked = -math.inf
        self.latest = None

    def diverging(self) -> bool:
        """The fused heading follows none of its sources: its divergence went above ``threshold``
        and has not come down to half of it since."""
        return self._over_since is not None

    def diverged_total_s(self, t: float | None = None) -> float:
        """Log time (s) spent diverging, the current span up to ``t`` (or its start) included."""
        extra = 0.0 if self._over_since is None or t is None else max(float(t) - self._over_since, 0.0)
        return self.diverged_s + extra
