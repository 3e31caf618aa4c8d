"""Device clock -> host clock alignment (offset + drift), robust to transport jitter and to steps.

Each received message gives a pair ``(t_dev, t_rx)``: the device timestamp in seconds
(MCU microseconds / 1e6, unwrapped; the laser's "time of transmission"; a ROS header stamp)
and the host arrival time.  The observed difference ``d = t_rx - t_dev`` is

    d = offset + drift * (t_dev - t_ref) + delay,    delay >= 0

where ``delay`` is the (jittery, always positive) transport + OS latency.  A
*minimum-delay filter* keeps, per ``bin_s`` of device time, the smallest ``d`` (the
sample that travelled fastest, closest to the true offset), and fits a line through
the last ``n_bins`` bin minima by least squares: the intercept is the offset, the
slope the drift (clock rate error).  Until two bins exist the running minimum
alone is used (offset only).  A mapped host time is never later than the arrival
time of the message it belongs to (causality clamp).

Steps.  A device clock can jump while its messages go on (a microcontroller reset or re-flash
that keeps its sequence counter, a scanner re-synchronised, a host clock stepped by NTP under a
ROS driver).  Against the anchor line a sample's residual ``r = d - line(t_dev)`` is its delay
above the fastest, never negative; after a step of ``S`` seconds it is ``delay - S``.  Two
signs, each about the device clock alone (no other sensor is needed):

* the device time goes backwards (a step back of more than one message period), or the residual
  is below ``-step_tol_s`` (a step forward: the message would have arrived before it was sent;
  in the first two bins, while the offset is a running minimum, a lower ``d`` is simply taken).
  The sample is *suspect*: it is stamped by its own arrival (never by the old anchor) and kept
  out of the filter; the next sample decides.  If it agrees with the suspect's offset (within
  ``step_tol_s``) the step is confirmed; if it fits the old anchor the suspect was a lone bad
  stamp (``outliers``);
* every residual over ``confirm_s`` of arrival time (and at least ``confirm_n`` samples) is
  above ``step_tol_s`` and above twice the 95th percentile of the residuals before (the link's
  own jitter), and they spread no more than that jitter (their median minus their minimum: a
  loaded host delays every message of a thread it starves by a wandering 30-260 ms for a second
  or more, measured with the emulators beside a starting Ray instance; a step adds a constant):
  a step back smaller than the message period, or one made while the link was silent.  A
  transport stall cannot look like this: the backlog it leaves arrives in a burst whose last
  samples are on time again.  Not in the warm-up (no line, no jitter known yet).  The samples of
  that window were stamped through the old anchor, early by the step: they are the step's
  affected span.

A confirmed step re-anchors: the filter restarts from the samples after the step (the drift
estimate is kept), and a :class:`ClockStep` is recorded; its size is measured again against the
fastest sample of each of the first :data:`REFINE_BINS` bins after it (``steps``: found with two
samples, a step's size carries their delay, 0.4 s on a host so loaded that every thread waited
that long).  :meth:`ClockSync.continuous` gives
the device time with the steps taken out, for intervals measured across one (wheel counts
over a frame period).

Pure maths: no I/O.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field, replace

import numpy as np

#: the steps kept for reporting (the count in ``n_steps`` goes on)
MAX_STEPS_KEPT = 32
#: a step is measured again over this many bins after it (its size: the largest of the measures)
REFINE_BINS = 5


@dataclass(frozen=True)
class ClockStep:
    """A step of a device clock against the host's, found and re-anchored."""

    step_s: float              #: the device clock's jump (negative: it went back)
    device_s: float            #: the device time of the first sample after the step
    host_s: float              #: that sample's arrival (host time)
    detected_host_s: float     #: arrival of the sample that confirmed it
    affected: int              #: samples stamped through the old anchor before it was found (0: none)
    affected_from_host_s: float  #: the first of them (host time; NaN when none)

    def describe(self) -> str:
        """One line: the step, when, and what it cost."""
        span = (f"{self.affected} samples before it was found stamped {abs(self.step_s):.3f} s "
                f"{'early' if self.step_s < 0 else 'late'} (arrivals "
                f"{self.affected_from_host_s:.3f}..{self.detected_host_s:.3f})" if self.affected
                else "no sample stamped through the old anchor")
        return (f"device clock stepped {self.step_s:+.3f} s (at device time {self.device_s:.3f} s, "
                f"found {1e3 * (self.detected_host_s - self.host_s):.0f} ms later); re-anchored, {span}")


