"""The noise arbiter: each source's noise from its disagreement with the others (see the package's
docstring)."""

from __future__ import annotations

import math
from bisect import bisect_right
from collections import deque
from dataclasses import dataclass, field

from fgloc.backends.health.cornered_hat import cornered_hat
from fgloc.geometry import wrap_scalar

RATE, INSTANT_RATE, ABSOLUTE, ANGLE_ABSOLUTE = "rate", "instant_rate", "absolute", "angle"
#: readings held unchecked at most (then taken into their streams at once, as at an update)
INBOX_MAX = 1024


@dataclass
class _Stream:
    """One source's readings (stamps, values, variances: plain lists, the newest ``Arbiter.history`` at
    most) and what the arbiter knows of it."""

    kind: str
    t: list[float] = field(default_factory=list)
    v: list[float] = field(default_factory=list)
    var: list[float] = field(default_factory=list)
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
        # readings as they came, (stream, t, value, var), not yet checked into their streams: taken in one
        # pass where the streams are read (:meth:`_take_inbox`)
        self._inbox: list[tuple[_Stream, float, float, float]] = []
        # :meth:`noise`'s answers since the statistics it reads last changed (a new stream, a processed block)
        self._noise_memo: dict[str, tuple[float, float]] = {}
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
            self._noise_memo.clear()
            self.streams[name] = _Stream(kind, rel_prior=float(rel_prior))

    def add_reading(self, name: str, kind: str, rel_prior: float, t: float, value: float, var: float) -> None:
        """A sample of source ``name`` into the inbox (as :meth:`add`), the source registered
        (:meth:`add_source`) at its first one."""
        s = self.streams.get(name)
        if s is None:
            self.add_source(name, kind, rel_prior)
            s = self.streams[name]
        self._inbox.append((s, t, value, var))
        if len(self._inbox) >= INBOX_MAX:
            self._take_inbox()

    def add(self, name: str, t: float, value: float, var: float) -> None:
        """A sample of a registered source: a rate (rate sources) or an absolute value (absolute /
        angle sources); held in the inbox until the streams are read."""
        s = self.streams.get(name)
        if s is None:
            return
        self._inbox.append((s, t, value, var))
        if len(self._inbox) >= INBOX_MAX:
            self._take_inbox()

    def _take_inbox(self) -> None:
        """The readings received since the last call into their streams, in the order they came: a
        reading that is not finite, or not later than its stream's last, is dropped; each stream keeps
        its newest ``history`` readings."""
        inbox = self._inbox
        self._inbox = []
        isfinite = math.isfinite
        for s, t, value, var in inbox:
            if not (isfinite(t) and isfinite(value)):
                continue
            if s.t and t <= s.t[-1]:
                continue
            if self._t0 is None:
                self._t0 = float(t)
            s.t.append(float(t))
            s.v.append(float(value))
            s.var.append(float(var) if isfinite(var) and var > 0 else 0.0)
        for s in self.streams.values():
            extra = len(s.t) - self.history
            if extra > 0:
                del s.t[:extra], s.v[:extra], s.var[:extra]

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
        if self._inbox:
            self._take_inbox()
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
                tn = t1 if t1 < ts[i] else ts[i]   # min(ts[i], t1)
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
                a = t0 if t0 > ta else ta   # max(ta, t0), min(tb, t1) without the builtins' calls
                b = t1 if t1 < tb else tb
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
        at0 = self._value_at(s, t0)
        at1 = self._value_at(s, t1)
        if at0 is None or at1 is None:
            return None
        d = at1[0] - at0[0]
        if s.kind == ANGLE_ABSOLUTE:
            d = wrap_scalar(d)
        return d, at0[1] + at1[1]

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
        if self._inbox:
            self._take_inbox()
        if self._t0 is None:
            return 0
        done = 0
        while True:
            b0 = self._t0 + self._next_block * self.block_s
            b1 = b0 + self.block_s
            if now < b1 + self.settle_s:
                return done
            self._next_block += 1
            self._noise_memo.clear()
            self._block(b0, b1, self._next_block - 1)
            done += 1
            self._forget_before(self._t0 + self._next_block * self.block_s)

    def _forget_before(self, t: float) -> None:
        """Drop the readings no block from ``t`` on reads: each stream keeps its last reading at or
        before ``t`` and everything after (an increment over ``(t0, t1]`` with ``t0 >= t`` reads the
        reading at or before ``t0`` and the later ones), so the streams hold the few seconds since the
        last processed block, whatever the session's length, and the increments are the same."""
        for s in self.streams.values():
            k = bisect_right(s.t, t) - 1   # the readings before the last one at or before t
            if k > 0:
                del s.t[:k], s.v[:k], s.var[:k]

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
            s.claimed_mean += (v - s.claimed_mean) / (240 if 240 < s.n_claimed else s.n_claimed)
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
        got = self._noise_memo.get(name)
        if got is None:
            got = self._noise_memo[name] = self._noise(name)
        return got

    def _noise(self, name: str) -> tuple[float, float]:
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


def _median_abs(inc: dict[str, tuple[float, float]]) -> float:
    """The median of the increments' magnitudes (np.median's, without its overhead)."""
    mags = sorted(abs(d) for d, _ in inc.values())
    m = len(mags) // 2
    return float(mags[m]) if len(mags) % 2 else float((mags[m - 1] + mags[m]) / 2.0)


def _still_stat(st: list[float], r: float, claimed: float, cap: float, a: float) -> None:
    """One still block's squared pair difference ``r^2`` into the EW mean ``st = [mean, n]``
    (at most ``cap`` times the current mean or the claim: a disturbance moves it little)."""
    # max / min in conditionals (the builtins' calls cost more than the rest: every block, every pair)
    if st[1]:
        ref = claimed if claimed > st[0] else st[0]
        ref = 1e-12 if 1e-12 > ref else ref
    else:
        ref = claimed + 1e-12
    z, zc = r * r, cap * ref
    z = zc if zc < z else z
    st[1] += 1
    w = 1.0 / st[1]
    w = w if w > a else a
    st[0] += w * (z - st[0])
