"""Sensors that check each other: per-source noise from the sources' disagreement, and health.

The back-ends weight each source by the noise it *shows*, not only by what its messages
claim.  :class:`Arbiter` compares the increments several sources give for one quantity (the
yaw change: wheel odometry, gyro, IMU orientation, scan fixes; or the distance driven) over
fixed blocks of time (``block_s``).  A rate source (a yaw rate, a speed) is integrated over
the block, an absolute source (a heading, a position) is differenced across it, so a
compass offset or a map frame never enters.  For every pair of sources ``a, b`` seen in a
block, ``(d_a - d_b)^2`` estimates ``var_a + var_b`` (the two sources' errors are
independent): with three or more sources the pairs determine every source's own variance
(the "N-cornered hat" of clock metrology), so when two disagree, the one the third agrees
with keeps its weight and the other is down-weighted.  With only two sources the excess is
shared in proportion to their priors (claimed noise; ``rel_prior`` for the motion-
proportional part).

Each source's noise is modelled as ``var = k^2 * claimed + c^2 * increment^2``: ``k >= 1``
inflates what the messages claim (estimated on blocks with little motion), ``c`` is a
fraction of the motion (a skid-steer's scrub, a wheel's slip, a gyro's scale error;
estimated on blocks with motion).  Both are exponentially weighted means over the last
``halflife_blocks`` / ``halflife_moving_blocks`` blocks; one block adds at most ``cap``
times the current estimate, so a short genuine disturbance (a +25 deg compass step, 3 s of
wheel slip) moves them little while a persistent disagreement takes over within a minute.
The back-ends still reject short disturbances with their robust kernels and gates.

:class:`SourceHealth` counts each source's accepted, gated and skipped inputs and carries
what the back-end estimated about it (scale, bias, latency) for the run summary and the
live status line.  Core maths only: no I/O.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from collections import deque
from dataclasses import dataclass, field
from operator import itemgetter
from typing import Any

import numpy as np

from fgloc.geometry import wrap_scalar

RATE, INSTANT_RATE, ABSOLUTE, ANGLE_ABSOLUTE = "rate", "instant_rate", "absolute", "angle"


@dataclass
class _Stream:
    kind: str
    t: deque = field(default_factory=lambda: deque(maxlen=4000))
    v: deque = field(default_factory=lambda: deque(maxlen=4000))
    var: deque = field(default_factory=lambda: deque(maxlen=4000))
    gain: float = 1.0
    gain_ref: float = 1.0          # the gain when the motion statistics last restarted
    bias: float = 0.0
    rel_prior: float = 0.02
    claimed_mean: float = 0.0      # EW mean of the claimed per-block variance
    n_claimed: int = 0


class Arbiter:
    """Per-source noise of one scalar quantity from pairwise disagreement (see the module docstring)."""

    def __init__(self, block_s: float = 0.125, still: float = 0.00625, moving: float = 0.025,
                 halflife_blocks: float = 480.0, halflife_moving_blocks: float = 80.0,
                 min_blocks: int = 20, min_moving_blocks: int = 8, cap: float = 100.0,
                 settle_s: float = 0.3, max_gap_s: float = 0.25, k_min: float = 0.1, rel_trusted: float = 0.03,
                 history: int = 20000, long_blocks: tuple[int, ...] = ()) -> None:
        self.block_s = float(block_s)
        self.still = float(still)
        self.moving = float(moving)
        self.halflife_blocks = float(halflife_blocks)
        self.a_still = 1.0 - 0.5 ** (1.0 / halflife_blocks)
        self.a_moving = 1.0 - 0.5 ** (1.0 / halflife_moving_blocks)
        self.min_blocks = int(min_blocks)
        self.min_moving_blocks = int(min_moving_blocks)
        self.cap = float(cap)
        self.settle_s = float(settle_s)
        self.max_gap_s = float(max_gap_s)
        self.k_min = float(k_min)
        self.rel_trusted = float(rel_trusted)
        self.solve_every = max(1, int(round(1.0 / self.block_s)))  # re-solve the hat once a second
        self.history = int(history)
        self.streams: dict[str, _Stream] = {}
        self._t0: float | None = None
        self._next_block = 0
        # pair statistics: EW means and counts
        self._still: dict[tuple[str, str], list[float]] = {}    # [mean r^2, n]
        self._moving: dict[tuple[str, str], list[float]] = {}   # [mean (r / d)^2, n]
        self._var: dict[str, float] = {}     # per-block absolute variance estimate
        self._rel: dict[str, float] = {}     # relative noise estimate (fraction of the motion)
        self.blocks = 0
        # the same still-block statistics over longer blocks (``long_blocks`` blocks each): what a
        # source shows over the block_s blocks leaves out its slowly varying errors
        self.long_blocks = tuple(sorted({int(m) for m in long_blocks if int(m) > 1}))
        self._recent: deque[tuple[int, dict[str, tuple[float, float]]]] = deque(
            maxlen=max(self.long_blocks, default=1))
        self._still_long: dict[int, dict[tuple[str, str], list[float]]] = {m: {} for m in self.long_blocks}
        self._claimed_long: dict[int, dict[str, list[float]]] = {m: {} for m in self.long_blocks}
        self._var_long: dict[int, dict[str, float]] = {m: {} for m in self.long_blocks}    # resolved
        # the long blocks' statistics changes (a long block is complete every m blocks, the hat is
        # solved every second: _solve re-solves a long block's hat only when they changed)
        self._long_changes: dict[int, int] = dict.fromkeys(self.long_blocks, 0)
        self._long_solved: dict[int, int] = dict.fromkeys(self.long_blocks, -1)

    # ------------------------------------------------------------------ inputs
    def add_source(self, name: str, kind: str, rel_prior: float = 0.02) -> None:
        if name not in self.streams:
            self.streams[name] = _Stream(kind, deque(maxlen=self.history), deque(maxlen=self.history),
                                         deque(maxlen=self.history), rel_prior=float(rel_prior))

    def add_reading(self, name: str, kind: str, rel_prior: float, t: float, value: float, var: float) -> None:
        """A sample of source ``name``, registered (:meth:`add_source`) at its first one."""
        self.add_source(name, kind, rel_prior)
        self.add(name, t, value, var)

    def add(self, name: str, t: float, value: float, var: float) -> None:
        """A sample: a rate (rate sources) or an absolute value (absolute / angle sources)."""
        s = self.streams.get(name)
        if s is None or not (math.isfinite(t) and math.isfinite(value)):
            return
        if s.t and t <= s.t[-1]:
            return
        if self._t0 is None:
            self._t0 = float(t)
        s.t.append(float(t))
        s.v.append(float(value))
        s.var.append(float(var) if math.isfinite(var) and var > 0 else 0.0)

    def set_correction(self, name: str, gain: float = 1.0, bias: float = 0.0) -> None:
        """A rate source's current calibration: ``true = gain * (reported - bias)``."""
        s = self.streams.get(name)
        if s is not None and math.isfinite(gain) and math.isfinite(bias):
            s.gain, s.bias = float(gain), float(bias)
            if abs(s.gain / s.gain_ref - 1.0) > 0.05:
                # the calibration moved: what the source showed before is not what it shows now
                s.gain_ref = s.gain
                for p, mv in self._moving.items():
                    if name in p:
                        mv[1] = min(mv[1], 1.0)

    # ------------------------------------------------------------------ increments
    def increment(self, name: str, t0: float, t1: float) -> tuple[float, float] | None:
        """A source's (corrected) increment over ``(t0, t1]`` and its claimed variance, or None."""
        s = self.streams.get(name)
        if s is None or not s.t:
            return None
        ts = s.t
        if s.kind == RATE:  # a reading is the mean rate since the previous one (wheel odometry)
            if ts[0] > t0 + self.max_gap_s or ts[-1] < t1:
                return None
            i = bisect_right(ts, t0)
            d = var = 0.0
            t = t0
            n = len(ts)
            while t < t1 - 1e-12 and i < n:
                tn = min(ts[i], t1)
                dt = tn - t
                if dt > self.max_gap_s:
                    return None
                d += (s.v[i] - s.bias) * dt
                var += s.var[i] * dt * dt
                t = tn
                i += 1
            return s.gain * d, s.gain * s.gain * var
        if s.kind == INSTANT_RATE:
            # a reading is the rate at its stamp (a gyro): linear between readings, integrated exactly
            if ts[0] > t0 or ts[-1] < t1:
                return None
            # (the variance squares each reading's whole weight in the block: a reading between two
            # sub-intervals is one error, counted once; w_a^2 + w_b^2 claimed the gyro ~1.4x
            # better than it is, in sigma, and its excess was put on the other sources)
            i = max(bisect_right(ts, t0) - 1, 0)
            n = len(ts)
            d = var = 0.0
            w_prev = 0.0   # the weight reading i has so far
            while i < n - 1 and ts[i] < t1:
                ta, tb = ts[i], ts[i + 1]
                a, b = max(ta, t0), min(tb, t1)
                wj = 0.0
                if b > a:
                    h = tb - ta
                    if h > self.max_gap_s:
                        return None
                    fa, fb = (a - ta) / h, (b - ta) / h
                    wj = (b - a) * 0.5 * (fa + fb)
                    wi = (b - a) - wj
                    d += wi * (s.v[i] - s.bias) + wj * (s.v[i + 1] - s.bias)
                    w_prev += wi
                var += w_prev * w_prev * s.var[i]
                w_prev = wj
                i += 1
            var += w_prev * w_prev * s.var[i]
            return s.gain * d, s.gain * s.gain * var
        a = self._value_at(s, t0)
        b = self._value_at(s, t1)
        if a is None or b is None:
            return None
        d = b[0] - a[0]
        if s.kind == ANGLE_ABSOLUTE:
            d = wrap_scalar(d)
        return d, a[1] + b[1]

    def _value_at(self, s: _Stream, t: float) -> tuple[float, float] | None:
        ts = s.t
        i = bisect_right(ts, t)
        if i == 0 or i >= len(ts):
            if i == len(ts) and ts and t - ts[-1] <= self.max_gap_s * 0.2:
                return s.v[-1], s.var[-1]
            return None
        ta, tb = ts[i - 1], ts[i]
        if tb - ta > self.max_gap_s:
            return None
        va, vb = s.v[i - 1], s.v[i]
        dv = wrap_scalar(vb - va) if s.kind == ANGLE_ABSOLUTE else vb - va
        f = (t - ta) / (tb - ta) if tb > ta else 0.0
        return va + f * dv, (1 - f) * s.var[i - 1] + f * s.var[i]

    # ------------------------------------------------------------------ blocks
    def update(self, now: float) -> int:
        """Process the blocks complete by ``now`` (every source has had time to arrive); returns how many."""
        if self._t0 is None:
            return 0
        done = 0
        while True:
            b0 = self._t0 + self._next_block * self.block_s
            b1 = b0 + self.block_s
            if now < b1 + self.settle_s:
                return done
            self._next_block += 1
            self._block(b0, b1, self._next_block - 1)
            done += 1

    def _block(self, t0: float, t1: float, index: int = 0) -> None:
        inc: dict[str, tuple[float, float]] = {}
        for name in self.streams:
            got = self.increment(name, t0, t1)
            if got is not None:
                inc[name] = got
        if self.long_blocks:
            self._recent.append((index, inc))
            for m in self.long_blocks:
                if (index + 1) % m == 0:
                    self._long_block(m)
        if len(inc) < 2:
            return
        self.blocks += 1
        for name, (_, v) in inc.items():
            s = self.streams[name]
            s.n_claimed += 1
            s.claimed_mean += (v - s.claimed_mean) / min(s.n_claimed, 240)
        mag = _median_abs(inc)
        names = sorted(inc)
        for i, a in enumerate(names):
            for b in names[i + 1:]:
                r = inc[a][0] - inc[b][0]
                if mag < self.still:
                    _still_stat(self._still.setdefault((a, b), [0.0, 0.0]), r, inc[a][1] + inc[b][1],
                                self.cap, self.a_still)
                elif mag > self.moving:
                    mv = self._moving.setdefault((a, b), [0.0, 0.0])
                    base = (self._abs_var(a, inc[a][1]) + self._abs_var(b, inc[b][1])) / (mag * mag)
                    prior = self.streams[a].rel_prior ** 2 + self.streams[b].rel_prior ** 2
                    ref = max(mv[0], prior) if mv[1] else prior
                    z = max(min((r / mag) ** 2, self.cap * ref) - base, 0.0)
                    mv[1] += 1
                    w = max(self.a_moving, 1.0 / mv[1])
                    mv[0] += w * (z - mv[0])
        if self.blocks % self.solve_every == 0 or self.blocks < 4 * self.solve_every:
            self._solve()

    def _long_block(self, m: int) -> None:
        """The still-block statistics over the last ``m`` blocks (one long block): a source's
        increment is the sum of its block increments (it must have all ``m``); its claimed
        variance the sum (a rate source's errors add up) or the ends' (an absolute source's)."""
        last = list(self._recent)[-m:]
        if len(last) < m or last[-1][0] - last[0][0] != m - 1:
            return
        inc: dict[str, tuple[float, float]] = {}
        for name, s in self.streams.items():
            parts = [b[1][name] for b in last if name in b[1]]
            if len(parts) < m:
                continue
            d = float(sum(p[0] for p in parts))
            if s.kind in (RATE, INSTANT_RATE):
                v = float(sum(p[1] for p in parts))
            else:
                d = wrap_scalar(d) if s.kind == ANGLE_ABSOLUTE else d
                v = 0.5 * (parts[0][1] + parts[-1][1])
            inc[name] = (d, v)
        if len(inc) < 2 or _median_abs(inc) >= self.still * m:
            return
        claimed = self._claimed_long[m]
        a_still = 1.0 - 0.5 ** (m / self.halflife_blocks)  # the same half-life in seconds
        for name, (_, v) in inc.items():
            c = claimed.setdefault(name, [0.0, 0.0])
            c[1] += 1
            c[0] += (v - c[0]) / min(c[1], 240.0)
        names = sorted(inc)
        stats = self._still_long[m]
        self._long_changes[m] += 1
        for i, a in enumerate(names):
            for b in names[i + 1:]:
                _still_stat(stats.setdefault((a, b), [0.0, 0.0]), inc[a][0] - inc[b][0], inc[a][1] + inc[b][1],
                            self.cap, a_still)

    def _abs_var(self, name: str, claimed: float) -> float:
        v = self._var.get(name)
        return claimed if v is None else max(v, claimed)

    def _solve(self) -> None:
        names = sorted(self.streams)
        still = {p: st[0] for p, st in self._still.items() if st[1] >= self.min_blocks}
        n_still = {p: min(st[1], 2.0 / self.a_still) for p, st in self._still.items()}
        self._var = cornered_hat(names, still, {n: self.streams[n].claimed_mean for n in names}, n_still)
        moving = {p: mv[0] for p, mv in self._moving.items() if mv[1] >= self.min_moving_blocks}
        n_mov = {p: min(mv[1], 2.0 / self.a_moving) for p, mv in self._moving.items()}
        rel = cornered_hat(names, moving, {n: self.streams[n].rel_prior ** 2 for n in names}, n_mov)
        self._rel = {n: math.sqrt(v) for n, v in rel.items()}
        for m in self.long_blocks:
            if self._long_solved[m] == self._long_changes[m]:
                continue   # the same statistics: the same answer
            self._long_solved[m] = self._long_changes[m]
            st_m = self._still_long[m]
            n_max = 2.0 / (1.0 - 0.5 ** (m / self.halflife_blocks))
            pairs = {p: st[0] for p, st in st_m.items() if st[1] >= self.min_blocks}
            n_m = {p: min(st[1], n_max) for p, st in st_m.items()}
            self._var_long[m] = cornered_hat(names, pairs, {}, n_m, unresolved="omit")

    # ------------------------------------------------------------------ outputs
    def noise(self, name: str) -> tuple[float, float]:
        """``(k, c)`` of a source: its claimed variance times ``k^2`` plus ``(c * increment)^2``."""
        s = self.streams.get(name)
        if s is None:
            return 1.0, 0.0
        v = self._var.get(name)
        rel = float(self._rel.get(name, 0.0))
        k = 1.0
        if v is not None and s.claimed_mean > 0:
            # better than claimed only for a source seen moving without motion-proportional errors
            # (a wheel that scrubs in turns is no precision yaw sensor, however quiet it is straight)
            # and never for an absolute source: short increments do not show its slowly varying
            # errors (a compass's magnetic distortion, a map's bias)
            k_min = self.k_min if rel < self.rel_trusted and s.kind in (RATE, INSTANT_RATE) else 1.0
            k = math.sqrt(max(k_min**2, v / s.claimed_mean))
        return k, rel

    def shown_k(self, name: str) -> float:
        """How much better (< 1) or worse (> 1) than claimed a source's errors are, in sigma: the
        largest ``sqrt(shown / claimed variance)`` over the ``block_s`` blocks and the long blocks
        (``long_blocks``, where they resolve the source), at least ``k_min``; 1 before there is
        evidence.  For an absolute source (a heading) the long blocks are what shows a slowly
        varying error (a magnetic distortion, a map error that changes along the way): the short
        blocks leave it out.  (:meth:`noise` keeps an absolute source at its claim or worse.)"""
        s = self.streams.get(name)
        v = self._var.get(name)
        if s is None or v is None or s.claimed_mean <= 0:
            return 1.0
        k2 = v / s.claimed_mean
        for m in self.long_blocks:
            vm, cm = self._var_long[m].get(name), self._claimed_long[m].get(name)
            if vm is not None and cm is not None and cm[0] > 0:
                k2 = max(k2, vm / cm[0])
        return math.sqrt(max(k2, self.k_min**2))

    def shown_sigma(self, name: str) -> float | None:
        """The per-block standard deviation the source showed (None before there is evidence)."""
        v = self._var.get(name)
        return None if v is None else math.sqrt(max(v, 0.0))

    def claimed_sigma(self, name: str) -> float | None:
        s = self.streams.get(name)
        return None if s is None or not s.n_claimed else math.sqrt(max(s.claimed_mean, 0.0))


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


