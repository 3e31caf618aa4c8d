"""A gyro's bias from what observes it without the wheels (:class:`GyroBias`)."""

from __future__ import annotations

import math
from array import array
from bisect import bisect_right

from fgloc.geometry import wrap_scalar

MAX_GYRO_GAP_S = 0.5  # a longer gap between gyro readings breaks the integral


class GyroSeries:
    """The newest ``n`` gyro readings ``(t, G, rate, var)`` with increasing ``t``, as a ``deque(maxlen=n)`` of
    them reads (``s[i]``, ``s[-1]``, ``len``), in float64 columns (``array('d')``) allocated and written once at
    construction: 32 bytes a reading whatever the log's length, where tuples of floats took ~180 and grew as
    the series filled.  The columns hold ``2 n`` rows; the live ones are ``[a, b)``, and when ``b`` reaches
    the end the newest move to the front (one copy every ``n`` readings)."""

    def __init__(self, n: int) -> None:
        self.n = max(int(n), 1)
        empty = array("d", [math.nan]) * (2 * self.n)
        self._t, self._g, self._r, self._v = empty, array("d", empty), array("d", empty), array("d", empty)
        self._a = self._b = 0
        self.last: tuple[float, float, float, float] | None = None  # the newest reading (None: empty)

    def __len__(self) -> int:
        return self._b - self._a

    def __getitem__(self, i: int) -> tuple[float, float, float, float]:
        k = (self._b + i) if i < 0 else (self._a + i)
        if not self._a <= k < self._b:
            raise IndexError(i)
        if k == self._b - 1:
            return self.last  # type: ignore[return-value]
        return self._t[k], self._g[k], self._r[k], self._v[k]

    def first_t(self) -> float:
        """The oldest reading's time (the series must not be empty)."""
        return self._t[self._a]

    def append(self, row: tuple[float, float, float, float]) -> None:
        """A reading of four floats, newer than the last."""
        k = self._b
        if k == 2 * self.n:
            keep = self.n - 1
            for col in (self._t, self._g, self._r, self._v):
                col[:keep] = col[k - keep:k]
            self._a, k = 0, keep
        self._t[k], self._g[k], self._r[k], self._v[k] = self.last = row
        self._b = k + 1
        if self._b - self._a > self.n:
            self._a += 1

    def integral_at(self, t: float) -> tuple[float, float] | None:
        """``(G, var)``: the raw integral at ``t`` (the trapezoid, the rate linear between the readings
        around ``t``) and the variance the reading before ``t`` gives it over their gap; None outside the
        readings or across a gap over :data:`MAX_GYRO_GAP_S`.  (Read from the columns.)"""
        a0, b0 = self._a, self._b
        if b0 == a0:
            return None
        T = self._t
        if t < T[a0] or t > T[b0 - 1]:
            return None
        lo, hi = self.bracket(t)
        ka, kb = a0 + lo, a0 + hi
        ta, tb = T[ka], T[kb]
        if tb - ta > MAX_GYRO_GAP_S:
            return None
        h = tb - ta
        ga, ra, va = self._g[ka], self._r[ka], self._v[ka]
        if h <= 0:
            return ga, va
        f = (t - ta) / h
        rate = ra + f * (self._r[kb] - ra)
        return ga + 0.5 * (ra + rate) * (t - ta), va * h

    def bracket(self, t: float) -> tuple[int, int]:
        """The indices ``lo, hi`` of the readings around ``t`` (as :func:`fgloc.backends.health.latency.bracket`:
        ``self[lo][0] <= t``, ``hi = lo + 1``; ``0, 0`` for one reading)."""
        n = self._b - self._a
        if n < 2:
            return 0, 0
        lo = bisect_right(self._t, t, self._a, self._b) - 1 - self._a   # max(min(lo, n - 2), 0) as conditionals
        lo = n - 2 if n - 2 < lo else lo
        lo = 0 if 0 > lo else lo
        return lo, lo + 1


class GyroBias:
    """One gyro's bias (rad/s), from what observes it without the wheels.

    A wheel's yaw rate cannot tell a gyro's bias from its own scrub or slip: a skid steer
    whose wheels report 0.5 rad/s while driving straight would be read as a 0.5 rad/s gyro
    bias.  The bias is therefore estimated from

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
        # every heading reading: numpy's per-call overhead would be most of the filter's time)
        self.x: list[float] = [0.0]
        self.P: list[list[float]] = [[float(prior_sigma) ** 2]]
        self.t: float | None = None
        self.idx: dict[str, int] = {}
        self._last: dict[str, float] = {}
        self._bad_since: dict[str, float] = {}
        # the gyro's raw integral (trapezoid over readings): (t, G, rate, var)
        self.series = GyroSeries(history)
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
        last = self.series.last
        if last is not None and t <= last[0]:
            return
        g = 0.0
        if last is not None:
            t0, g0, r0, _ = last
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
        s = self.series
        arw = s.last[3] * (s.last[0] - s[-2][0]) if s.last is not None and len(s) > 1 else 0.0
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
        last = self.series.last
        if not self._pending or last is None:
            return
        covered = last[0]
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
        integral_at = self.series.integral_at
        for t, source, yaw, var in ready:
            g = integral_at(t)
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
        # an outlier does not make the source correlated: min(max(yn, -k), k) as conditionals
        yn = -self.huber_k if -self.huber_k > yn else yn
        yn = self.huber_k if self.huber_k < yn else yn
        st[7] += 1.0
        w = 1.0 / st[7]
        st[0] += (w if w > 0.01 else 0.01) * (yn * yn - st[0])
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
