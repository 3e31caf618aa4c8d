"""The odometry's clock against the scans': an offset estimated online and applied to its stamps.

A driver stamps its messages when it reads them, not when the motion happened; two drivers on one
robot (wheels, laser) can sit tens to hundreds of milliseconds apart.  On CARMEN's Radish logs the
6-8 Hz odometry sits 80-120 ms off the scans (fr079, aces: the odometry's yaw over scan pairs fits
the SLAM reference best read 0.08-0.12 s off the scans' stamps); in turns the back-end then
integrated each keyframe interval's rotation over the wrong 0.1 s, increments 5-13 deg off where
they claimed 0.3-1.4 deg, and they outvoted a correct fix.

:class:`OdometryClock` measures that offset from what the localizer already has: an odometry
message stamped ``s`` is taken to report the motion at ``s + offset`` on the scans' clock.  For
pairs of accepted fixes ``a, b`` about :data:`PAIR_S` apart, the fixes' yaw change is compared with
the odometry's cumulative yaw read at ``t_a - offset, t_b - offset`` for every offset on a grid of
+-:data:`MAX_OFFSET_S` (a pair's residual curve, computed once the odometry covers it).  Only a
change of the turn rate between ``a`` and ``b`` (a turn starting or ending) tells offsets apart,
and only increments enter, so neither the map's nor the odometry's heading offset does.  The cost
over the grid is robust (a truncated quadratic at :data:`TRUNCATE` times the residuals' own scale
at offset 0: a wheel slip or a wrong fix costs every offset the same).  The estimate is used when

* the odometry is slow: its mean message period above :data:`SLOW_PERIOD_S` (the smoother's own
  ``MAX_REF_PERIOD_S``).  A faster odometry places the motion within its period, and the
  smoother's latency estimator measures the scans' lag against it (the simulator's 20-50 Hz
  odometry is never shifted here, and no estimate is made for it: a few microseconds per message);
* its stamps are regular: the median spacing at least :data:`REGULAR` of the mean.  A logger that
  writes its messages in bursts (intel: 69 % of the segment's odometry steps under 2 ms, a median
  step of 0.8 ms for a mean of 100 ms) stamps each burst when it is written: no one offset
  describes it (its fix pairs gave a cost curve with a kink and a flat side, and a 0.1 s shift
  made its heading 6.6 deg RMS against SLAM instead of 0.59).  For such an odometry the localizer
  has the smoother carry the timing as yaw variance instead (``SlidingWindowSmoother.
  odom_timing_unknown``: ``(period * w)^2`` at each end of a keyframe's odometry factor);
* it is confident: at least :data:`MIN_PAIRS` pairs, the best offset inside the grid, its cost
  below offset 0's by :data:`MIN_GAIN` (in units of the residuals' variance), its standard
  deviation (the cost's curvature) at most :data:`MAX_SIGMA_S`, every offset whose cost is
  within :data:`INTERVAL_COST` of the best within ``3 * MAX_SIGMA_S`` of it, and the fixes' turn
  over the odometry's at that offset within :data:`YAW_SCALE_TOL` of 1 (the model's premise: the
  odometry turns as much as the fixes, only late or early; mit-csail's odometry turns 1/1.11 of
  the fixes', which the smoother's yaw-scale variable takes.  A skid steer's wheels report 1.4-7
  times the turn: the simulator's 50 Hz skid steer, ratio 0.46, read as a -34 ms offset, and with
  a yaw scale fitted at each offset as a 0.27 s one at scale 0.40; neither is a clock).

Otherwise the offset is 0: an odometry whose increments agree with the fixes at its own stamps is
left as it is.  The offset in use moves towards the estimate by at most half the spacing of the
raw stamps per message, so the shifted stamps keep their order.

Core maths only: no printing, no files.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from fgloc.backends.health.latency import MAX_REF_PERIOD_S
from fgloc.geometry import wrap_angle, wrap_scalar
from fgloc.io.source import REGULAR, stamp_spacing

MAX_OFFSET_S = 0.3     # s, the offsets considered: +- this (a driver's latency, not a wrong clock)
GRID_STEP_S = 0.01     # s, the grid of offsets
PAIR_S = 0.5           # s, a fix is paired with the accepted fix nearest this long before it
PAIR_MIN_S, PAIR_MAX_S = 0.25, 1.0   # s, no pair outside these spans
MAX_ODOM_GAP_S = 1.0   # s, a pair read across an odometry gap longer than this is not used
SLOW_PERIOD_S = MAX_REF_PERIOD_S  # s, mean odometry period above which the offset is estimated and applied
PERIOD_MESSAGES = 200  # the mean period is taken over this many messages
MIN_PAIRS = 40         # pairs before any estimate is used
TRUNCATE = 3.0         # a pair's squared residual is capped at (TRUNCATE * scale)^2
SCALE_FLOOR_RAD = math.radians(0.05)   # the residuals' scale is at least this
MIN_GAIN = 25.0        # the best offset's cost below offset 0's, in units of the residuals' variance
MAX_SIGMA_S = 0.03     # s, the estimate's standard deviation at most this, locally (the cost's curvature)
#: and globally: every offset whose cost is within this (a 3-sigma profile interval) of the best
#: lies within ``3 * MAX_SIGMA_S`` of it (a cost curve with a kink and a flat side is not a measurement)
INTERVAL_COST = 9.0
YAW_SCALE_TOL = 0.2    # the fixes' turn over the odometry's at the best offset within 1 +- this,
SCALE_TURN_RAD = math.radians(5.0)   # over the pairs in which the odometry turns at least this,
MIN_TURNING_PAIRS = 10               # at least this many
MAX_PAIRS = 4000       # the residual curves kept (the oldest dropped)
REFIT_EVERY = 10       # new pairs between fits
SLEW = 0.5             # the offset in use moves by at most this share of the raw stamps' spacing



class OdometryClock:
    """The offset (s) to add to a slow odometry's stamps to put them on the scans' clock (see the
    module docstring).  Feed it every accepted odometry message (:meth:`stamp` with its raw stamp,
    then :meth:`add_odometry` with the dead-reckoned yaw) and every fix the back-end used
    (:meth:`add_fix`); :attr:`offset_s` is the offset in use."""

    def __init__(self) -> None:
        self.grid_s = np.round(np.arange(-MAX_OFFSET_S, MAX_OFFSET_S + 0.5 * GRID_STEP_S, GRID_STEP_S), 6)
        self._g0 = int(np.argmin(np.abs(self.grid_s)))
        self.offset_s = 0.0            # in use (applied to the stamps)
        self.estimate_s = 0.0          # the confident estimate (0 when not confident)
        self.sigma_s = math.inf        # its standard deviation
        self.gain = 0.0                # cost at 0 minus the best cost, in residual variances
        self.confident = False
        self.fit_s, self.fit_sigma_s = 0.0, math.inf   # the last fit's best offset and its sigma
        self.yaw_scale = math.nan                      # and the fixes' turn over the odometry's there
        self.turning_pairs = 0                         # over this many pairs
        self.slow = False
        self.regular = False
        self.fits = 0
        self._raw_t: list[float] = []  # raw odometry stamps and the cumulative (unwrapped) yaw there
        self._yaw: list[float] = []
        self._last_yaw: float | None = None
        self._cum_yaw = 0.0
        self._count = 0
        self._last_raw: float | None = None
        self._stamps: deque[float] = deque(maxlen=PERIOD_MESSAGES)
        self._fixes: deque[tuple[float, float]] = deque(maxlen=64)
        self._pending: list[tuple[float, float, float]] = []   # (t_a, t_b, fix yaw change) not yet covered
        self._curves: deque[np.ndarray] = deque(maxlen=MAX_PAIRS)   # per pair: the odometry's yaw change per offset
        self._d_fix: deque[float] = deque(maxlen=MAX_PAIRS)         # and the fixes'
        self._new = 0

    @property
    def applies(self) -> bool:
        """Whether the estimate is used: a slow odometry with regular stamps, a confident estimate."""
        return self.slow and self.regular and self.confident

    @property
    def pairs(self) -> int:
        return len(self._curves)

    # ------------------------------------------------------------------ inputs
    def stamp(self, t_raw: float) -> float:
        """The message stamped ``t_raw`` (checked, later than the previous one) on the scans' clock;
        the offset in use moves towards the estimate here."""
        target = self.estimate_s if self.confident and self.applies else 0.0
        if self._last_raw is not None and target != self.offset_s:
            step = SLEW * max(t_raw - self._last_raw, 0.0)
            self.offset_s += max(-step, min(step, target - self.offset_s))
        self._last_raw = t_raw
        return t_raw + self.offset_s

    def add_odometry(self, t_raw: float, yaw_rad: float) -> None:
        """The odometry's dead-reckoned yaw after the message stamped ``t_raw`` (raw stamp).  Nothing is
        kept but the stamps' period while the odometry is fast (no estimate is made then)."""
        if not (math.isfinite(t_raw) and math.isfinite(yaw_rad)):
            return
        if self._stamps and t_raw <= self._stamps[-1]:
            return
        if self._last_yaw is not None:
            self._cum_yaw += wrap_scalar(yaw_rad - self._last_yaw)
        self._last_yaw = yaw_rad
        self._stamps.append(t_raw)
        self._count += 1
        spacing = stamp_spacing(self._stamps) if self._count < 20 or self._count % 20 == 0 else None
        if spacing is not None:  # (the stamps kept are increasing already)
            median, mean = spacing
            self.slow = mean > SLOW_PERIOD_S
            self.regular = median >= REGULAR * mean
        if not self.slow:
            if self._raw_t or self._pending:
                self._raw_t.clear()
                self._yaw.clear()
                self._pending.clear()
            return
        self._raw_t.append(t_raw)
        self._yaw.append(self._cum_yaw)
        if self._pending and self._pending[0][1] + MAX_OFFSET_S <= t_raw:
            self._take_covered()

    def add_fix(self, t: float, yaw_rad: float) -> None:
        """A fix the back-end used, at scan stamp ``t``: paired with the one nearest :data:`PAIR_S` before."""
        if not (self.slow and math.isfinite(t) and math.isfinite(yaw_rad)):
            return
        best = None
        for ta, ya in self._fixes:
            dt = t - ta
            if PAIR_MIN_S <= dt <= PAIR_MAX_S and (best is None or abs(dt - PAIR_S) < abs(t - best[0] - PAIR_S)):
                best = (ta, ya)
        if best is not None:
            d = wrap_scalar(yaw_rad - best[1])
            self._pending.append((best[0], t, d))
        self._fixes.append((t, yaw_rad))

    # ------------------------------------------------------------------ the estimate
    def _take_covered(self) -> None:
        t_last = self._raw_t[-1]
        covered = [p for p in self._pending if p[1] + MAX_OFFSET_S <= t_last]
        self._pending = [p for p in self._pending if p[1] + MAX_OFFSET_S > t_last]
        ot = np.asarray(self._raw_t)
        oy = np.asarray(self._yaw)
        for ta, tb, d_fix in covered:
            if ta - MAX_OFFSET_S < ot[0]:
                continue
            lo = int(np.searchsorted(ot, ta - MAX_OFFSET_S)) - 1
            hi = int(np.searchsorted(ot, tb + MAX_OFFSET_S)) + 1
            if lo < 0 or float(np.max(np.diff(ot[lo:hi + 1]))) > MAX_ODOM_GAP_S:
                continue
            ya = np.interp(ta - self.grid_s, ot, oy)
            yb = np.interp(tb - self.grid_s, ot, oy)
            self._curves.append(yb - ya)
            self._d_fix.append(d_fix)
            self._new += 1
        # keep the odometry the pending pairs (and a margin) still need
        keep_from = (self._pending[0][0] if self._pending else t_last) - MAX_OFFSET_S - PAIR_MAX_S - 1.0
        i = int(np.searchsorted(ot, keep_from)) - 1
        if i > 256:
            del self._raw_t[:i], self._yaw[:i]
        if self._new >= REFIT_EVERY and len(self._curves) >= MIN_PAIRS:
            self._fit()

    def _fit(self) -> None:
        self._new = 0
        self.fits += 1
        f = np.asarray(self._d_fix)
        o = np.asarray(self._curves)
        r = np.asarray(wrap_angle(f[:, None] - o))
        scale = max(1.4826 * float(np.median(np.abs(r[:, self._g0]))), SCALE_FLOOR_RAD)
        cost = np.minimum(r * r, (TRUNCATE * scale) ** 2).sum(axis=0) / (scale * scale)
        g = int(np.argmin(cost))
        self.gain = float(cost[self._g0] - cost[g])
        # the model's premise: the odometry's turns are the fixes' turns, only late or early.  The
        # fixes' turn over the odometry's at the best offset (the median ratio over the pairs that turn
        # at least SCALE_TURN_RAD; not over the pairs within the truncation, which a scaled turn leaves
        # out) tells a wheel base that reports a scaled turn, whose timing this cannot measure
        turning = np.abs(o[:, g]) >= SCALE_TURN_RAD
        self.turning_pairs = int(np.count_nonzero(turning))
        self.yaw_scale = float(np.median(f[turning] / o[turning, g])) if self.turning_pairs else math.nan
        self.fit_s, self.fit_sigma_s = float(self.grid_s[g]), math.inf
        if g == 0 or g == len(cost) - 1:
            return  # on the grid's edge: no offset within the bounds explains the pairs
        cm, c0, cp = float(cost[g - 1]), float(cost[g]), float(cost[g + 1])
        h = GRID_STEP_S
        a = (cm - 2.0 * c0 + cp) / (2.0 * h * h)  # cost ~ a (x - x*)^2: variance 1 / a (cost in variances)
        if not a > 0:
            return
        self.fit_s += 0.5 * h * (cm - cp) / (cm - 2.0 * c0 + cp)
        self.fit_sigma_s = 1.0 / math.sqrt(a)
        near = self.grid_s[cost <= c0 + INTERVAL_COST]
        narrow = float(np.max(np.abs(near - self.fit_s))) <= 3.0 * MAX_SIGMA_S + GRID_STEP_S
        if self.gain >= MIN_GAIN and self.fit_sigma_s <= MAX_SIGMA_S and narrow and \
                self.turning_pairs >= MIN_TURNING_PAIRS and abs(self.yaw_scale - 1.0) <= YAW_SCALE_TOL:
            # used from now on; a later fit that is not confident keeps the last confident estimate
            self.confident = True
            self.estimate_s, self.sigma_s = self.fit_s, self.fit_sigma_s

    def summary(self) -> dict[str, float | int | bool | None]:
        """What the estimate is and why it is (not) used."""
        return {"offset_s": round(self.offset_s, 4), "estimate_s": round(self.estimate_s, 4),
                "sigma_s": round(self.sigma_s, 4) if math.isfinite(self.sigma_s) else -1.0,
                "fit_s": round(self.fit_s, 4),
                "yaw_scale": round(self.yaw_scale, 4) if math.isfinite(self.yaw_scale) else None,
                "turning_pairs": self.turning_pairs,
                "fit_sigma_s": round(self.fit_sigma_s, 4) if math.isfinite(self.fit_sigma_s) else -1.0,
                "gain": round(self.gain, 1), "pairs": self.pairs, "slow": self.slow, "regular": self.regular,
                "confident": self.confident, "applied": self.applies}