def _median_abs(inc: dict[str, tuple[float, float]]) -> float:
    """The median of the increments' magnitudes (np.median's, without its overhead)."""
    mags = sorted(abs(d) for d, _ in inc.values())
    m = len(mags) // 2
    return float(mags[m]) if len(mags) % 2 else float((mags[m - 1] + mags[m]) / 2.0)


def _still_stat(st: list[float], r: float, claimed: float, cap: float, a: float) -> None:
    """One still block's squared pair difference ``r^2`` into the EW mean ``st = [mean, n]``
    (at most ``cap`` times the current mean or the claim: a disturbance moves it little)."""
    ref = max(st[0], claimed, 1e-12) if st[1] else claimed + 1e-12
    z = min(r * r, cap * ref)
    st[1] += 1
    w = max(a, 1.0 / st[1])
    st[0] += w * (z - st[0])


def cornered_hat(names: list[str], pairs: dict[tuple[str, str], float],
                 prior: dict[str, float], n_eff: dict[tuple[str, str], float] | None = None,
                 unresolved: str = "prior") -> dict[str, float]:
    """Per-source variances ``v`` with ``v_a + v_b ~= pairs[(a, b)]``, ``v >= 0`` (least squares).

    A source the pairs cannot separate from another (two sources alone, or a third source far
    noisier than the two: its pairs' statistics are too uncertain, judged from ``n_eff``
    blocks each) keeps its prior (claimed) variance, but never more than any pair it is in
    allows (``v_a <= pairs[(a, b)]``): evidence that it is better than claimed is used,
    evidence of which of two is worse is not invented.

    Each connected group of sources is a least-squares problem ``A v = y`` whose rows hold two
    ones (a pair): a handful of unknowns, solved in scalar maths through its normal equations
    ``A^T A`` (integer entries: a group is separable exactly when they are regular, i.e. its pairs
    close an odd cycle); the standard deviations of the solution from ``(A^T A)^-1 A^T`` and the
    pairs' own.  Only a solution with a negative part goes through the non-negative active set
    (:func:`_nnls_normal`).  (numpy's SVD,
    pseudo-inverse and least squares on these 3x3 to 6x4 systems cost ~0.25 ms per call, the
    arbiter solves two or three a second.)
    """
    if not pairs:
        return {}
    n_eff = n_eff or {}
    plist = tuple(pairs)
    groups = _GROUPS.get(plist)
    if groups is None:  # the connected groups and each one's source indices: once per pair set
        srcs = sorted({s for p in pairs for s in p})
        groups = [(members, {s: i for i, s in enumerate(members)}) for members in _components(srcs, list(plist))]
        if len(_GROUPS) > 256:
            _GROUPS.clear()
        _GROUPS[plist] = groups
    out: dict[str, float] = {}
    for members, loc in groups:
        n = len(members)
        rows = [(loc[a], loc[b], float(pairs[(a, b)]), float(pairs[(a, b)])
                 * math.sqrt(2.0 / max(n_eff.get((a, b), 1e9), 1.0))) for (a, b) in plist if a in loc]
        rhs = [0.0] * n
        ub = [math.inf] * n
        for a, b, yv, _ in rows:
            rhs[a] += yv
            rhs[b] += yv
            ub[a] = min(ub[a], yv)
            ub[b] = min(ub[b], yv)
        N, inv, wsq = _hat_system(n, tuple((a, b) for a, b, _, _ in rows))
        v = [math.nan] * n
        if inv is not None:
            v = [sum(inv[i][j] * rhs[j] for j in range(n)) for i in range(n)]
            if not all(x > 0.0 for x in v):
                v = _nnls_normal(N, rhs, len(rows))
            sd2 = [0.0] * n
            for (_, _, _, sig), wr in zip(rows, wsq, strict=True):
                s2 = sig * sig
                for m in range(n):
                    sd2[m] += wr[m] * s2
            for m, s_name in enumerate(members):
                if math.sqrt(max(sd2[m], 0.0)) > 0.5 * max(v[m], prior.get(s_name, 0.0)):
                    v[m] = math.nan  # not resolved
        for m, s_name in enumerate(members):
            if math.isfinite(v[m]):
                val = v[m]
            elif unresolved == "prior":
                val = prior.get(s_name, 0.0)
            else:
                continue
            out[s_name] = max(min(val, ub[m]), 0.0)
    return out


