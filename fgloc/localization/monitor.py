"""It knows when it is wrong: every pose gets a status, ``ok``, ``degraded``, ``suspect`` or ``lost``.

* ``ok`` - the map confirms the pose: a fix was accepted within ``integrity.degraded_after_s`` and
  nothing below contradicts it (in an ``odom``-frame run without a map: the fusion agrees with
  dead reckoning);
* ``degraded`` - dead reckoning, nothing contradicts it: no fix accepted for a while (the laser
  silent, space the map does not have, scans that match nothing, fixes held back by the jump gate
  of :mod:`fgloc.localization.gate`); the covariance grows with the odometry;
* ``suspect`` - something contradicts the pose: the map keeps pointing elsewhere (fixes held back
  or rejected for longer than ``integrity.suspect_after_s``), the fused pose is further from the last
  fix the back-end took than the odometry drove since (:mod:`fgloc.localization.divergence`: a back-end
  that diverged), or, in an ``odom``-frame run, the
  fused path left odometry + IMU dead reckoning (:class:`DeadReckoning`) further than a drifting
  odometry explains (``integrity.divergence_share`` of the distance driven);
* ``lost`` - the localizer does not know where the robot is in the map: no pose yet, a start pose
  the map has not confirmed, a global search, and (decided afterwards) the span before a
  relocalization moved the pose elsewhere.

:class:`ConsistencyMonitor` keeps one record per pose the localizer produced (at each scan, and
at each dead-reckoned pose while no scan arrives), amends them when a relocalization shows the
pose was wrong before it, and answers the status at any output stamp.  It also keeps the
run-level verdicts (:attr:`ConsistencyMonitor.verdicts`): no scan ever matched the map, the map
does not fit the log, the initial pose did not fit the map, the fusion diverged.

Core logic only: no I/O.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from collections import deque
from dataclasses import dataclass
from statistics import median
from typing import Any

import numpy as np

from fgloc.config.schema import setting
from fgloc.geometry import wrap_scalar
from fgloc.localization.coverage import RANGE_FIT_LOG, UNMAPPED_SHARE, beyond_walls, range_residuals, unmapped_share
from fgloc.localization.gate import scan_agreement

OK = "ok"
DEGRADED = "degraded"
SUSPECT = "suspect"
LOST = "lost"
#: the statuses, best first (the run summary counts them in this order)
STATUSES = (OK, DEGRADED, SUSPECT, LOST)


@dataclass(frozen=True)
class IntegrityConfig:
    """``integrity:`` the jump gate and the consistency monitor (:mod:`fgloc.localization.gate`,
    :mod:`fgloc.localization.monitor`)."""

    gate: bool = setting(True, "hold back a fix that jumps further from the last accepted one, carried by the "
                         "odometry, than the covariances allow, unless the map confirms it")
    gate_chi2: float = setting(13.82, "... a jump: the squared Mahalanobis distance of the fix's position from the "
                               "prediction's and from the previous fix's beyond this (chi-square, 2 dof, 99.9 %)", gt=0)
    covariance_period_s: float = setting(1.0, "... judged with a back-end covariance at most this old (log time; a "
                                         "smoother's marginal is not free)", gt=0)
    odometry_slip: float = setting(0.5, "... a fix following the previous one as the odometry says, within this "
                                   "fraction of the distance and the turn it reported (slip, scrub), is no jump", min=0)
    confirm_agreement: float = setting(0.5, "... taken anyway when the scan's agreement with the map near the "
                                       "prediction is this fraction below its agreement at the fix", min=0, max=1)
    agreement_sigma_m: float | None = setting(None, "distance scale of the scan's agreement with the map (null: "
                                              "the map's cell or its declared accuracy, whichever is larger)", gt=0)
    odometry_gap_s: float = setting(0.25, "the jump gate knows the motion since the last accepted fix only where the "
                                    "odometry's stamps cover it, none more than this apart nor this far from its ends "
                                    "(s; odometry late, stopped or absent: the map decides)", gt=0)
    degraded_after_s: float = setting(1.0, "no accepted fix for this long: degraded (dead reckoning)", gt=0)
    suspect_after_s: float = setting(3.0, "fixes held back or rejected for this long: suspect (the map keeps "
                                     "pointing elsewhere)", gt=0)
    laser_silent_after_s: float = setting(1.0, "no scan for this long: the laser is silent ...", gt=0)
    dead_reckoning_period_s: float = setting(0.1, "... and a dead-reckoned pose is written this often (log time)",
                                             gt=0)
    divergence_share: float = setting(0.05, "odom frame (no map): the fused path more than this share of the distance "
                                      "driven from odometry + IMU dead reckoning is suspect ...", gt=0)
    divergence_min_m: float = setting(5.0, "... and more than this (m); at the end of the run: unusable", gt=0)
    agreement_period_s: float = setting(0.25, "the scan's agreement with the map at the fused pose is measured this "
                                        "often (log time; MapAgreement)", gt=0)
    agreement_low: float = setting(0.5, "... low below this fraction of what the run's own good stretch showed (the "
                                   "lower quartile of its measurements while the poses were ok)", gt=0, max=1)
    agreement_suspect_s: float = setting(0.5, "... low for this long: suspect", gt=0)
    agreement_lost_s: float = setting(1.5, "... low for this long: lost, and the localizer searches again", gt=0)
    max_bad_share: float = setting(0.2, "fgloc run exits 3 when more than this share of the poses is suspect or "
                                   "lost (--allow-lost: exit 0)", min=0, max=1)


@dataclass
class Verdict:
    """A run-level finding: a one-line message, and whether it makes the run unusable."""

    kind: str  # no_fix, map_mismatch, ambiguous, initial_pose, global_start, diverging, heading_diverged, agreement,
    # path_diverged, laser_mount
    message: str
    unusable: bool


class ConsistencyMonitor:
    """The status of every pose (see the module docstring)."""

    def __init__(self, cfg: IntegrityConfig | None = None) -> None:
        self.cfg = cfg or IntegrityConfig()
        self.t: list[float] = []
        self.status: list[str] = []
        self.why: list[str] = []
        self.verdicts: list[Verdict] = []
        self._nis: deque[float] = deque(maxlen=20)
        #: keep the records only this far back (s; None: the whole run): a live session runs for days
        self.history_s: float | None = None

    # ------------------------------------------------------------------ records
    def record(self, t: float, status: str, why: str = "") -> None:
        """The status of the pose at ``t`` (a later stamp than the last record; an equal one replaces it)."""
        t = float(t)
        if self.t and t <= self.t[-1]:
            if t < self.t[-1]:
                return
            self.status[-1], self.why[-1] = status, why
            return
        self.t.append(t)
        self.status.append(status)
        self.why.append(why)
        h = self.history_s
        if h is not None and t - self.t[0] > 2.0 * h:  # amortized: once twice the history
            i = bisect_right(self.t, t - h)
            del self.t[:i], self.status[:i], self.why[:i]

    def amend(self, t0: float, t1: float, status: str, why: str) -> int:
        """Set the records in ``[t0, t1]`` that are better than ``status`` to it (decided afterwards:
        the span before a relocalization was lost); how many changed."""
        rank = STATUSES.index(status)
        i = bisect_right(self.t, float(t0) - 1e-9)
        n = 0
        while i < len(self.t) and self.t[i] <= t1 + 1e-9:
            if STATUSES.index(self.status[i]) < rank:
                self.status[i], self.why[i] = status, why
                n += 1
            i += 1
        return n

    @property
    def current(self) -> tuple[str, str]:
        """The newest record's status and why (``lost`` before any)."""
        return (self.status[-1], self.why[-1]) if self.status else (LOST, "no pose yet")

    def at(self, stamps: Any) -> tuple[list[str], list[str]]:
        """Status and why at each of ``stamps``: the newest record at or before it (``lost`` before the first)."""
        out_s, out_w = [], []
        for t in np.asarray(stamps, dtype=float).reshape(-1):
            i = bisect_right(self.t, float(t) + 1e-9) - 1
            if i < 0:
                out_s.append(LOST)
                out_w.append("no pose yet")
            else:
                out_s.append(self.status[i])
                out_w.append(self.why[i])
        return out_s, out_w

    def counts(self, stamps: Any = None) -> dict[str, int]:
        """How many poses have each status (the records, or the statuses at ``stamps``)."""
        sts = self.status if stamps is None else self.at(stamps)[0]
        return {s: sum(1 for x in sts if x == s) for s in STATUSES}

    # ------------------------------------------------------------------ signals
    def add_nis(self, d2: float) -> None:
        if math.isfinite(d2):
            self._nis.append(float(d2))

    def nis_mean(self) -> float | None:
        """Mean normalized innovation squared of the last accepted fixes (3 when consistent)."""
        return float(np.mean(self._nis)) if len(self._nis) >= 5 else None

    def verdict(self, kind: str, message: str, unusable: bool) -> None:
        if all(v.kind != kind for v in self.verdicts):
            self.verdicts.append(Verdict(kind, message, unusable))

    def summary(self, stamps: Any) -> dict[str, Any]:
        """The statuses at ``stamps`` (the poses written) counted, and the run-level verdicts."""
        counts = self.counts(stamps)
        n = max(sum(counts.values()), 1)
        bad = (counts[SUSPECT] + counts[LOST]) / n
        return {"counts": counts, "bad_share": bad,
                "verdicts": [{"kind": v.kind, "message": v.message, "unusable": v.unusable} for v in self.verdicts]}


