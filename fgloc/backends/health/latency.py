"""The scans' latency, one home for both back-ends: configured, or estimated from pairs of fixes
(:class:`ScanLatency`: the pairs collected, evaluated against the back-end's reference motion,
:class:`LatencyReference`), by a robust fit (:class:`LatencyEstimator`); and the time-series
helpers it uses (:func:`median_period`, :func:`bracket`, :func:`fix_speed`)."""

from __future__ import annotations

import math
from bisect import bisect_left, bisect_right, insort
from collections import deque
from operator import itemgetter, sub
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from fgloc.geometry import wrap_scalar

FloatArray = NDArray[np.float64]
#: s: a latency reference (gyro, odometry) slower than this (~17 Hz) cannot resolve a lag of tens of
#: ms (the motion inside one of its periods is not known): it gives no pairs (the odometry also
#: de-skews the scans: a slow odometry bends the fixes in turns)
MAX_REF_PERIOD_S = 0.06
#: a fix pair: (t_a, t_b, pose_a, pose_b, cov_a, cov_b)
FixPair = tuple[float, float, FloatArray, FloatArray, FloatArray, FloatArray]
#: s: consecutive fixes at most this far apart make a latency pair (turns starting / ending)
SHORT_PAIR_S = 0.3
#: s: once a second, a fix and one this far before it (a start from standstill: the lag is v * latency)
LONG_PAIR_S = (0.8, 1.2)
#: s: a pair is evaluated once its later fix is this much older than the newest fix (the fixes'
#: own speed around it is known)
SETTLE_S = 0.25
#: s: distance pairs only this long or longer: a consecutive pair's few cm cannot tell a lag from slip
MIN_DISTANCE_PAIR_S = 0.5