_HAT_SYSTEMS: dict[tuple[int, tuple[tuple[int, int], ...]], tuple] = {}
_GROUPS: dict[tuple[tuple[str, str], ...], list[tuple[list[str], dict[str, int]]]] = {}


def _hat_system(n: int, rows: tuple[tuple[int, int], ...]) -> tuple[list[list[float]], list[list[float]] | None,
                                                                   list[list[float]]]:
    """A pair set's normal matrix ``N = A^T A`` (``rows``: each pair's two source indices), its
    inverse (None when singular) and per row the squared weights ``(inv[m][a] + inv[m][b])^2`` of
    its pair in each source's solution: they depend on which pairs there are only, not on their
    values (the arbiter solves the same few sets once a second), so they are made once per set."""
    key = (n, rows)
    got = _HAT_SYSTEMS.get(key)
    if got is None:
        N = [[0.0] * n for _ in range(n)]
        for a, b in rows:
            N[a][a] += 1.0
            N[b][b] += 1.0
            N[a][b] += 1.0
            N[b][a] += 1.0
        inv = _spd_inverse(N)
        wsq = [[(inv[m][a] + inv[m][b]) * (inv[m][a] + inv[m][b]) for m in range(n)] for a, b in rows] \
            if inv is not None else []
        if len(_HAT_SYSTEMS) > 256:
            _HAT_SYSTEMS.clear()
        got = _HAT_SYSTEMS[key] = (N, inv, wsq)
    return got