class DeadReckoning:
    """Odometry + IMU dead reckoning beside the fusion, to tell when the fused path leaves it (a
    configuration that makes the back-end diverge): the odometry's twist integrated along the
    compass / IMU heading (its absolute yaw, aligned with the fused heading at the start) when there
    is one, else along the odometry's own turn when it reports one, or along the gyro's (an IMU's yaw
    rate, or the increments of an orientation used differentially), whichever the fused path is nearer;
    none when the odometry reports no turn (a configuration whose heading comes from relative yaw or a
    gyro alone: nothing independent to compare with).
    Started at the fused start pose (:meth:`start`).

    Wheels and gyro may disagree by a scale (a skid steer's wheels scrub sideways when it turns and
    report 1.4-2.5 times its turn; the fusion rightly follows the gyro), not in the direction of a turn
    (an IMU mounted upside down with its mount not said, a reversed wheel: a configuration to fix).  The
    gyro's turn counts only while the two agree in direction (the sum of their products over the turns
    the wheels report stays positive), less its bias: the mean of its readings while the wheels say
    the robot drives straight or stands (a bias of 0.002 rad/s takes a path 5.7 m off in 90 s at 0.7 m/s)."""

    MAX_DT_S = 0.5  # an odometry gap longer than this is not integrated (its twist is unknown over it) ...
    GAP_STEPS = 3.0  # ... unless within this many of the odometry's typical step (a slow odometry's, 1-2 Hz)
    STRAIGHT_RADPS = 0.01  # the wheels' turn below this: the gyro's reading is its bias (and its noise)
    TURN_RADPS = 0.05  # the wheels' turn above this: a turn whose direction the gyro must agree with

    def __init__(self) -> None:
        self.t: float | None = None
        self.t0: float | None = None  # the start's stamp
        self.wheels: np.ndarray | None = None
        self.compassed: np.ndarray | None = None
        self.distance_m = 0.0
        self._compass: tuple[float, float] | None = None  # (stamp, yaw) of the last compass reading
        self._offset: float | None = None  # compass yaw - fused yaw at the start
        self.compass_readings = 0  # absolute yaw readings since the start
        self.turned = False  # the odometry reported a turn
        self._steps: deque[float] = deque(maxlen=16)  # the last odometry stamp steps (s)
        self._seen: float | None = None  # the last odometry stamp
        self.gyroed: np.ndarray | None = None  # along the gyro's turn (its yaw: the start's plus the turn)
        self._gyro: tuple[float, float] | None = None  # (stamp, rate) of the last gyro reading
        self._wheel_rate: tuple[float, float] | None = None  # (stamp, yaw rate) of the last odometry twist
        self._bias_sum = 0.0  # the gyro's readings while the wheels said straight, and how many
        self._bias_n = 0
        self.gyro_agreement = 0.0  # sum of gyro x wheels' rates over the wheels' turns
        self.gyro_readings = 0  # gyro rates and relative yaw increments so far
        self._yaw: tuple[float, float] | None = None  # (stamp, yaw) of the last relative yaw reading

    def start(self, t: float, pose: Any) -> None:
        p = np.asarray(pose, dtype=float).reshape(3)
        self.t = self.t0 = float(t)
        self.wheels = p.copy()
        self.compassed = p.copy()
        self.gyroed = p.copy()
        if self._compass is not None:
            self._offset = self._compass[1] - float(p[2])

    def compass(self, t: float, yaw: float) -> None:
        self._compass = (float(t), float(yaw))
        if self._offset is None and self.compassed is not None:
            self._offset = float(yaw) - float(self.compassed[2])  # the first reading after the start
        if self._offset is not None:
            self.compass_readings += 1

    def odometry(self, t: float, twist: Any) -> None:
        t = float(t)
        seen, self._seen = self._seen, t
        max_dt = self.MAX_DT_S
        if self._steps and self.t is not None and t - self.t > max_dt:  # the odometry's typical step before this one
            max_dt = max(max_dt, self.GAP_STEPS * median(self._steps))
        if seen is not None and t > seen:
            self._steps.append(t - seen)  # also before the start: the first step after it is judged by them
        vx, vy, w = (float(v) for v in np.asarray(twist, dtype=float).reshape(3))
        self._wheel_rate = (t, w)
        if self.t is None or self.wheels is None or self.compassed is None or self.gyroed is None:
            return
        dt = t - self.t
        self.t = t
        if not 0.0 < dt <= max_dt:
            return
        self.distance_m += math.hypot(vx, vy) * dt
        self.turned = self.turned or abs(w) > 1e-4
        g = float(self.gyroed[2])  # the gyro's heading (gyro())
        for p, heading in ((self.wheels, None), (self.compassed, self._heading(t)), (self.gyroed, g)):
            th = float(p[2]) + 0.5 * w * dt if heading is None else heading
            c, s_ = math.cos(th), math.sin(th)
            p[0] += (c * vx - s_ * vy) * dt
            p[1] += (s_ * vx + c * vy) * dt
            p[2] = float(p[2]) + w * dt if heading is None else heading

    def reading(self, t: float, yaw: float | None, rate: float | None) -> None:
        """An IMU's or compass's reading at ``t``: its absolute yaw and its yaw rate, either None."""
        if yaw is not None:
            self.compass(t, float(yaw))
        if rate is not None:
            self.gyro(t, rate)

    def relative_yaw(self, t: float, yaw: float) -> None:
        """An orientation whose increments are used (a differential IMU yaw): its turn since the last reading on
        the gyro's track as it is (increments add up without a bias to learn: a yaw's noise does not accumulate)."""
        t, last, self._yaw = float(t), self._yaw, (float(t), float(yaw))
        if last is not None and 0.0 < t - last[0] <= self.MAX_DT_S:
            turn = wrap_scalar(float(yaw) - last[1])
            self._agree(t, turn / (t - last[0]))
            if self.gyroed is not None:
                self.gyroed[2] = float(self.gyroed[2]) + turn

    def gyro(self, t: float, rate: float) -> None:
        """A gyro's yaw rate (rad/s) at ``t``: its turn since the last reading (less its bias) on the gyro's
        track; its bias and its agreement with the wheels' turn learnt (the class's docstring)."""
        t, rate = float(t), float(rate)
        last, self._gyro = self._gyro, (t, rate)
        wr = self._wheel_rate
        if wr is not None and abs(t - wr[0]) <= self.MAX_DT_S and abs(wr[1]) < self.STRAIGHT_RADPS:
            self._bias_sum += rate
            self._bias_n += 1
        self._agree(t, rate - self.gyro_bias())
        if self.gyroed is not None and last is not None and 0.0 < t - last[0] <= self.MAX_DT_S:
            self.gyroed[2] = float(self.gyroed[2]) + (last[1] - self.gyro_bias()) * (t - last[0])

    def _agree(self, t: float, rate: float) -> None:
        """The gyro's turn ``rate`` against the wheels' (when they turn): :attr:`gyro_agreement`."""
        self.gyro_readings += 1
        wr = self._wheel_rate
        if wr is not None and abs(t - wr[0]) <= self.MAX_DT_S and abs(wr[1]) > self.TURN_RADPS:
            self.gyro_agreement += rate * wr[1]

    def gyro_bias(self) -> float:
        """The gyro's bias (rad/s): the mean of its readings while the wheels said straight (0 before any)."""
        return self._bias_sum / self._bias_n if self._bias_n else 0.0

    def _heading(self, t: float) -> float | None:
        if self._compass is None or self._offset is None or abs(float(t) - self._compass[0]) > self.MAX_DT_S:
            return None
        return self._compass[1] - self._offset

    def divergence(self, pose: Any) -> float | None:
        """How far (m) the fused ``pose`` is from the dead reckoning along the compass heading (when
        there were absolute yaw readings), else along the odometry's turn (when it reported one) or the
        gyro's (while it agrees with it in direction), whichever is nearer."""
        if self.compass_readings > 0:
            tracks = [self.compassed]
        elif self.turned:
            tracks = [self.wheels] + ([self.gyroed] if self.gyro_readings and self.gyro_agreement >= 0 else [])
        else:
            return None
        p = np.asarray(pose, dtype=float).reshape(3)
        return min(math.hypot(float(p[0] - q[0]), float(p[1] - q[1])) for q in tracks if q is not None)


