"""Device clock -> host clock alignment (offset + drift), robust to transport jitter.

Each received message gives a pair ``(t_dev, t_rx)``: the device timestamp in seconds
(MCU microseconds / 1e6, unwrapped; or the laser's "time of transmission") and the
host arrival time.  The observed difference ``d = t_rx - t_dev`` is

    d = offset + drift * (t_dev - t_ref) + delay,    delay >= 0

where ``delay`` is the (jittery, always positive) transport + OS latency.  A
*minimum-delay filter* keeps, per ``bin_s`` of device time, the smallest ``d`` (the
sample that travelled fastest, closest to the true offset), and fits a line through
the last ``n_bins`` bin minima by least squares: the intercept is the offset, the
slope the drift (clock rate error).  Until two bins exist the running minimum
alone is used (offset only).  A mapped host time is never later than the arrival
time of the message it belongs to (causality clamp).

Pure maths: no I/O.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np


@dataclass
class ClockSync:
    """Minimum-delay offset + drift estimator.  Times in seconds."""

    bin_s: float = 1.0
    n_bins: int = 30
    max_drift: float = 1e-3  # |drift| above 1000 ppm is rejected as implausible
    _bins: deque[tuple[float, float]] = field(default_factory=deque)  # (t_dev, d_min)
    _cur_start: float | None = None
    _cur_best: tuple[float, float] | None = None
    _offset: float | None = None  # host - dev at t_ref
    _drift: float = 0.0
    _t_ref: float = 0.0
    n_samples: int = 0

    def reset(self) -> None:
        self._bins.clear()
        self._cur_start = None
        self._cur_best = None
        self._offset = None
        self._drift = 0.0
        self.n_samples = 0

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

    def update(self, t_dev: float, t_rx: float) -> None:
        """Add one observation (device time, host arrival time)."""
        d = t_rx - t_dev
        self.n_samples += 1
        if self._cur_start is None:
            self._cur_start = t_dev
        if self._cur_best is None or d < self._cur_best[1]:
            self._cur_best = (t_dev, d)
        if t_dev - self._cur_start >= self.bin_s:
            self._bins.append(self._cur_best)
            while len(self._bins) > self.n_bins:
                self._bins.popleft()
            self._cur_start = t_dev
            self._cur_best = (t_dev, d)
            self._fit()
        elif len(self._bins) < 2:
            # warm-up: the running minimum is the best offset estimate we have
            best = min([b[1] for b in self._bins] + [self._cur_best[1]])
            self._offset, self._t_ref, self._drift = best, t_dev, 0.0

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
        """Map a device time to host time (clamped to ``t_rx`` when given)."""
        if self._offset is None:
            return t_dev if t_rx is None else t_rx
        h = t_dev + self._offset + self._drift * (t_dev - self._t_ref)
        if t_rx is not None and h > t_rx:
            h = t_rx
        return h