def _nnls_normal(N: list[list[float]], rhs: list[float], n_rows: int) -> list[float]:
    """``argmin |A v - y|`` with ``v >= 0`` (Lawson-Hanson's active set, as scipy.optimize's ``nnls``;
    importing scipy.optimize cost 0.3-1.3 s of CPU per process) on the normal equations ``N = A^T A``,
    ``rhs = A^T y`` of a full-column-rank ``A`` with ``n_rows`` rows of zeros and ones, in scalar
    maths: each step's least squares on the active columns is ``N_SS z_S = rhs_S``."""
    n = len(N)
    x = [0.0] * n
    z = [0.0] * n
    active = [False] * n
    tol = 10.0 * _EPS * max(N[i][i] for i in range(n)) * max(n_rows, n)
    for _ in range(3 * n + 3):
        w = [rhs[i] - sum(N[i][j] * x[j] for j in range(n)) for i in range(n)]
        free = [i for i in range(n) if not active[i]]
        if not free:
            break
        j = max(free, key=lambda i: w[i])  # the first of equal maxima, as np.argmax
        if w[j] <= tol:
            break
        active[j] = True
        for _ in range(3 * n + 3):
            S = [i for i in range(n) if active[i]]
            zs = _spd_solve([[N[a][b] for b in S] for a in S], [rhs[a] for a in S])
            z = [0.0] * n
            for a, za in zip(S, zs, strict=True):
                z[a] = za
            if all(za > 0.0 for za in zs):
                break
            alpha = min(x[i] / (x[i] - z[i]) for i in S if z[i] <= 0.0)
            x = [xi + alpha * (zi - xi) for xi, zi in zip(x, z, strict=True)]
            active = [active[i] and x[i] > tol for i in range(n)]
        x = z
    return [max(xi, 0.0) for xi in x]