class LatencyEstimator:
    """A source's constant time offset (its stamps this late) from how its pose increments lag.

    A fix stamped ``delta`` late shows the pose at ``t - delta``.  Over two fixes ``a, b`` its
    yaw change is the reference's (gyro / odometry, correctly stamped) over
    ``(t_a - delta, t_b - delta)``, i.e. ``r = d_fix - d_ref(t_a, t_b) ~= -delta (w_b - w_a)``,
    and likewise the distance driven with the speeds ``v``.  Only changes of motion (a turn
    starting or ending, a start from standstill) carry information, and only increments enter,
    so a compass offset or a map bias never does.  A scale error of the reference (``beta *
    d_ref``) is fitted alongside, so a wheel-radius error is not taken for a latency.  The fit
    is robust (Huber weights, iterated): wheel slip or a kidnapping makes a few pairs wrong, not
    the lag.  The latency is used once significant (``significance`` sigmas from zero, with at
    least ``min_pairs`` pairs): an undetectable latency is taken as none rather than as the
    noise of its estimate.
    """

    def __init__(self, min_pairs: int = 50, significance: float = 3.0, huber_k: float = 2.0,
                 var_floor: tuple[float, float] = (math.radians(0.1) ** 2, 0.003**2),
                 max_latency_s: float = 0.3, max_rows: int = 20000, refit_every: int = 25,
                 refit_share: float = 0.025) -> None:
        self.var_floor = (float(var_floor[0]), float(var_floor[1]))
        self.max_latency_s = float(max_latency_s)
        self.min_pairs = int(min_pairs)
        self.significance = float(significance)
        self.huber_k = float(huber_k)
        self.refit_every = int(refit_every)
        self.refit_share = float(refit_share)
        self.max_rows = int(max_rows)
        # the rows (x, r, var, ref, kind) in an array, appended in place: its last ``_nrows`` lines
        # are the newest ``max_rows`` pairs (40 B a row); the window plus an eighth (0.9 MB for 20000
        # rows), allocated and written at the first pair (resident from then on: a live session's memory
        # does not grow as it fills); the rows kept are moved to its front once it is full (every
        # ``max_rows / 8`` pairs)
        self._nrows = 0
        self._buf = np.empty((0, 5))
        self._nbuf = 0
        self.n = 0
        self.rejected = 0
        self._fit: tuple[int, float, float] | None = None   # (n, delta, sigma)
        self._fit_n = 0
        self._refit_after: float = 0   # refit once n - _fit_n reaches this (0: no fit yet)

    def add(self, x: float, r: float, var: float, ref: float = 0.0, kind: int = 0) -> None:
        """One pair: regressor ``x = -(rate_b - rate_a)``, residual ``r``, its variance, and the
        reference increment ``ref`` (``kind`` 0: a yaw pair, 1: a distance pair)."""
        if not (math.isfinite(x) and math.isfinite(r) and math.isfinite(var) and math.isfinite(ref)) or var <= 0:
            return
        # floors: a fix's own covariance leaves out the reference's noise and the map's
        var = max(var, self.var_floor[int(kind)])
        # no latency up to max_latency_s (and no scale error up to 10 %) explains this pair: a
        # kidnapping, a wrong fix; never evidence
        if abs(r) > self.max_latency_s * abs(x) + 0.1 * abs(ref) + 5.0 * math.sqrt(var):
            self.rejected += 1
            return
        row = (float(x), float(r), float(var), float(ref), int(kind))
        self._nrows = min(self._nrows + 1, self.max_rows)
        if not len(self._buf):
            self._buf = np.full((self.max_rows + max(self.max_rows // 8, 1), 5), 0.0)
        elif self._nbuf == len(self._buf):   # full: the rows still kept to the front
            k = self._nrows - 1
            self._buf[:k] = self._buf[self._nbuf - k:self._nbuf].copy()
            self._nbuf = k
        self._buf[self._nbuf] = row
        self._nbuf += 1
        self.n += 1

    def _refit(self) -> tuple[float, float]:
        # refit after refit_every new pairs, or once they are refit_share of the rows fitted: a refit reads
        # every row (up to max_rows), so a fixed count would make its cost grow with the log (quadratic)
        if self.n - self._fit_n < self._refit_after:   # (the threshold is the fit's: one test per call)
            return self._fit[1], self._fit[2]  # type: ignore[index]
        if not self._nrows:
            return 0.0, math.inf
        a = self._buf[self._nbuf - self._nrows:self._nbuf]
        A = np.zeros((len(a), 3))
        A[:, 0] = a[:, 0]
        kind = a[:, 4].astype(int)
        A[kind == 0, 1] = a[kind == 0, 3]
        A[kind == 1, 2] = a[kind == 1, 3]
        y = a[:, 1]
        s = np.sqrt(a[:, 2])
        w = np.ones(len(a))
        prior = np.diag([1e-9, 1e-2, 1e-2])  # the scale errors: a weak prior at 0 (10 %)
        sol: np.ndarray = np.zeros(3)
        N = prior
        for _ in range(6):
            Aw = A * (w / s)[:, None]
            yw = y * w / s
            N = Aw.T @ Aw + prior
            sol = np.linalg.solve(N, Aw.T @ yw)
            z = np.abs(y - A @ sol) / s
            w_new = np.sqrt(np.where(z <= self.huber_k, 1.0, self.huber_k / np.maximum(z, 1e-12)))
            if np.array_equal(w_new, w):
                break   # the same weights: every further iteration repeats this one exactly (the usual case:
                        # no pair beyond huber_k, the weights all 1 after the first)
            w = w_new
        res = (y - A @ sol) / s * w
        scale2 = max(float(res @ res) / max(len(a) - 3, 1), 1.0)
        sig = math.sqrt(scale2 * float(np.linalg.inv(N)[0, 0])) if N[0, 0] > 1e-8 else math.inf
        self._fit = (self.n, float(sol[0]), sig)
        self._fit_n = self.n
        # the fit holds until refit_every / refit_share new pairs; below min_pairs until any new one
        self._refit_after = max(self.refit_every, self.refit_share * min(self.n, self.max_rows)) \
            if self.n >= self.min_pairs else 1
        return self._fit[1], self._fit[2]

    def estimate(self) -> tuple[float, float]:
        """``(delta_s, sigma_s)`` of the robust fit (inf sigma before any information)."""
        return self._refit()

    def value(self) -> float:
        """The latency to correct for: the estimate once significant, else 0."""
        d, s = self.estimate()
        if self.n >= self.min_pairs and abs(d) > self.significance * s:
            return d
        return 0.0

    def settled(self, sigma_s: float = 0.005) -> bool:
        """Enough evidence to decide (significant, or known to within ``sigma_s``)."""
        d, s = self.estimate()
        return self.n >= self.min_pairs and (abs(d) > self.significance * s or s < sigma_s)


def fix_speed(fixes: Any, t: float, half_s: float = 0.2) -> float | None:
    """The speed (m/s) the fixes themselves show around ``t`` (over ``t +- half_s``), or None.

    A latency regressor from the fixes, not the odometry: wheel slip changes what the wheels
    report, never how fast the fixes move."""
    before = after = None
    for f in fixes:
        if f[0] <= t - half_s:
            before = f
        elif f[0] >= t + half_s and after is None:
            after = f
    if before is None or after is None or after[0] - before[0] > 4 * half_s:
        return None
    return float(np.hypot(after[1][0] - before[1][0], after[1][1] - before[1][1])) / (after[0] - before[0])


def bracket(series: deque, t: float) -> tuple[int, int]:
    """The indices ``lo, hi`` of the samples (tuples whose first item is the time, in time order)
    around ``t``: ``series[lo][0] <= t`` and ``hi = lo + 1`` (``0, 0`` for one sample).  The
    caller checks ``series[0][0] <= t <= series[-1][0]``.  (Bisection in C, keyed on the time:
    the last sample at or before ``t``, at most the last but one.)"""
    n = len(series)
    if n < 2:
        return 0, 0
    lo = max(min(bisect_right(series, t, key=_time) - 1, n - 2), 0)
    return lo, lo + 1


_time = itemgetter(0)


#: :func:`median_period`'s window: the spacings of its last this many stamps
PERIOD_STAMPS = 50


def median_period(ts: list[float]) -> float:
    """Median spacing of the last (50) stamps ``ts`` (inf with fewer than 3)."""
    if len(ts) < 3:
        return math.inf
    last = ts[-PERIOD_STAMPS:]
    d = sorted(map(sub, last[1:], last[:-1]))  # np.median's, without numpy's overhead
    m = len(d) // 2
    return float(d[m]) if len(d) % 2 else float((d[m - 1] + d[m]) / 2.0)


class StepMedian:
    """:func:`median_period` of one growing stamp list (strictly increasing; it only grows at its end
    and loses its oldest), kept up to date: each stamp appended since the last call swaps its spacing
    for the window's oldest in a sorted copy of the window (the same spacings, the same median,
    without sorting the window again at every call)."""

    __slots__ = ("ts", "last", "recent", "ordered")

    def __init__(self) -> None:
        self.ts: list[float] | None = None   # the list followed, its newest stamp at the last call
        self.last = math.nan
        self.recent: deque[float] = deque()  # the window's spacings, oldest first
        self.ordered: list[float] = []       # the same, sorted

    def of(self, ts: list[float]) -> float:
        """:func:`median_period` of ``ts``."""
        n = len(ts)
        w = PERIOD_STAMPS - 1
        if n < PERIOD_STAMPS:
            self.ts = None
            return median_period(ts)
        if self.ts is ts:
            j = bisect_left(ts, self.last)
            if j < n and ts[j] == self.last and n - 1 - j < w:
                recent, ordered = self.recent, self.ordered
                for i in range(j + 1, n):
                    d = ts[i] - ts[i - 1]
                    del ordered[bisect_left(ordered, recent.popleft())]
                    insort(ordered, d)
                    recent.append(d)
                self.last = ts[-1]
                return float(ordered[w // 2])
        last = ts[-PERIOD_STAMPS:]
        self.recent = deque(map(sub, last[1:], last[:-1]))
        self.ordered = sorted(self.recent)
        self.ts, self.last = ts, ts[-1]
        return float(self.ordered[w // 2])


class LatencyReference(Protocol):
    """A back-end's reference motion (its gyro / odometry, correctly stamped) for the latency pairs."""

    def reference_covered_until(self) -> float:
        """The stamp up to which every reference has readings."""
        ...

    def reference_periods(self) -> tuple[float, float]:
        """The median message periods (s) of the distance and of the yaw reference."""
        ...

    def reference_yaw(self, ta: float, tb: float) -> tuple[float, float, float] | None:
        """``(d_ref, x, var)``: the reference's yaw change over ``(ta, tb]``, the regressor
        ``x = -(rate_b - rate_a)`` and the variance it adds; None: not known there."""
        ...

    def reference_distance(self, ta: float, tb: float) -> tuple[float, float] | None:
        """``(distance, var)``: the reference's distance over ``(ta, tb]`` and the variance it adds."""
        ...


class ScanLatency:
    """The scans' latency: ``latency_s`` when configured, else (``on``) estimated from pairs of
    fixes (:meth:`add_fix`) against a reference's motion (:meth:`evaluate`), used once significant."""

    def __init__(self, on: bool, latency_s: float | None) -> None:
        self.on = bool(on)
        self.latency_s = latency_s
        self.est = LatencyEstimator()
        self.recent_fixes: deque[tuple[float, FloatArray, FloatArray]] = deque(maxlen=64)
        self._fixes_in_order = True   # every recent fix later than the one before it (bisection finds them)
        self.pairs: list[FixPair] = []
        self._long_pair_t = -math.inf

    @property
    def estimated(self) -> bool:
        """Whether the latency is estimated (on, and not configured)."""
        return self.on and self.latency_s is None

    def value(self) -> float:
        """The latency (s) in use: configured, estimated once significant, or 0."""
        if self.latency_s is not None:
            return float(self.latency_s)
        return self.est.value() if self.on else 0.0

    def fit(self) -> tuple[float, float] | None:
        """The estimator's ``(estimate s, sigma s)`` once its sigma is finite, else None."""
        est, sig = self.est.estimate()
        return (float(est), float(sig)) if math.isfinite(sig) else None

    def add_fix(self, t: float, pose: FloatArray, cov: FloatArray) -> None:
        """A fix used at scan stamp ``t``: a pair with the previous fix (within :data:`SHORT_PAIR_S`)
        and, once a second, with one :data:`LONG_PAIR_S` before it."""
        if not self.estimated:
            return
        pose, cov = np.array(pose, dtype=float), np.array(cov, dtype=float)
        recent = self.recent_fixes
        if recent and 0.0 < t - recent[-1][0] <= SHORT_PAIR_S:
            f = recent[-1]
            self.pairs.append((f[0], t, f[1], pose, f[2], cov))
        if t - self._long_pair_t >= 1.0:
            old = [f for f in recent if LONG_PAIR_S[0] <= t - f[0] <= LONG_PAIR_S[1]]
            if old:
                f = old[0]
                self.pairs.append((f[0], t, f[1], pose, f[2], cov))
                self._long_pair_t = t
        if recent and not t >= recent[-1][0]:
            self._fixes_in_order = False
        recent.append((t, pose, cov))

    def _fix_speed(self, t: float, half_s: float = 0.2) -> float | None:
        """:func:`fix_speed` of the recent fixes: the two it reads found by bisection while they are in
        time order (the last at or before ``t - half_s``, the first at or after ``t + half_s``)."""
        fixes = self.recent_fixes
        if not self._fixes_in_order:
            return fix_speed(fixes, t, half_s)
        i = bisect_right(fixes, t - half_s, key=_time) - 1
        j = bisect_left(fixes, t + half_s, key=_time)
        if i < 0 or j >= len(fixes):
            return None
        before, after = fixes[i], fixes[j]
        if after[0] - before[0] > 4 * half_s:
            return None
        return float(np.hypot(after[1][0] - before[1][0], after[1][1] - before[1][1])) / (after[0] - before[0])

    def evaluate(self, ref: LatencyReference) -> None:
        """The pairs the reference now covers into the estimator: a yaw pair (the fixes' yaw change
        against the reference's) where the yaw reference is fast enough, and a distance pair (the
        regressor from the fixes' own speeds: immune to wheel slip) where the pair is long enough."""
        if not self.estimated:
            self.pairs.clear()
            return
        if not self.pairs:
            return
        covered = ref.reference_covered_until()
        last_fix = self.recent_fixes[-1][0] if self.recent_fixes else -math.inf
        periods: tuple[float, float] | None = None
        keep = []
        for pair in self.pairs:
            ta, tb, pa, pb, ca, cb = pair
            if tb > covered or tb > last_fix - SETTLE_S:
                keep.append(pair)
                continue
            if periods is None:
                periods = ref.reference_periods()
            if periods[0] > MAX_REF_PERIOD_S:
                continue
            if periods[1] <= MAX_REF_PERIOD_S:
                y = ref.reference_yaw(ta, tb)
                if y is not None:
                    d_ref, x, var = y
                    r = wrap_scalar(float(pb[2] - pa[2]) - d_ref)
                    self.est.add(x, r, float(ca[2, 2] + cb[2, 2]) + var, d_ref, 0)
            if tb - ta < MIN_DISTANCE_PAIR_S:
                continue
            dist = ref.reference_distance(ta, tb)
            if dist is None:
                continue
            dist_ref, var = dist
            dist_fix = float(np.hypot(pb[0] - pa[0], pb[1] - pa[1]))
            var_d = float(ca[0, 0] + ca[1, 1] + cb[0, 0] + cb[1, 1]) / 2 + var
            va, vb = self._fix_speed(ta), self._fix_speed(tb)
            if va is not None and vb is not None:
                self.est.add(-(vb - va), dist_fix - dist_ref, var_d, dist_ref, 1)
        self.pairs = keep
