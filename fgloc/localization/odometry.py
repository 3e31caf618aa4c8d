"""Odometry handling: the twist to integrate and the dead-reckoned ``odom`` pose.

:class:`OdometryTracker` checks each wheel-odometry message, decides which body twist the
back-end integrates (the message's own, or robot_localization's differential mode: the
twist of the pose increment when the message's twist disagrees with it) and keeps the
dead-reckoned ``odom`` pose the front-ends use for their ``odom_delta`` (de-skew, motion
model).  Core maths: no I/O.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

import numpy as np

from fgloc.backends.base import FloatArray
from fgloc.geometry import between1, between_values, compose1, exp_values
from fgloc.geometry import log as se2_log
from fgloc.localization.config import PipelineConfig
from fgloc.localization.sources import UNUSED_VAR

#: s: pose_deltas auto compares the twist with the pose increments summed over this long (stamp
#: jitter and a noisy twist cancel out over it; a missing or partial twist does not)
AGREEMENT_WINDOW_S = 1.0
#: pose_deltas auto: a twist whose increments match the pose increments one message earlier or later
#: than its own (a simulator that publishes with each pose the velocity of the step that follows it:
#: Stage) is offset in time; mixing its increments with pose increments counts one message's motion
#: twice or not at all at each switch.  It is offset once its mismatch at that shift, summed over the
#: run, is at most OFFSET_RATIO of the mismatch at its own stamp, by at least OFFSET_EVIDENCE
#: tolerances (``pose_delta_tolerance_m`` / ``_deg``): the pose increments are then taken
OFFSET_RATIO = 0.5
OFFSET_EVIDENCE = 50.0
#: a pose-derived twist is a velocity to extrapolate with only over a time baseline of at least
#: this fraction of the source's mean period (over its last :data:`RATE_WINDOW` poses), at most (and
#: until that is known) :data:`MAX_BASELINE_S`: loggers that stamp late and in bursts deliver
#: several poses within a millisecond (two poses 169 us and 4 cm apart are "240 m/s")
BASELINE_FRACTION = 0.5
MAX_BASELINE_S = 0.05
RATE_WINDOW = 16
#: s: the long-run mean period over this long (at least :data:`RATE_WINDOW` poses) bounds how many
#: increments a velocity to extrapolate with may average over a short time (a logger's flush)
LONG_RATE_WINDOW_S = 5.0
#: s: the longest span a bursty source's velocity measurement is averaged over (see
#: :meth:`OdometryTracker.velocity_measurement`)
VELOCITY_SPAN_MAX_S = 0.25


def _carried(pose: FloatArray | list[float], tw: FloatArray, dt: float) -> FloatArray:
    """``compose1(pose, exp(tw * dt))``: ``pose`` carried on with the twist ``tw`` for ``dt``."""
    return compose1(pose, exp_values(tw, dt))  # type: ignore[arg-type]


def _zero_unused(tw: FloatArray, unused: tuple[bool, bool, bool]) -> FloatArray:
    """``tw`` with the components the source does not fuse set to 0 (``tw`` itself when it fuses all)."""
    if unused[0] or unused[1] or unused[2]:
        return np.array([0.0 if unused[i] else float(tw[i]) for i in range(3)])
    return tw


class TwistOffset:
    """Whether a source's twist is one message ahead of or behind its pose increments (see
    :data:`OFFSET_RATIO`): each pose increment's mismatch with the increments of the twists of the
    message before it, its own and the one after it, summed over the run in units of the agreement
    tolerances (the three sums over the same increments: a twist that is always 0 gives three equal
    sums)."""

    def __init__(self, tol_m: float, tol_deg: float) -> None:
        self.tol_m = tol_m
        self.tol_rad = math.radians(tol_deg)
        self.err = [0.0, 0.0, 0.0]   # twist of message k-1, k, k+1 against the pose increment k
        self.shift = 0               # -1: the twist leads its poses, +1: it lags them, 0: neither
        # the last three messages: (previous pose's stamp, stamp, twist values, pose increment, twist increment)
        self._last: deque[tuple[float, float, list[float], tuple[float, float, float],
                                tuple[float, float, float]]] = deque(maxlen=3)

    def _mismatch(self, a: tuple[float, float, float], b: tuple[float, float, float],
                  unused: tuple[bool, bool, bool]) -> float:
        lin = 0.0 if unused[0] and unused[1] else math.hypot(a[0] - b[0], a[1] - b[1]) / self.tol_m
        rot = 0.0 if unused[2] else abs(math.remainder(a[2] - b[2], math.tau)) / self.tol_rad
        return lin + rot

    def add(self, t_prev: float, t: float, tw: list[float], delta: tuple[float, float, float],
            d_tw: tuple[float, float, float], unused: tuple[bool, bool, bool]) -> int:
        """One message's pose increment over ``(t_prev, t]`` and its twist; returns :attr:`shift`
        (the previous message's increment is scored once this one's twist is known)."""
        last = self._last
        if last and last[-1][1] != t_prev:
            last.clear()  # a message without a pose in between: the neighbours are not known
        last.append((t_prev, t, tw, delta, d_tw))
        if len(last) < 3:
            return self.shift
        before, (tp, tm, _, dm, d_own) = last[0], last[1]
        if dm[0] == 0.0 and dm[1] == 0.0 and dm[2] == 0.0:
            return self.shift  # poses frozen or standing still: no evidence
        dt = tm - tp
        self.err[0] += self._mismatch(exp_values(before[2], dt), dm, unused)
        self.err[1] += self._mismatch(d_own, dm, unused)
        self.err[2] += self._mismatch(exp_values(tw, dt), dm, unused)
        e_lead, e0, e_lag = self.err
        best = min(e_lead, e_lag)
        self.shift = (-1 if e_lead <= e_lag else 1) \
            if best <= OFFSET_RATIO * e0 and e0 - best >= OFFSET_EVIDENCE else 0
        return self.shift


class OdometryTracker:
    """The dead-reckoned odom pose and the twist to integrate (see the module docstring)."""

    def __init__(self, cfg: PipelineConfig) -> None:
        self.cfg = cfg
        self.pose = np.zeros(3)            # dead-reckoned odom pose at ``t``
        self.t: float | None = None        # stamp of the last odometry message
        self.first_t: float | None = None
        self.twist = np.zeros(3)           # the last twist integrated (held until the next message)
        self.from_poses = 0                # twists taken from pose increments
        self._prev_pose: tuple[float, FloatArray | list[float]] | None = None  # (stamp, pose) of the last message
        self._scale_sig = np.asarray(cfg.pose_delta_sigmas, dtype=float)
        self.offset = TwistOffset(cfg.pose_delta_tolerance_m, cfg.pose_delta_tolerance_deg)
        # auto mode's agreement window: (t, pose increment, twist increment, poses moved) and sums
        self._window: deque[tuple[Any, ...]] = deque()  # (t, pose increment, twist increment, length, |turn|, moved)
        self._sums = [0.0] * 8  # pose increments (3), twist increments (3), path length, |turn|
        self._moved = 0
        # stamps of the last RATE_WINDOW poses (the source's mean period), the recent odom poses, and
        # whether the last twist came from a pose increment shorter than the baseline (a burst)
        self._stamps: deque[float] = deque(maxlen=RATE_WINDOW + 1)
        self._long_stamps: deque[float] = deque()  # pose stamps of the last LONG_RATE_WINDOW_S (>= RATE_WINDOW + 1)
        self._recent: deque[tuple[float, FloatArray]] = deque(maxlen=4 * RATE_WINDOW)
        self._short = False
        self._derived = False              # whether the last twist came from a pose increment
        self._short_flags: deque[bool] = deque(maxlen=RATE_WINDOW)  # the last pose-derived ones: short?
        self.short_increments = 0          # pose increments over less than the baseline (bursty stamps)
        self.carried = 0                   # twists handed on to a scan stamp after a burst (carry_to)
        self._last_out: tuple[FloatArray, FloatArray | None] = (np.zeros(3), None)  # the last step's result
        #: ``(twist, dt, exp_values(twist, dt))`` of the message being taken, when _twist computed it
        self._increment: tuple[FloatArray, float, tuple[float, float, float]] | None = None

    def step(self, t: float, twist: FloatArray, cov: FloatArray | None, pose: FloatArray | None,
             cov_finite: bool | None = None, twist_values: list[float] | None = None
             ) -> tuple[FloatArray, FloatArray | None]:
        """Take one odometry message (its stamp and twist checked); returns the twist and covariance
        to integrate.  A pose or covariance that is not all finite is dropped (``cov_finite``:
        whether ``cov`` is, when the caller knows; ``twist_values``: ``twist.tolist()``, when it has
        them).

        A component the source does not fuse (variance ``UNUSED_VAR``) is handed to the back-end as
        0 (with that variance): its value must not shape the others either (a skid steer's wheel yaw
        rate, several times the true one, would bend every integrated increment's translation).  The
        dead-reckoned odom pose for the front-ends keeps the message's twist.

        Scalar maths per message (called at the odometry's rate): no temporary arrays but the
        pose and twist handed on.
        """
        pv = None  # the pose's floats
        if pose is not None:
            pv = pose.tolist() if pose.shape == (3,) else None
            if pv is None or not math.isfinite(sum(pv)):
                pv = None  # finiteness by the sum of the values (one scalar test, as for the twist)
        if cov is not None and not (math.isfinite(float(np.asarray(cov, dtype=float).sum())) if cov_finite is None
                                    else cov_finite):
            cov = None
        unused = self._unused(cov)
        tw, cov = self._twist(t, twist, cov, pv, unused, twist_values)
        if cov is not None and tw is not twist:
            unused = self._unused(cov)  # a pose-derived twist's covariance keeps the unused ones
        # dead-reckoned odom pose (for the front-end's odom_delta); twist held backwards
        if self.t is not None:
            inc, self._increment = self._increment, None
            dt = t - self.t
            if inc is not None and inc[0] is tw and inc[1] == dt:  # _twist's increment of this message
                self.pose = compose1(self.pose, inc[2])  # type: ignore[arg-type]  # (floats: indexed)
            else:
                self.pose = _carried(self.pose, tw, dt)
        self.t = t
        self.twist = tw
        self._recent.append((t, self.pose))
        if self.first_t is None:
            self.first_t = t
        if unused[0] or unused[1] or unused[2]:
            tw = _zero_unused(tw, unused)
        self._last_out = (tw, cov)
        return tw, cov

    def pose_at(self, t: float) -> FloatArray:
        """The odom pose at ``t``: the last message's pose carried on (or back) with its twist,
        when ``t`` is within ``odom_extrapolate_max_s`` of it (slow or late odometry must not hand
        the front-end a stale motion for its de-skew); else the last pose as it is."""
        if self.t is not None and abs(t - self.t) <= self.cfg.odom_extrapolate_max_s:
            return _carried(self.pose, self.extrapolation_twist(), t - self.t)
        return self.pose

    @property
    def burst(self) -> bool:
        """Whether the last twist came from a pose increment shorter than the baseline (a burst of
        stamps): integrated it meets the pose increment, as a velocity it is absurd (intel: two
        poses 169 us / 4 cm apart, 240 m/s); :meth:`extrapolation_twist` is the velocity then."""
        return self._short and len(self._recent) >= 2

    def velocity_measurement(self) -> tuple[FloatArray, FloatArray | None] | None:
        """The last message's twist and covariance as a velocity measurement, for a back-end whose
        velocity state the odometry measures instead of integrating its increments (the EKF).

        A pose-derived twist from a source that delivers its poses in bursts (an increment shorter
        than the baseline among the last :data:`RATE_WINDOW`) is no velocity: a burst's is absurd
        (240 m/s), the long step before it holds still while the robot moved (the poses are stale
        until the burst).  Then the mean velocity over the last poses spanning the longest of those
        steps (a whole stale step and its burst; at most :data:`VELOCITY_SPAN_MAX_S`), with a
        pose-derived twist's covariance for that speed; None (no measurement) while the poses kept
        span less.  Otherwise the twist integrated."""
        tw, cov = self._last_out
        if not self._derived or not any(self._short_flags):
            return tw, cov
        st = self._stamps
        longest = max((b - a for a, b in zip(st, list(st)[1:], strict=False)), default=0.0)
        v = self._mean_velocity(min(max(longest, self._baseline()), VELOCITY_SPAN_MAX_S))
        if v is None:
            return None  # the first burst of the stream: no velocity is known yet
        return self._as_pose_derived(v, tw, cov)

    def carry_to(self, t: float) -> tuple[FloatArray, FloatArray | None] | None:
        """After a burst (:attr:`burst`), for a back-end that integrates the odometry's increments
        and holds the last twist past its last stamp (the smoother): the twist and covariance to
        hand it at ``t`` (a scan's stamp) so that it holds a velocity, not the burst's increment:
        :meth:`extrapolation_twist` over ``(last stamp, t]``.  The odom pose and the pose the next
        increment starts from move to ``t`` with it, so what the back-end integrates still meets
        the next message's pose exactly.  None (nothing to hand on) without a burst, when ``t`` is
        not after the last stamp, or more than ``odom_extrapolate_max_s`` after it."""
        if not self.burst or self.t is None or self._prev_pose is None:
            return None
        dt = t - self.t
        if not 0.0 < dt <= self.cfg.odom_extrapolate_max_s:
            return None
        tw, cov = self._last_out
        v = self.extrapolation_twist()
        t_prev, p_prev = self._prev_pose
        self._prev_pose = (t, _carried(p_prev, v, t - t_prev))
        self.pose = _carried(self.pose, v, dt)
        self.t = t
        self.twist = v
        self._short = False
        self.carried += 1
        out_v, out_cov = self._as_pose_derived(v, tw, cov)
        out_v = _zero_unused(out_v, self._unused(out_cov))
        self._last_out = (out_v, out_cov)
        return out_v, out_cov

    def _as_pose_derived(self, v: FloatArray, tw: FloatArray, cov: FloatArray | None,
                         unused: tuple[bool, bool, bool] | None = None) -> tuple[FloatArray, FloatArray]:
        """``v`` with a pose-derived twist's covariance for its speed; the source's unused components
        (``unused``, else from ``cov``) stay as the message gave them (``tw``, ``cov``), unused."""
        if unused is None:
            unused = self._unused(cov)
        speed = math.hypot(float(v[0]), float(v[1]))
        rel = self.cfg.pose_delta_rel
        sig = (float(self._scale_sig[0]) + rel * speed, float(self._scale_sig[1]) + rel * speed,
               float(self._scale_sig[2]) + rel * (abs(float(v[2])) + speed))
        out = np.diag(np.square(sig))
        if (unused[0] or unused[1] or unused[2]) and cov is not None:
            c3 = np.asarray(cov, dtype=float).reshape(3, 3)
            for i in range(3):
                if unused[i]:
                    out[i, i] = float(c3[i, i])
            v = np.array([float(tw[i]) if unused[i] else float(v[i]) for i in range(3)])
        return v, out

    def extrapolation_twist(self) -> FloatArray:
        """The velocity to carry the odom pose past the last message with: the last twist, unless
        it came from a pose increment shorter than the baseline (:data:`BASELINE_FRACTION`): then
        the mean velocity over the last poses that span at least the baseline.  Integrating the
        pose increments stays exact (``twist``); only what is extrapolated from a burst changes
        (intel's 240 m/s pose-delta twist put the next scan's guess 16.8 m off)."""
        if not self.burst:
            return self.twist
        v = self._spread_velocity()
        return np.zeros(3) if v is None else v

    def _spread_velocity(self) -> FloatArray | None:
        """The mean velocity from the last pose back to the latest one that is at least the baseline
        before it and at least half the source's long-run mean period (:data:`LONG_RATE_WINDOW_S`)
        per increment in between: a logger that stalled and then flushed a second of poses within
        milliseconds packs many increments into the last poses; the window reaches back past them
        (a pair of poses 0.3 ms apart after a 40 ms step: the two increments, as the baseline)."""
        lt = self._long_stamps
        per = (lt[-1] - lt[0]) / (len(lt) - 1) if len(lt) > RATE_WINDOW else 0.0
        base = self._baseline()
        t1, p1 = self._recent[-1]
        n = 0
        for tj, pj in reversed(self._recent):
            if tj >= t1:
                continue
            n += 1
            if t1 - tj >= base and t1 - tj >= n * BASELINE_FRACTION * per:
                return se2_log(between1(pj, p1)) / (t1 - tj)
        return None

    def _mean_velocity(self, span_s: float) -> FloatArray | None:
        """The mean body velocity from the last odom pose back to the latest one at least ``span_s``
        before it; None while the poses kept span less (the first burst of a stream: no velocity
        is known yet, and the mean over its microseconds is as absurd as its last increment)."""
        t1, p1 = self._recent[-1]
        for tj, pj in reversed(self._recent):
            if t1 - tj >= span_s and t1 - tj > 0:
                return se2_log(between1(pj, p1)) / (t1 - tj)
        return None

    def _twist(self, t: float, tw: FloatArray, cov: FloatArray | None, pose: list[float] | None,
               unused: tuple[bool, bool, bool] | None = None, tw_values: list[float] | None = None
               ) -> tuple[FloatArray, FloatArray | None]:
        """The body twist to integrate: the message's, or the dead-reckoned pose's differential.

        robot_localization's differential mode: when the source carries poses and its twist
        disagrees with the pose increments (CARMEN logs that leave tv = rv = 0, or rv = 0 while
        the pose turns) by more than ``pose_delta_tolerance_m/_deg`` (+10 % of the motion) summed
        over the last :data:`AGREEMENT_WINDOW_S` (a twist that is noisy message by message but
        describes the motion, as a Husky's, is the better measurement: robot_localization fuses
        it), or ``pose_deltas: always``, the twist is ``log(between(prev_pose, pose)) / dt`` (held over ``(t_prev, t]``
        like an encoder twist, so integrating it reproduces the pose increment exactly).  Its
        covariance then grows with the motion (``pose_delta_sigmas`` + ``pose_delta_rel`` *
        |twist|): the poses' stamps are often where the error is (bursty logger stamps).

        Only the components the source contributes are taken from the poses: a component whose
        variance is :data:`~fgloc.localization.sources.UNUSED_VAR` (not in the source's ``use``)
        keeps the message's value and that variance, and plays no part in the ``auto`` agreement
        test (an odometry fusing only vx, vy never brings its wheel yaw in through its poses).
        A twist offset in time from its poses by one message (:class:`TwistOffset`) is not taken:
        its increments would agree only where the velocity does not change.
        Poses that do not move at all over the window while the twist does are not filled in by
        the driver (an AR.Drone's odometry leaves them at zero): the twist is kept.
        """
        prev = self._prev_pose
        pv = pose  # (the pose's floats: read here and by the next message)
        self._prev_pose = None if pv is None else (t, pv)
        self._increment = None
        self._short = False
        self._derived = False
        mode = self.cfg.pose_deltas
        if pv is None or prev is None or mode == "never":
            return tw, cov
        dt = t - prev[0]
        if not dt > 0:
            return tw, cov
        self._stamps.append(t)
        lt = self._long_stamps
        lt.append(t)
        while len(lt) > RATE_WINDOW + 1 and lt[0] < t - LONG_RATE_WINDOW_S:
            lt.popleft()
        if unused is None:
            unused = self._unused(cov)
        if unused[0] and unused[1] and unused[2]:
            return tw, cov
        delta = between_values(prev[1], pv)
        tv = tw.tolist() if tw_values is None else tw_values
        d_tw = exp_values(tv, dt)
        self._increment = (tw, dt, d_tw)  # step() carries the odom pose by the same increment
        offset = mode == "auto" and self.offset.add(prev[0], t, tv, delta, d_tw, unused) != 0
        if mode != "always" and self._agrees(t, delta, d_tw, unused) and not offset:
            # auto: keep the twist while it agrees with the pose increments (a simulator, a good
            # driver); CARMEN logs leave tv = rv = 0 (intel, aces) or rv = 0 (fr079)
            if self._moved:
                # poses that move and agree: the twist is as good as derived from them (a reader
                # that differences burst-stamped poses), so the burst guard of
                # velocity_measurement applies to it too
                self._derived = True
                self._short_flags.append(dt < self._baseline())
            return tw, cov
        u = se2_log(np.array(delta)) / dt
        self.from_poses += 1
        self._derived = True
        if dt < self._baseline():
            self._short = True
            self.short_increments += 1
        self._short_flags.append(self._short)
        return self._as_pose_derived(u, tw, cov, unused)

    def _baseline(self) -> float:
        """The shortest pose increment whose twist is a velocity to extrapolate with (s):
        :data:`BASELINE_FRACTION` of the source's mean period over its last :data:`RATE_WINDOW`
        poses, at most (and until that is known) :data:`MAX_BASELINE_S`."""
        st = self._stamps
        if len(st) <= RATE_WINDOW:
            return MAX_BASELINE_S
        return min(BASELINE_FRACTION * (st[-1] - st[0]) / (len(st) - 1), MAX_BASELINE_S)

    def _agrees(self, t: float, delta: tuple[float, float, float], d_tw: tuple[float, float, float],
                unused: tuple[bool, bool, bool]) -> bool:
        """Whether the twist's increments and the poses' agree, summed over the window ending at ``t``
        (running sums in Python floats: this runs for every odometry message that carries a pose)."""
        win = self._window
        d0, d1, d2 = delta
        e0, e1, e2 = d_tw
        moved = d0 != 0.0 or d1 != 0.0 or d2 != 0.0
        lin_d, rot_d = math.hypot(d0, d1), abs(d2)
        win.append((t, d0, d1, d2, e0, e1, e2, lin_d, rot_d, moved))
        s = self._sums
        s[0] += d0
        s[1] += d1
        s[2] += d2
        s[3] += e0
        s[4] += e1
        s[5] += e2
        s[6] += lin_d
        s[7] += rot_d
        self._moved += moved
        while len(win) > 1 and win[0][0] <= t - AGREEMENT_WINDOW_S:
            old = win.popleft()
            s[0] -= old[1]
            s[1] -= old[2]
            s[2] -= old[3]
            s[3] -= old[4]
            s[4] -= old[5]
            s[5] -= old[6]
            s[6] -= old[7]
            s[7] -= old[8]
            self._moved -= old[9]
        if not self._moved:
            return True  # poses frozen: not filled in by the driver (or standing still: both agree)
        lin, rot = max(s[6], 0.0), max(s[7], 0.0)
        tol_lin = self.cfg.pose_delta_tolerance_m + 0.1 * lin
        tol_rot = math.radians(self.cfg.pose_delta_tolerance_deg) + 0.1 * rot
        lin_ok = bool(unused[0] and unused[1]) or math.hypot(s[3] - s[0], s[4] - s[1]) <= tol_lin
        rot_ok = bool(unused[2]) or abs(s[5] - s[2]) <= tol_rot
        return lin_ok and rot_ok

    @staticmethod
    def _unused(cov: FloatArray | None) -> tuple[bool, bool, bool]:
        """Which of vx, vy, vyaw the source does not contribute (variance UNUSED_VAR or more)."""
        if cov is None:
            return (False, False, False)
        c = cov if isinstance(cov, np.ndarray) and cov.shape == (3, 3) else np.asarray(cov, dtype=float).reshape(3, 3)
        return (c.item(0) >= UNUSED_VAR, c.item(4) >= UNUSED_VAR, c.item(8) >= UNUSED_VAR)