_EPS = float(np.finfo(float).eps)


def _cholesky(N: list[list[float]], tol: float | None) -> list[list[float]] | None:
    """The lower Cholesky factor of a small symmetric matrix (scalar maths).  ``tol`` None: a pivot
    is clamped at 1e-300 (positive definite by construction); else None when one is not above ``tol``."""
    n = len(N)
    L = [[0.0] * n for _ in range(n)]
    for j in range(n):
        d = N[j][j] - sum(L[j][k] * L[j][k] for k in range(j))
        if tol is None:
            d = max(d, 1e-300)
        elif not d > tol:
            return None
        L[j][j] = math.sqrt(d)
        for i in range(j + 1, n):
            L[i][j] = (N[i][j] - sum(L[i][k] * L[j][k] for k in range(j))) / L[j][j]
    return L


def _spd_solve(N: list[list[float]], b: list[float]) -> list[float]:
    """``N^-1 b`` for a small symmetric positive definite ``N`` (Cholesky, scalar maths)."""
    n = len(N)
    L = _cholesky(N, None)
    assert L is not None
    y = [0.0] * n
    for i in range(n):
        y[i] = (b[i] - sum(L[i][k] * y[k] for k in range(i))) / L[i][i]
    out = [0.0] * n
    for i in reversed(range(n)):
        out[i] = (y[i] - sum(L[k][i] * out[k] for k in range(i + 1, n))) / L[i][i]
    return out