@dataclass
class ClockSync:
    """Minimum-delay offset + drift estimator with step detection.  Times in seconds."""

    bin_s: float = 1.0
    n_bins: int = 30
    max_drift: float = 1e-3  # |drift| above 1000 ppm is rejected as implausible
    step_tol_s: float = 0.03  # a residual beyond this (either way) may be a step
    confirm_s: float = 1.0    # residuals above the threshold for this long (arrival time) are a step
    confirm_n: int = 5        # and for at least this many samples
    jitter_n: int = 256       # the residuals the jitter's percentile is taken over (at least 50 of them)
    _bins: deque[tuple[float, float]] = field(default_factory=deque)  # (t_dev, d_min)
    _cur_start: float | None = None
    _cur_best: tuple[float, float] | None = None
    _offset: float | None = None  # host - dev at t_ref
    _drift: float = 0.0
    _t_ref: float = 0.0
    n_samples: int = 0
    n_steps: int = 0
    outliers: int = 0
    steps: deque[ClockStep] = field(default_factory=lambda: deque(maxlen=MAX_STEPS_KEPT))
    _step_total: float = 0.0  # sum of the confirmed steps since the last reset
    _last_dev: float | None = None
    _suspect: tuple[float, float, float] | None = None  # (t_dev, t_rx, residual)
    _high: list[tuple[float, float, float]] = field(default_factory=list)  # (t_dev, t_rx, residual) all > tol
    _high_jitter: float = 0.0  # the 95th percentile of the residuals before the window in _high
    _resid: deque[float] = field(default_factory=deque)  # recent residuals of the samples fed
    _refine: tuple[ClockStep, float, float, float] | None = None  # the last step and the anchor before it
    _refine_bins: int = 0

    def reset(self) -> None:
        """Forget everything about the device clock (the device restarted)."""
        self._restart()
        self._offset = None
        self._drift = 0.0
        self.n_samples = 0
        self._step_total = 0.0
        self._last_dev = None

    def _restart(self) -> None:
        self._resid.clear()
        self._bins.clear()
        self._cur_start = None
        self._cur_best = None
        self._suspect = None
        self._high.clear()

    @property
    def ready(self) -> bool:
        return self._offset is not None

    @property
    def offset(self) -> float:
        """Current host - device offset at the newest reference (s)."""
        return float("nan") if self._offset is None else self._offset

    @property
    def drift_ppm(self) -> float:
        return self._drift * 1e6

    @property
    def suspect(self) -> bool:
        """Whether the newest sample is held as a possible step (stamped by its arrival)."""
        return self._suspect is not None

    def _line(self, t_dev: float) -> float:
        assert self._offset is not None
        return self._offset + self._drift * (t_dev - self._t_ref)

    def update(self, t_dev: float, t_rx: float) -> ClockStep | None:
        """Add one observation (device time, host arrival time); a confirmed step is returned."""
        self.n_samples += 1
        if self._offset is None:
            self._feed(t_dev, t_rx)
            return None
        r = (t_rx - t_dev) - self._line(t_dev)
        if self._suspect is not None:
            s_dev, s_rx, s_r = self._suspect
            if t_dev >= s_dev and abs(r - s_r) <= self.step_tol_s:
                # the device clock did step: the suspect and this sample share the new offset
                step = ClockStep(-min(s_r, r), s_dev, s_rx, t_rx, 0, math.nan)
                self._reanchor(step, [(s_dev, s_rx), (t_dev, t_rx)])
                return step
            if r >= -self.step_tol_s and (self._last_dev is None or t_dev >= self._last_dev):
                self.outliers += 1  # a lone bad stamp: this sample fits the old anchor
                self._suspect = None
            else:
                self._suspect = (t_dev, t_rx, r)  # another inconsistent one: it decides with the next
                return None
        elif (r < -self.step_tol_s and len(self._bins) >= 2) or (self._last_dev is not None and t_dev < self._last_dev):
            # (in the warm-up the offset is a running minimum of a few samples: a lower one is a faster
            # sample, taken as the minimum at once)
            self._suspect = (t_dev, t_rx, r)
            return None
        if r > self.step_tol_s and len(self._bins) >= 2 and len(self._resid) >= 50:
            if not self._high:
                self._high_jitter = float(np.percentile(self._resid, 95))
            if r <= max(self.step_tol_s, 2.0 * self._high_jitter):
                self._high.clear()
            else:
                self._high.append((t_dev, t_rx, r))
            if len(self._high) >= self.confirm_n and t_rx - self._high[0][1] >= self.confirm_s:
                lo = min(self._high, key=lambda s: s[2])
                spread = float(np.median([h[2] for h in self._high])) - lo[2]
                if spread > max(0.005, 2.0 * self._high_jitter):
                    # late by a wandering amount, not by a constant one: a starved reader, not a step
                    self._high.clear()
                    self._feed(t_dev, t_rx)
                    return None
                first = self._high[0]
                step = ClockStep(-lo[2], first[0], first[1], t_rx, len(self._high), first[1])
                self._reanchor(step, [(lo[0], lo[1])])
                return step
        else:
            self._high.clear()
        if not self._high:
            self._resid.append(max(r, 0.0))
            if len(self._resid) > self.jitter_n:
                self._resid.popleft()
        self._feed(t_dev, t_rx)
        return None

    def _reanchor(self, step: ClockStep, samples: list[tuple[float, float]]) -> None:
        self._refine, self._refine_bins = None, 0
        if self._offset is not None:
            self._refine = (step, self._offset, self._drift, self._t_ref)
        self._restart()
        self._step_total += step.step_s
        self.n_steps += 1
        self.steps.append(step)
        self._offset = None  # the warm-up (running minimum) starts over from these samples
        for t_dev, t_rx in sorted(samples):
            self._feed(t_dev, t_rx)

    def _feed(self, t_dev: float, t_rx: float) -> None:
        d = t_rx - t_dev
        self._last_dev = t_dev
        if self._cur_start is None:
            self._cur_start = t_dev
        if self._cur_best is None or d < self._cur_best[1]:
            self._cur_best = (t_dev, d)
        if t_dev - self._cur_start >= self.bin_s:
            self._bins.append(self._cur_best)
            if self._refine is not None:
                self._refined(*self._cur_best)
                self._refine_bins += 1
                if self._refine_bins >= REFINE_BINS:
                    self._refine = None
            while len(self._bins) > self.n_bins:
                self._bins.popleft()
            self._cur_start = t_dev
            self._cur_best = (t_dev, d)
            self._fit()
        elif len(self._bins) < 2:
            # warm-up: the running minimum is the best offset estimate we have
            best = min([b[1] for b in self._bins] + [self._cur_best[1]])
            self._offset, self._t_ref = best, t_dev  # (the drift: 0 from a reset, kept through a step)

    def _refined(self, t_b: float, d_min: float) -> None:
        """The step measured again as each of the first :data:`REFINE_BINS` bins after it completes:
        its fastest sample against the old anchor.  Every measure is the step less a delay (a lower
        bound), the first one too: the largest is kept.  The kept record only (the stamps and
        :meth:`continuous` already went on with the first measure)."""
        step, off, drift, t_ref = self._refine  # type: ignore[misc]
        size = off + drift * (t_b - step.step_s - t_ref) - d_min
        for i, s in enumerate(self.steps):
            if s is step and size > s.step_s:
                self.steps[i] = replace(s, step_s=size)
                self._refine = (self.steps[i], off, drift, t_ref)

    def _fit(self) -> None:
        pts = list(self._bins)
        if len(pts) < 2:
            return
        t = np.array([p[0] for p in pts])
        d = np.array([p[1] for p in pts])
        t_ref = float(t[-1])
        tt = t - t_ref
        # robust: drop bins whose minimum sits far above the lower envelope
        for _ in range(2):
            a = np.vstack([np.ones_like(tt), tt]).T
            coef, *_ = np.linalg.lstsq(a, d, rcond=None)
            res = d - a @ coef
            thr = max(3.0 * float(np.median(np.abs(res - np.median(res)))) * 1.4826, 1e-4)
            keep = res <= thr
            if keep.all() or keep.sum() < 2:
                break
            tt, d = tt[keep], d[keep]
        off, drift = float(coef[0]), float(coef[1])
        if abs(drift) > self.max_drift:
            drift = 0.0
            off = float(np.min(d))
        # the line must stay at or below the envelope: shift down to the lowest bin residual
        low = float(np.min(d - (off + drift * tt)))
        self._offset = off + min(low, 0.0)
        self._drift = drift
        self._t_ref = t_ref

    def to_host(self, t_dev: float, t_rx: float | None = None) -> float:
        """Map a device time to host time (clamped to ``t_rx`` when given).  While the newest sample
        is suspect (a possible step), the mapping is that sample's own offset (its arrival)."""
        if self._suspect is not None:
            s_dev, s_rx, _ = self._suspect
            h = t_dev + (s_rx - s_dev)
        elif self._offset is None:
            return t_dev if t_rx is None else t_rx
        else:
            h = t_dev + self._line(t_dev)
        if t_rx is not None and h > t_rx:
            h = t_rx
        return h

    def continuous(self, t_dev: float) -> float:
        """The device time with the steps taken out (the one held as suspect included), for an
        interval measured across a step."""
        held = -self._suspect[2] if self._suspect is not None else 0.0
        return t_dev - self._step_total - held