class MapAgreement:
    """How well the scans agree with the map at the fused pose, against what this run showed while it was
    right: a front-end sure of a wrong place (a particle filter that tracked on after a kidnapping, fixes
    that follow each other onto furniture the map lacks) keeps giving fixes the jump gate cannot fault,
    but the scan no longer lies on the map's walls where the fusion puts it.

    Every ``integrity.agreement_period_s`` (log time) :meth:`check` measures the mean over at most
    :data:`MAX_BEAMS` of the scan's beams (evenly spread) of ``exp(-d^2 / 2 sigma^2)``, ``d`` the distance
    from the beam's endpoint to the nearest mapped wall (:func:`fgloc.localization.gate.scan_agreement`
    with the map's distance field at the endpoint's cell, where the jump gate interpolates it).  A low
    one where most beams end in space the map does not have without crossing a mapped wall
    (:func:`fgloc.localization.coverage.unmapped_share`, cast only then) is no measurement.
    The expectation is learnt from the run itself: the lower quartile of the last :data:`SAMPLES`
    measurements the localizer called good (poses ``ok``, not low), so the furniture, people and doors it
    passed while right are in it.  A measurement below ``integrity.agreement_low`` of it is low;
    :meth:`low_for` is how long the measurements have been low without a break.  Nothing is judged before
    :data:`MIN_SAMPLES` good
    measurements (a building of any clutter, a map of any quality: the level is this run's)."""

    MAX_BEAMS = 64
    MIN_BEAMS = 10  # fewer valid beams than this (a blocked laser): no measurement
    SAMPLES = 256  # the good measurements remembered (a minute at the default period)
    MIN_SAMPLES = 8
    QUANTILE = 0.25  # the expectation: this quantile of them (the clutter, the doors, the people it passed)
    REFRESH = 8  # ... recomputed every this many new ones
    #: a measurement this low lies the scan nowhere near the map's walls (a right map, a changed world with
    #: people and moved furniture: 0.5 and more at the median; another building: 0.05)
    MISFIT = 0.25
    #: the ranges check (:meth:`range_misfit`): at a good measurement at most this often (log s), the map's
    #: ranges ray-cast against the laser's (coverage.py :func:`range_fit`) ...
    RANGE_PERIOD_S = 1.0
    RANGE_MIN_SAMPLES = 10  # ... judged after this many
    #: ... the map does not fit when the median over them of the share of beams that fit is below this (the
    #: paper hall with people, moved furniture, glass: 0.8 and more at the median, 0.6 at the lower decile;
    #: its map at twice its cell size: 0.15)
    RANGE_FIT_LOW = 0.35
    #: ... or when the median share of beams that end beyond the map's wall (coverage.py :func:`beyond_walls`) is
    #: above this (the right map, people, pallets, moved furniture, glass, open doors: 0.09 and less in simulation,
    #: 0.05 and less on the Radish and Stage logs; the paper hall's map mirrored, where AMCL tracks 0.3 m off: 0.25
    #: and more)
    RANGE_BEYOND_HIGH = 0.15

    def __init__(self, cfg: IntegrityConfig, occ_map: Any, laser_mount: Any, sigma_m: float) -> None:
        self.cfg = cfg
        self.map = occ_map
        self.laser_mount = laser_mount
        self.sigma_m = float(sigma_m)
        self._good: deque[float] = deque(maxlen=self.SAMPLES)
        self._expected: float | None = None
        self._added = 0  # good measurements so far
        self._t = -math.inf  # stamp of the last measurement
        self.low_since: float | None = None
        #: when the pose may have gone wrong: the last measurement before the low stretch that was not low
        self.wrong_since: float | None = None
        self._t_fit: float | None = None  # the last measurement that was not low
        self.after_start = False  # the pose was started anew and not measured since (restarted())
        self.last: float | None = None  # the last measurement
        self.checks = 0
        self.low_checks = 0
        self.unmapped_checks = 0  # low measurements the map could not judge
        self.judged_checks = 0  # measurements at MISFIT or above, or below it where the map has the space
        self.misfit_checks = 0  # ... of them below MISFIT
        self._range_t = -math.inf
        self._blocked: np.ndarray | None = None  # the map's occupied grid, for range_fit (made at its first use)
        #: the last samples of range_fit at good measurements: (median log(cast / measured), share that fit)
        self.range_samples: deque[tuple[float, float]] = deque(maxlen=4 * self.SAMPLES)
        #: ... and of the share of beams that end beyond the map's wall (coverage.py beyond_walls)
        self.beyond_samples: deque[float] = deque(maxlen=4 * self.SAMPLES)

    def due(self, t: float) -> bool:
        return t - self._t >= self.cfg.agreement_period_s or t < self._t

    def expected(self) -> float | None:
        """The run's good level (None until :data:`MIN_SAMPLES` good measurements)."""
        return self._expected

    def measure(self, scan: Any, pose: Any) -> float:
        """The agreement of ``scan`` with the map at ``base_link`` pose ``pose`` (NaN: too few valid beams):
        :func:`fgloc.localization.gate.scan_agreement` over at most :data:`MAX_BEAMS` beams, the distance
        field looked up at each endpoint's cell."""
        return scan_agreement(self.map, self.laser_mount, scan, pose, self.sigma_m, max_beams=self.MAX_BEAMS,
                              min_beams=self.MIN_BEAMS)

    def check(self, t: float, scan: Any, pose: Any, good: bool) -> float | None:
        """Measure at ``pose`` when due; ``good``: the localizer finds the pose ok otherwise (the measurement
        may then teach the expectation, unless it is low).  The measurement, None when not due or none."""
        if not self.due(t):
            return None
        self._t = t
        a = self.measure(scan, pose)
        if not math.isfinite(a):
            return None
        self.last = a
        self.checks += 1
        if a >= self.MISFIT:
            self.judged_checks += 1
        elif unmapped_share(self.map, self.laser_mount, scan, pose) <= UNMAPPED_SHARE:
            self.judged_checks += 1
            self.misfit_checks += 1
        self.after_start = False
        exp_ = self._expected
        if exp_ is not None and a < self.cfg.agreement_low * exp_:
            if unmapped_share(self.map, self.laser_mount, scan, pose) > UNMAPPED_SHARE:
                # most beams end in space the map does not have, crossing no mapped wall: the map cannot judge
                # the pose there (a wing it lacks; dead reckoning, not wrong)
                self.unmapped_checks += 1
                return None
            self.low_checks += 1
            if self.low_since is None:
                self.low_since = t
                self.wrong_since = self._t_fit if self._t_fit is not None else t
            return a
        self.low_since = None
        self._t_fit = t
        if good:
            self._range_sample(t, scan, pose)
            self._good.append(a)
            n = len(self._good)
            self._added += 1
            if n >= self.MIN_SAMPLES and (self._expected is None or self._added % self.REFRESH == 0):
                self._expected = float(np.quantile(np.fromiter(self._good, float, n), self.QUANTILE))
        return a

    def _range_sample(self, t: float, scan: Any, pose: Any) -> None:
        if t - self._range_t < self.RANGE_PERIOD_S and t >= self._range_t:
            return
        self._range_t = t
        if self._blocked is None:
            self._blocked = np.ascontiguousarray(self.map.occupied)
        lr = range_residuals(self.map, self.laser_mount, scan, pose, self.MAX_BEAMS, self.MIN_BEAMS, self._blocked)
        if lr is not None:
            self.range_samples.append((float(np.median(lr)), float(np.mean(np.abs(lr) < RANGE_FIT_LOG))))
            self.beyond_samples.append(beyond_walls(lr))

    def range_misfit(self) -> tuple[float, float] | None:
        """Whether the laser's ranges fit the map's at the poses the localizer called good: None when they do
        (or fewer than :data:`RANGE_MIN_SAMPLES` samples), else the medians over the samples of the share of
        beams that fit and of ``cast / measured`` (a map.yaml with a wrong ``resolution``: every wall at
        another distance than measured, wherever the front-end put the pose)."""
        n = len(self.range_samples)
        if n < self.RANGE_MIN_SAMPLES:
            return None
        share = median(s for _, s in self.range_samples)
        if share >= self.RANGE_FIT_LOW:
            return None
        return share, math.exp(median(r for r, _ in self.range_samples))

    def beyond_walls(self) -> tuple[float, int] | None:
        """Whether the laser saw through the map's walls at the poses the localizer called good: None when not (or
        fewer than :data:`RANGE_MIN_SAMPLES` samples), else the median over the samples of the share of beams that
        end beyond the map's wall (above :data:`RANGE_BEYOND_HIGH`: the map's walls are not the building's where
        the front-end put the pose) and how many samples."""
        n = len(self.beyond_samples)
        if n < self.RANGE_MIN_SAMPLES:
            return None
        share = median(self.beyond_samples)
        return (share, n) if share > self.RANGE_BEYOND_HIGH else None

    def never_fit(self, min_checks: int = 2 * MIN_SAMPLES) -> bool:
        """Whether most of the run's measurements the map could judge (at least ``min_checks``; not those
        where most beams end in space it does not have) lay the scan nowhere near its walls (:data:`MISFIT`):
        the map is not of this building, wherever the front-end put the pose."""
        return self.judged_checks >= min_checks and self.misfit_checks > 0.5 * self.judged_checks

    def low_for(self, t: float) -> float:
        """How long (s) the measurements have been low up to ``t`` (0: the last was not)."""
        return 0.0 if self.low_since is None else max(0.0, t - self.low_since)

    def reset(self) -> None:
        """The localizer searches anew: the low stretch ends (the expectation stays: the same map and laser)."""
        self.low_since = self.wrong_since = self._t_fit = None
        self.after_start = False

    def restarted(self) -> None:
        """The pose was started anew on a fix (a relocalization, a restart the map confirmed over the
        prediction): the next scan is measured, and until then a low stretch goes on (a restart on another
        wrong place keeps its poses suspect; a right one ends it at that measurement)."""
        self._t = -math.inf
        self.after_start = True