def _spd_inverse(N: list[list[float]]) -> list[list[float]] | None:
    """The inverse of a small symmetric positive semi-definite matrix (Cholesky, scalar maths),
    None when it is singular (a pivot below 1e-9 of the largest diagonal entry)."""
    n = len(N)
    L = _cholesky(N, 1e-9 * max(N[i][i] for i in range(n)))
    if L is None:
        return None
    # L^-1 by forward substitution, then N^-1 = L^-T L^-1
    Li = [[0.0] * n for _ in range(n)]
    for i in range(n):
        Li[i][i] = 1.0 / L[i][i]
        for j in range(i):
            Li[i][j] = -sum(L[i][k] * Li[k][j] for k in range(j, i)) / L[i][i]
    return [[sum(Li[k][i] * Li[k][j] for k in range(max(i, j), n)) for j in range(n)] for i in range(n)]


def _components(srcs: list[str], pairs: list[tuple[str, str]]) -> list[list[str]]:
    parent = {s: s for s in srcs}

    def find(s: str) -> str:
        while parent[s] != s:
            parent[s] = parent[parent[s]]
            s = parent[s]
        return s

    for a, b in pairs:
        parent[find(a)] = find(b)
    groups: dict[str, list[str]] = {}
    for s in srcs:
        groups.setdefault(find(s), []).append(s)
    return list(groups.values())


@dataclass
class SourceHealth:
    """What one input source did during a run (accepted / gated / skipped and the estimates)."""

    name: str
    kind: str
    accepted: int = 0
    gated: int = 0
    skipped: int = 0
    skipped_reasons: dict[str, int] = field(default_factory=dict)
    estimates: dict[str, float] = field(default_factory=dict)

    def skip(self, reason: str) -> None:
        self.skipped += 1
        self.skipped_reasons[reason] = self.skipped_reasons.get(reason, 0) + 1

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"kind": self.kind, "accepted": self.accepted, "gated": self.gated,
                               "skipped": self.skipped}
        if self.skipped_reasons:
            out["skipped_reasons"] = dict(self.skipped_reasons)
        out.update({k: float(v) for k, v in self.estimates.items()})
        return out


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
        self.rows: deque[tuple[float, float, float, float, int]] = deque(maxlen=int(max_rows))
        # the rows as an array, appended in place (the fit read them all through np.asarray, every
        # refit: O(rows) Python objects converted again); its last len(rows) lines are the rows
        self._buf = np.empty((64, 5))
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
        self.rows.append(row)
        if self._nbuf == len(self._buf):
            keep = self._buf[self._nbuf - len(self.rows) + 1:self._nbuf]   # the rows still kept
            self._buf = np.empty((max(64, 2 * len(keep) + 2), 5))
            self._buf[:len(keep)] = keep
            self._nbuf = len(keep)
        self._buf[self._nbuf] = row
        self._nbuf += 1
        self.n += 1

    def _refit(self) -> tuple[float, float]:
        # refit after refit_every new pairs, or once they are refit_share of the rows fitted: a refit reads
        # every row (up to max_rows), so a fixed count made its cost grow with the log (quadratic)
        if self.n - self._fit_n < self._refit_after:   # (the threshold is the fit's: one test per call)
            return self._fit[1], self._fit[2]  # type: ignore[index]
        if not self.rows:
            return 0.0, math.inf
        a = self._buf[self._nbuf - len(self.rows):self._nbuf]
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


MAX_GYRO_GAP_S = 0.5  # a longer gap between gyro readings breaks the integral


class GyroBias:
    """One gyro's bias (rad/s), from what observes it without the wheels.

    A wheel's yaw rate cannot tell a gyro's bias from its own scrub or slip: a skid steer
    whose wheels report 0.5 rad/s while driving straight would be read as a 0.5 rad/s gyro
    bias (robot_localization's Jackal bag: 0.32 rad/s, when the bias was an EKF state beside
    the wheels' yaw-rate scale).  The bias is therefore estimated from

    * absolute headings (an IMU's orientation, a compass, scan-to-map fixes): per heading
      source ``i`` an offset ``c_i`` = its yaw minus the gyro's raw integral ``G(t)``, which
      drifts as ``dc_i/dt = -b``; state ``[b, c_1, ..., c_n]``, measurement
      ``z = yaw_i(t) - G(t) = c_i``.  Only increments matter (a source's heading frame never
      enters); ``offset_q`` lets a source's own slow errors (magnetic distortion, an AHRS's
      drift) wander, on top of the gyro's angle random walk;
    * standstill: while the wheels report no motion (``still_s`` in a row), each gyro reading
      measures ``b`` itself.

    A heading source's readings share its slowly varying errors: each counts for its variance
    times the inflation its innovations show over ``window_s`` windows (:meth:`_shared`).

    Robust: an innovation beyond ``huber_k`` sigmas is down-weighted (Huber), beyond
    ``reject_k`` it is not used; a source rejected for ``reanchor_s`` in a row (a lasting
    magnetic disturbance, a re-initialized AHRS) is re-anchored instead of pulling the bias.
    Headings are processed once the gyro covers their stamp (bursty IMUs, late fixes), at most
    ``max_rate_hz`` per source (consecutive readings of one source share their slow errors).
    Core maths only.
    """

    def __init__(self, prior_sigma: float = 0.02, rw: float = 2e-5, offset_q: float = 1e-7,
                 huber_k: float = 3.0, reject_k: float = 8.0, reanchor_s: float = 5.0,
                 still_s: float = 0.3, max_rate_hz: float = 20.0, history: int = 8000,
                 window_s: float = 2.0) -> None:
        self.rw = float(rw)
        self.offset_q = float(offset_q)
        self.huber_k = float(huber_k)
        self.reject_k = float(reject_k)
        self.reanchor_s = float(reanchor_s)
        self.still_s = float(still_s)
        self.min_dt = 1.0 / float(max_rate_hz)
        self.window_s = float(window_s)
        # state [b, c_1, ..., c_n] and its covariance as plain lists (a handful of entries, updated at
        # every heading reading: numpy's per-call overhead was most of the filter's time)
        self.x: list[float] = [0.0]
        self.P: list[list[float]] = [[float(prior_sigma) ** 2]]
        self.t: float | None = None
        self.idx: dict[str, int] = {}
        self._last: dict[str, float] = {}
        self._bad_since: dict[str, float] = {}
        # the gyro's raw integral (trapezoid over readings): (t, G, rate, var)
        self.series: deque[tuple[float, float, float, float]] = deque(maxlen=int(history))
        self._pending: list[tuple[float, str, float, float]] = []
        self._reanchor: set[str] = set()
        # per heading source: [EW mean of yn^2, EW mean of n * mean(yn)^2 over a window, the window's sum
        # of yn, its n, its start, windows, the inflation factor, readings] (see _shared)
        self._vif: dict[str, list[float]] = {}
        self._still_since: float | None = None
        self._still_until = -math.inf
        self.n_heading = 0
        self.n_still = 0
        self.rejected = 0

    # ------------------------------------------------------------------ inputs
    def add_rate(self, t: float, rate: float, var: float) -> None:
        """A raw gyro reading (rad/s about base_link z) and its variance."""
        if not (math.isfinite(t) and math.isfinite(rate)):
            return
        if self.series and t <= self.series[-1][0]:
            return
        g = 0.0
        if self.series:
            t0, g0, r0, _ = self.series[-1]
            if t - t0 <= MAX_GYRO_GAP_S:
                g = g0 + 0.5 * (r0 + rate) * (t - t0)
            else:  # a gap: the integral does not bridge it, every heading source starts again
                g = g0
                self._reanchor.update(self.idx)
        v = var if math.isfinite(var) and var > 0 else 1e-4
        self.series.append((float(t), g, float(rate), v))
        if self._still_since is not None and t - self._still_since >= self.still_s and t <= self._still_until:
            self._update_still(float(t), float(rate), v)
        self._process()

    def add_heading(self, source: str, t: float, yaw: float, var: float) -> None:
        """An absolute heading (rad, any frame fixed per source) and its variance."""
        if not (math.isfinite(t) and math.isfinite(yaw)) or not (math.isfinite(var) and var > 0):
            return
        if t - self._last.get(source, -math.inf) < self.min_dt:
            return
        self._last[source] = float(t)
        self._pending.append((float(t), source, float(yaw), float(var)))
        if len(self._pending) > 2000:
            del self._pending[:1000]
        self._process()

    def set_still(self, t: float, still: bool, hold_s: float = 0.1) -> None:
        """The wheels' report at ``t``: standing still or not (gyro readings up to ``hold_s`` later count)."""
        if still:
            if self._still_since is None:
                self._still_since = float(t)
            self._still_until = float(t) + hold_s
        else:
            self._still_since = None
            self._still_until = -math.inf

    # ------------------------------------------------------------------ outputs
    def value(self) -> float:
        return self.x[0]

    def sigma(self) -> float:
        return math.sqrt(max(self.P[0][0], 0.0))

    # ------------------------------------------------------------------ filter
    def _integral_at(self, t: float) -> tuple[float, float] | None:
        s = self.series
        if not s or t < s[0][0] or t > s[-1][0]:
            return None
        lo, hi = bracket(s, t)
        a, b = s[lo], s[hi]
        if b[0] - a[0] > MAX_GYRO_GAP_S:
            return None
        h = b[0] - a[0]
        if h <= 0:
            return a[1], a[3]
        f = (t - a[0]) / h
        rate = a[2] + f * (b[2] - a[2])
        return a[1] + 0.5 * (a[2] + rate) * (t - a[0]), a[3] * h

    def _predict(self, t: float) -> None:
        if self.t is None:
            self.t = t
            return
        dt = t - self.t
        if dt <= 0:
            return
        # F = I with F[1:, 0] = -dt (each offset drifts as -b): F x and F P F^T by rows and columns
        x0 = self.x[0]
        if len(self.x) == 3:  # the bias and two heading sources (the common case), unrolled: the same operations
            (a00, a01, a02), (a10, a11, a12), (a20, a21, a22) = self.P
            x = [x0, self.x[1] - dt * x0, self.x[2] - dt * x0]
            a10, a11, a12 = a10 - dt * a00, a11 - dt * a01, a12 - dt * a02
            a20, a21, a22 = a20 - dt * a00, a21 - dt * a01, a22 - dt * a02
            P = [[a00, a01 - dt * a00, a02 - dt * a00], [a10, a11 - dt * a10, a12 - dt * a10],
                 [a20, a21 - dt * a20, a22 - dt * a20]]
        else:
            x = [x0] + [xk - dt * x0 for xk in self.x[1:]]
            p0 = self.P[0]
            FP = [p0] + [[a - dt * b for a, b in zip(row, p0, strict=True)] for row in self.P[1:]]
            P = [[r[0]] + [a - dt * r[0] for a in r[1:]] for r in FP]
        P[0][0] += self.rw**2 * dt
        arw = self.series[-1][3] * (self.series[-1][0] - self.series[-2][0]) if len(self.series) > 1 else 0.0
        q = (self.offset_q + arw) * dt
        for i in range(1, len(x)):
            P[i][i] += q
        self.x, self.P = x, P
        self.t = t

    def _robust_update(self, i: int, y: float, R: float, source: str | None, t: float) -> bool:
        """A measurement of state ``i`` (``H = e_i``) with innovation ``y`` and variance ``R``."""
        P = self.P
        Pii = P[i][i]
        S = Pii + R
        z = abs(y) / math.sqrt(S)
        if z > self.reject_k:
            self.rejected += 1
            return False
        if z > self.huber_k:
            R = R * z / self.huber_k
            S = Pii + R
        if len(P) == 3:  # unrolled (the common case): the same operations as below
            (a00, a01, a02), (a10, a11, a12), (a20, a21, a22) = P
            k0, k1, k2 = P[0][i] / S, P[1][i] / S, P[2][i] / S
            x = self.x
            self.x = [x[0] + k0 * y, x[1] + k1 * y, x[2] + k2 * y]
            b0, b1, b2 = P[i]
            a00, a01, a02 = a00 - k0 * b0, a01 - k0 * b1, a02 - k0 * b2
            a10, a11, a12 = a10 - k1 * b0, a11 - k1 * b1, a12 - k1 * b2
            a20, a21, a22 = a20 - k2 * b0, a21 - k2 * b1, a22 - k2 * b2
            self.P = [[0.5 * (a00 + a00), 0.5 * (a01 + a10), 0.5 * (a02 + a20)],
                      [0.5 * (a10 + a01), 0.5 * (a11 + a11), 0.5 * (a12 + a21)],
                      [0.5 * (a20 + a02), 0.5 * (a21 + a12), 0.5 * (a22 + a22)]]
            return True
        K = [row[i] / S for row in P]
        self.x = [a + k * y for a, k in zip(self.x, K, strict=True)]
        Pi = P[i]
        P = [[a - k * b for a, b in zip(row, Pi, strict=True)] for row, k in zip(P, K, strict=True)]
        cols = list(zip(*P, strict=True))  # (P + P^T) / 2
        self.P = [[0.5 * (pab + pba) for pab, pba in zip(row, col, strict=True)]
                  for row, col in zip(P, cols, strict=True)]
        return True

    def _process(self) -> None:
        if not self._pending or not self.series:
            return
        covered = self.series[-1][0]
        pend = self._pending
        if len(pend) == 1:  # the usual case: one reading waiting (the same as the general case's lists)
            if pend[0][0] > covered:
                return
            ready, self._pending = pend, []
        else:
            ready = sorted(p for p in pend if p[0] <= covered)
            if not ready:
                return
            self._pending = [p for p in pend if p[0] > covered]
        for t, source, yaw, var in ready:
            g = self._integral_at(t)
            if g is None:
                continue
            z = yaw - g[0]
            self._predict(t)
            i = self.idx.get(source)
            if i is None or source in self._reanchor:
                self._anchor(source, z, var)
                self._reanchor.discard(source)
                continue
            y = wrap_scalar(z - self.x[i])
            var = var * self._shared(source, t, y / math.sqrt(self.P[i][i] + var))
            if self._robust_update(i, y, var, source, t):
                self._bad_since.pop(source, None)
                self.n_heading += 1
            else:
                since = self._bad_since.setdefault(source, t)
                if t - since >= self.reanchor_s:
                    self._anchor(source, z, var)
                    self._bad_since.pop(source, None)

    def _shared(self, source: str, t: float, yn: float) -> float:
        """How many times its variance a heading reading counts for (>= 1): the variance inflation
        of the source's normalized innovations ``yn`` over ``window_s`` windows,
        ``n * var(mean of n) / var(one)``.  A heading's slowly varying errors (a magnetic
        distortion along the path, an AHRS's drift) are shared by the readings of a stretch; taken
        as independent, 20 readings a second fitted the distortion's slope as gyro bias (the
        skid-steer run: 1.82 mrad/s for 2.00).  White readings: 1."""
        st = self._vif.get(source)
        if st is None:
            st = self._vif[source] = [0.0, 0.0, 0.0, 0.0, t, 0.0, 1.0, 0.0]
        yn = min(max(yn, -self.huber_k), self.huber_k)  # an outlier does not make the source correlated
        st[7] += 1.0
        st[0] += max(0.01, 1.0 / st[7]) * (yn * yn - st[0])
        st[2] += yn
        st[3] += 1.0
        if t - st[4] >= self.window_s:
            n = st[3]
            st[5] += 1.0
            st[1] += max(0.05, 1.0 / st[5]) * (st[2] * st[2] / n - st[1])
            st[2], st[3], st[4] = 0.0, 0.0, t
            if st[5] >= 5 and st[0] > 0:
                st[6] = min(max(st[1] / st[0], 1.0), max(n, 1.0))
        return st[6]

    def _anchor(self, source: str, z: float, var: float) -> None:
        """(Re)start a heading source's offset at ``z``, uncorrelated with the rest."""
        i = self.idx.get(source)
        if i is None:
            i = len(self.x)
            self.idx[source] = i
            self.x = self.x + [0.0]
            self.P = [row + [0.0] for row in self.P] + [[0.0] * (i + 1)]
        n = len(self.x)
        self.P[i] = [0.0] * n
        for row in self.P:
            row[i] = 0.0
        self.x[i] = float(z)
        self.P[i][i] = var + 1e-6

    def _update_still(self, t: float, rate: float, var: float) -> None:
        self._predict(t)
        if self._robust_update(0, rate - self.x[0], var, None, t):
            self.n_still += 1