#: the status file beside ``trajectory.tum`` (``trajectory_status.csv``): its first line
STATUS_HEADER = ("# fgloc pose status: one row per pose of trajectory.tum (same stamps, s); x y in m, yaw in rad; "
                 "cov_*: the pose's covariance as known online, at the nearest online pose (m^2, m rad, rad^2); "
                 "status ok / degraded / suspect / lost; why: what made it so")
STATUS_COLUMNS = ("t", "x", "y", "yaw", "status", "cov_xx", "cov_xy", "cov_xyaw", "cov_yy", "cov_yyaw", "cov_yawyaw",
                  "why")


def status_rows(poses: Any, online: Any, monitor: ConsistencyMonitor) -> list[list[Any]]:
    """One row per pose of the trajectory ``poses`` (:data:`STATUS_COLUMNS`): its status and why, and
    the covariance of the ``online`` trajectory's pose nearest in time (NaN when it has none)."""
    st = np.asarray(poses.stamps, dtype=float)
    status, why = monitor.at(st)
    cov = np.full((len(st), 3, 3), np.nan)
    o_t = np.asarray(online.stamps, dtype=float)
    o_c = getattr(online, "covs", None)
    if o_c is not None and len(o_t):
        j = np.clip(np.searchsorted(o_t, st), 0, len(o_t) - 1)
        jm = np.clip(j - 1, 0, len(o_t) - 1)
        j = np.where(np.abs(o_t[jm] - st) < np.abs(o_t[j] - st), jm, j)
        cov[:] = np.asarray(o_c, dtype=float)[j]
    rows = []
    for k in range(len(st)):
        c = cov[k]
        p = poses.poses[k]
        rows.append([float(st[k]), float(p[0]), float(p[1]), float(p[2]), status[k], float(c[0, 0]), float(c[0, 1]),
                     float(c[0, 2]), float(c[1, 1]), float(c[1, 2]), float(c[2, 2]), why[k]])
    return rows


def status_csv(rows: list[list[Any]]) -> str:
    """The text of ``trajectory_status.csv`` (:data:`STATUS_HEADER`, a column line, one line per row)."""
    import csv
    import io

    buf = io.StringIO()
    buf.write(STATUS_HEADER + "\n")
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(STATUS_COLUMNS)
    for r in rows:
        w.writerow([f"{r[0]:.9f}", *(repr(v) for v in r[1:4]), r[4], *(repr(v) for v in r[5:11]), r[11]])
    return buf.getvalue()


__all__ = ["DEGRADED", "LOST", "OK", "STATUSES", "STATUS_COLUMNS", "STATUS_HEADER", "SUSPECT", "ConsistencyMonitor",
           "DeadReckoning", "IntegrityConfig", "MapAgreement", "Verdict", "status_csv", "status_rows"]
