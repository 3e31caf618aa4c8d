"""The buffered sensor streams, queried between any two stamps: the odometry's integrated increment,
a gyro's bias-free yaw change, the heading change from whichever covers an interval, the twist and
yaw rate at a stamp, and the timing uncertainty of a slow odometry."""

from __future__ import annotations

import math
from bisect import bisect_left, bisect_right
from operator import sub

import numpy as np

from fgloc.backends.base import FloatArray
from fgloc.backends.health.latency import MAX_REF_PERIOD_S, StepMedian
from fgloc.backends.integration import (
    TwistValues,
    chord_step,
    covering,
    integrate_heading,
    integrate_twist_values,
    rate_integral,
    twist_arrays,
)
from fgloc.backends.smoother.covariance import TWIST_VAR_MAX, carried_motion
from fgloc.backends.smoother.state import SmootherState
from fgloc.geometry import adjoint, between1, compose1, exp_coefficients, inverse1, wrap_scalar
from fgloc.geometry import exp as se2_exp
from fgloc.geometry import log as se2_log

#: the odometry's mean message period for :meth:`SlidingWindowSmoother._timing_var` is taken over this many
TIMING_MESSAGES = 200

#: s, an odometry step longer than this and than :data:`ODOM_GAP_STEPS` times the longest of its last
#: :data:`ODOM_GAP_WINDOW` steps leaves the motion beyond it unmeasured (a dead wheel driver, a dropped
#: stretch; as ``integrity.odometry_gap_s``); a slow or bursty odometry's own rhythm (CARMEN logs: four
#: poses within milliseconds, then nothing for 0.4 s) is no gap
ODOM_GAP_S = 0.25
ODOM_GAP_STEPS = 2.0
ODOM_GAP_WINDOW = 50
#: m/s, an odometry that has reported sideways speeds above this drives an omni base (the EKF's omni_vy_mps)
LATERAL_SPEED = 0.05
#: m/s, an odometry that has reported a sideways speed above this (with a usable variance) has a sideways
#: axis (a mecanum / omni base): its drift per metre forward is estimated sideways too
SIDEWAYS_REPORTED_MPS = 1e-4


class Streams(SmootherState):
    """Queries on the sensor buffers (no graph change)."""

    def _period_of(self, ts: list[float]) -> float:
        """:func:`_period` of a stamp list, remembered until it changes (a stamp list only grows at
        its end with later stamps, or loses its oldest: its length and last stamp tell)."""
        key = (id(ts), len(ts), ts[-1] if ts else None)
        got = self._periods.get(key)
        if got is None or got[0] is not ts:
            if len(self._periods) > 8:
                self._periods.clear()
            sm = self._step_medians.get(id(ts))
            if sm is None:
                if len(self._step_medians) > 8:
                    self._step_medians.clear()
                sm = self._step_medians[id(ts)] = StepMedian()
            got = self._periods[key] = (ts, sm.of(ts))
        return got[1]

    def _gyro_increment(self, name: str, t0: float, t1: float, max_gap: float = 0.25, want_var: bool = True
                        ) -> tuple[float, float] | None:
        """Bias-free gyro yaw change over ``(t0, t1]`` and its variance, or None when the readings
        do not cover the interval.  A gyro reading is the rate at its stamp: the rate is
        interpolated linearly between readings and integrated exactly (holding a reading over the
        interval before it would lead the heading by half a reading period).

        The variance is each reading's share of its whole weight: a reading with weight ``w`` here
        and ``W`` over all intervals adds ``var * w * W`` (not ``var * w^2``).  Neighbouring
        keyframe intervals share readings, so their increments are correlated; independent
        factors with ``var * w^2`` each claimed the integrated gyro 2-3x better (in variance) than
        it is once keyframes come faster than readings, and the gyro's random walk wobbles the
        heading.  With the shares the factors of consecutive
        intervals add up to the exact variance of the gyro's integral over them.  ``want_var=False``:
        the variance is not computed (returned as 0)."""
        got = self.gyro.get(name)   # (no default: .get's would build three lists at every call)
        if got is None:
            return None
        ts, rs, vs = got
        if not ts or ts[-1] < t1 - 1e-9 or ts[0] > t0 + 1e-9:
            return None
        # the same interval over the same readings again (a keyframe's relative-yaw increment, then its
        # gyro factor; the predictions' and the compass's rotations): the same integral (the lists only
        # grow at their end or lose their oldest: length and end stamps tell); the bias, which may have
        # moved in between, is taken off anew
        key = (name, t0, t1, max_gap, want_var, len(ts), ts[0], ts[-1])
        memo = self._gyro_memo
        raw = memo.get(key)
        if raw is not None:
            return None if raw[0] is None else (raw[0] - self.gyro_bias_of(name) * (t1 - t0), raw[1])
        if len(memo) >= 16:
            memo.clear()
        if not want_var:
            # predictions and motion corrections integrate from the same starts (the newest keyframe, an anchor
            # fix tens of seconds back) to later and later stamps: resumed (the least recently used start dropped)
            marks = self._rate_marks
            mark = marks.pop((name, t0), None)
            if mark is None:
                mark = []
                if len(marks) >= 8:
                    del marks[next(iter(marks))]
            marks[(name, t0)] = mark
            i0 = bisect_right(ts, t0) - 1
            d = rate_integral(ts, rs, t0, t1, 0 if 0 > i0 else i0, max_gap, mark=mark)
            memo[key] = (d, 0.0)
            return None if d is None else (d - self.gyro_bias_of(name) * (t1 - t0), 0.0)
        n = len(ts)
        w: dict[int, float] = {}
        d = rate_integral(ts, rs, t0, t1, max(bisect_right(ts, t0) - 1, 0), max_gap, w)
        if d is None:
            memo[key] = (None, 0.0)
            return None
        var = 0.0
        for m, ww in w.items():
            # the gaps either side (at the buffer's ends: the one gap known, twice)
            before = ts[m] - ts[m - 1] if m > 0 else None
            after = ts[m + 1] - ts[m] if m + 1 < n else None
            if before is None:
                before = after if after is not None else 0.0
            if after is None:
                after = before
            # max(0.5 * (min(before, max_gap) + min(after, max_gap)), ww) without the builtins' calls
            h = 0.5 * ((max_gap if max_gap < before else before) + (max_gap if max_gap < after else after))
            var += vs[m] * ww * (ww if ww > h else h)
        memo[key] = (d, var)
        return d - self.gyro_bias_of(name) * (t1 - t0), var

    def _gyro_rate_at(self, t: float) -> float | None:
        """The first gyro's bias-corrected rate at ``t`` (interpolated), or None."""
        for name, (ts, rs, _) in self.gyro.items():
            if ts and ts[0] <= t <= ts[-1]:
                i = bisect_left(ts, t)
                i = 1 if 1 > i else i
                i = len(ts) - 1 if len(ts) - 1 < i else i
                ta, tb = ts[i - 1], ts[i]
                f = (t - ta) / (tb - ta) if tb > ta else 1.0
                return rs[i - 1] + f * (rs[i] - rs[i - 1]) - self.gyro_bias_of(name)
        return None

    def _integrate(self, t0: float, t1: float) -> tuple[FloatArray, FloatArray]:
        if not self.odo_t:
            return np.zeros(3), np.diag(np.square(self.cfg.encoder_sigmas)) * max(t1 - t0, 1e-3) ** 2
        return twist_arrays(self._integrate_values(t0, t1))

    def _integrate_values(self, t0: float, t1: float) -> TwistValues:
        """:meth:`_integrate` as floats (:func:`integrate_twist_values`; the odometry has samples)."""
        # the same interval over the same samples again (the output floor's increment from the fix's
        # keyframe after the prediction from it): the same answer (the lists only grow at their end or
        # lose their oldest: length and end stamps tell)
        key = (t0, t1, len(self.odo_t), self.odo_t[0], self.odo_t[-1])
        memo = self._integrate_memo
        if memo is not None and memo[0] == key:
            return memo[1]
        i0, i1 = covering(self.odo_t, t0, t1)
        # the predictions integrate from the newest keyframe again and again (~4 times per keyframe,
        # to later and later stamps): each resumes from the last one's completed steps
        mark = self._int_marks.get(t0)
        if mark is None:
            if len(self._int_marks) >= 4:
                del self._int_marks[next(iter(self._int_marks))]
            mark = self._int_marks[t0] = []
        out = integrate_twist_values(self.odo_t, self.odo_u, self.odo_c, i0, i1, t0, t1, self._q_slip, mark)
        self._integrate_memo = (key, out)
        return out

    def _odom_gap_s(self) -> float:
        """The longest step a running odometry leaves between two stamps (inf with fewer than 3),
        remembered until a message comes."""
        ts = self.odo_t
        n = len(ts)
        key = (n, ts[-1] if ts else None)
        memo = self._gap_memo
        if memo[0] != key:
            if n < 3:
                tol, top, ti = math.inf, math.nan, -1
            else:
                # stamps appended since: the window's longest step stays while its last occurrence (ending at ti) does
                top, ti, m, w = memo[2], memo[3], (memo[0][0] if memo[0] else 0), ODOM_GAP_WINDOW
                if w + 1 < m < n <= m + w and ts[m - 1] == memo[0][1] and ti >= n - w:
                    for j in range(m, n):
                        step = ts[j] - ts[j - 1]
                        if step >= top:
                            top, ti = step, j
                else:
                    last = ts[-w - 1:]
                    d = list(map(sub, last[1:], last[:-1]))
                    ti = n - 1 - d[::-1].index(top := max(d))
                tol = max(ODOM_GAP_S, ODOM_GAP_STEPS * top)
            self._gap_memo = memo = (key, tol, top, ti)
        return memo[1]

    def _unmeasured_tail(self, t0: float, t1: float, tol: float | None = None) -> float:
        """How long the end of ``(t0, t1]`` lies beyond the odometry's newest stamp by more than a
        running odometry's gap (``tol``, default :meth:`_odom_gap_s`): 0 while it runs, the time since
        it stopped."""
        if not self.odo_t:
            return 0.0
        end = self.odo_t[-1] + (self._odom_gap_s() if tol is None else tol)
        return t1 - max(t0, end) if end < t1 else 0.0

    def _gap_s(self, t0: float, t1: float, tol: float | None = None) -> float:
        """How long of ``(t0, t1]`` falls into steps between two odometry stamps beyond a running
        odometry's gap (``tol``, default :meth:`_odom_gap_s`): a stretch it dropped, its first twist
        after held over it."""
        ts = self.odo_t
        if tol is None:
            tol = self._odom_gap_s()
        if len(ts) < 2 or not math.isfinite(tol):
            return 0.0
        out = 0.0
        i = bisect_right(ts, t0) - 1
        i = 0 if 0 > i else i
        hi = bisect_left(ts, t1)
        hi = len(ts) - 1 if len(ts) - 1 < hi else hi
        while i < hi:
            a, b = ts[i] + tol, ts[i + 1]   # max(a, t0), min(b, t1) without the builtins' calls
            if t0 > a:
                a = t0
            if t1 < b:
                b = t1
            if b > a:
                out += b - a
            i += 1
        return out

    def _graph_twist(self, t: float) -> tuple[FloatArray, FloatArray] | None:
        """The body twist ``[vx, vy, w]`` the graph's keyframes moved with up to ``t`` (the newest one
        at or before ``t`` against the newest at least :data:`ODOM_GAP_S` before it) and its variances:
        the last fix's over that time (both ends), plus a random walk since that fix
        (``unmeasured_accel_q``, ``unmeasured_turn_q``); sideways only where the odometry has reported
        sideways motion (an omni base; a wheeled one's sideways speed stays the odometry's).  None
        without two such keyframes or a fix."""
        j = bisect_right(self.kf_t, t) - 1
        i = bisect_right(self.kf_t, self.kf_t[j] - ODOM_GAP_S) - 1 if j >= 0 else -1
        pa = self.kf_pose.get(self.kf_key[i]) if i >= 0 else None
        pb = self.kf_pose.get(self.kf_key[j]) if j >= 0 else None
        fl = self._fix_floor
        if pa is None or pb is None or i == j or fl is None:
            return None
        dt = self.kf_t[j] - self.kf_t[i]
        since = max(0.0, t - fl[0])
        fc = fl[2]
        var_v = 2.0 * 0.5 * float(fc[0, 0] + fc[1, 1]) / (dt * dt) + self.cfg.unmeasured_accel_q * since
        var_w = 2.0 * float(fc[2, 2]) / (dt * dt) + self.cfg.unmeasured_turn_q * since
        tw = se2_log(between1(pa, pb)) / dt
        if self._odo_lateral_max > LATERAL_SPEED or not self.odo_c:   # no odometry: any base
            var_vy = var_v
        else:
            tw[1] = 0.0
            var_vy = float(self.odo_c[-1][3])
        return tw, np.array([var_v, var_vy, var_w])

    def _motion(self, t0: float, t1: float) -> tuple[FloatArray, FloatArray]:
        """The motion over ``(t0, t1]`` as far as the odometry measures it (:meth:`_integrate`), with
        what it does not: beyond its newest stamp (a dead wheel driver), the graph's own recent motion
        (:meth:`_graph_twist`) carried on, with that twist's variance over the time plus a random walk
        of the velocity over it; over a stretch it dropped, the first twist after it with its variance
        up to the fastest the odometry has shown.  Integrated as measured, a stopped odometry's last
        twist with its small covariance outweighs the fixes and drags the path on."""
        if not self.odo_t:   # none at all (scans on a map): the graph's own velocity carried on
            return carried_motion(self._graph_twist(t0), self.cfg.scans_only_twist_sigma,
                                  self.cfg.unmeasured_accel_q, self.cfg.unmeasured_turn_q, t1 - t0)
        tol = self._odom_gap_s()
        tail = self._unmeasured_tail(t0, t1, tol)
        gap = self._gap_s(t0, t1 - tail, tol)
        if tail <= 0.0 and gap <= 0.0:
            return self._integrate(t0, t1)
        qv, qw = self.cfg.unmeasured_accel_q, self.cfg.unmeasured_turn_q
        d, c = self._integrate(t0, t1 - tail)
        c = c.copy()
        if gap > 0.0:
            sv = max(self._odo_speed_max, self.cfg.encoder_sigmas[0]) ** 2
            c[0, 0] += sv * gap * gap + qv * gap ** 3 / 3.0
            c[2, 2] += max(self._odo_rate_max, self.cfg.encoder_sigmas[2]) ** 2 * gap * gap + qw * gap ** 3 / 3.0
        if tail > 0.0:
            got = self._graph_twist(t0)
            if got is None:   # no motion of the graph's to carry on: the last twist held
                tw = np.asarray(self.odo_u[-1], dtype=float)
                var = np.array([max(self._odo_speed_max, self.cfg.encoder_sigmas[0]) ** 2,
                                float(self.odo_c[-1][3]), max(self._odo_rate_max, self.cfg.encoder_sigmas[2]) ** 2])
            else:
                tw, var = got
            step = se2_exp(tw * tail)
            # the covered part's covariance carried through the step (the increment's covariance is
            # in the frame at its end, as integrate_twist_lists'), plus the step's own
            A = adjoint(inverse1(step))
            c = A @ c @ A.T
            c[0, 0] += var[0] * tail * tail + qv * tail ** 3 / 3.0
            c[1, 1] += var[1] * tail * tail + (qv * tail ** 3 / 3.0 if self._odo_lateral_max > LATERAL_SPEED else 0.0)
            c[2, 2] += var[2] * tail * tail + qw * tail ** 3 / 3.0
            d = compose1(d, step)
        return d, c

    def _chord_along_gyro(self, t0: float, t1: float
                          ) -> tuple[tuple[float, float, float], tuple[float, float, float]] | None:
        """The odometry's translation over ``(t0, t1]`` integrated along the first gyro's
        (bias-corrected) heading, ``[x, y, gyro yaw]`` in the frame at ``t0``, and the
        translation's covariance ``(p_xx, p_xy, p_yy)`` from the odometry's speed variances alone
        (the heading it is integrated along is the gyro's, not the wheels': their yaw-rate variance
        does not spread it, a wheel yaw that is not fused least of all); None when no gyro covers
        the interval (each odometry twist held backwards, as :func:`integrate_twist`)."""
        if not self.gyro or not self.odo_t:
            return None
        name = next(iter(self.gyro))
        gts, grs, _ = self.gyro[name]
        ng = len(gts)
        # the gyro's coverage of the whole interval (what each step's _gyro_increment checks: a step
        # it does not cover makes the chord None, whichever step it is)
        if not gts or gts[-1] < t1 - 1e-9 or gts[0] > t0 + 1e-9:
            return None
        bias = self.gyro_bias_of(name)
        max_gap = 0.25
        qx, qy = float(self._q_slip[0]), float(self._q_slip[1])
        ts = self.odo_t
        n = len(ts)
        i = bisect_right(ts, t0)
        g = max(bisect_right(gts, t0) - 1, 0)   # the gyro reading at or before the step's start
        us, cvs = self.odo_u, self.odo_c
        cos, sin = math.cos, math.sin
        t, x, y, th = t0, 0.0, 0.0, 0.0
        p00 = p01 = p11 = 0.0
        # one pass: per odometry step its gyro integral (rate_integral's sum, the gyro index carried from
        # step to step instead of searched) and its chord step (chord_step's), the same operations inline
        while t < t1 - 1e-12:
            j = i if i < n - 1 else n - 1
            tn = (ts[i] if ts[i] < t1 else t1) if i < n else t1
            dt = tn - t
            if dt > 0:
                while g + 1 < ng and gts[g + 1] <= t:
                    g += 1
                d = 0.0
                k = g
                while k < ng - 1 and gts[k] < tn:
                    ta, tb = gts[k], gts[k + 1]
                    a = t if t > ta else ta
                    b = tn if tn < tb else tb
                    if b > a:
                        h = tb - ta
                        if h > max_gap:
                            return None
                        fa, fb = (a - ta) / h, (b - ta) / h
                        wi = (b - a) * (1.0 - 0.5 * (fa + fb))
                        wj = (b - a) * 0.5 * (fa + fb)
                        d += wi * grs[k] + wj * grs[k + 1]
                    k += 1
                w = d - bias * (tn - t)
                u, cv = us[j], cvs[j]
                vx, vy = float(u[0]) * dt, float(u[1]) * dt
                ea, eb = exp_coefficients(w)
                dx, dy = ea * vx - eb * vy, eb * vx + ea * vy
                c, s_ = cos(th), sin(th)
                x, y, th = x + c * dx - s_ * dy, y + s_ * dx + c * dy, th + w
                dt2 = dt * dt
                s00, s01, s11 = cv[0] * dt2 + qx * dt, cv[1] * dt2, cv[3] * dt2 + qy * dt
                p00 += c * c * s00 - 2.0 * c * s_ * s01 + s_ * s_ * s11
                p01 += c * s_ * (s00 - s11) + (c * c - s_ * s_) * s01
                p11 += s_ * s_ * s00 + 2.0 * c * s_ * s01 + c * c * s11
            t = tn
            i += 1
        return (x, y, wrap_scalar(th)), (p00, p01, p11)

    def _add_heading_reading(self, t: float, yaw: float, var: float, source: str) -> None:
        """Keep the first absolute heading source's readings (unwrapped) for :meth:`_chord_along_heading`."""
        if self._heading_source is None:
            self._heading_source = source
        if source != self._heading_source:
            return
        ts, ys = self.heading_hist
        if ts and t <= ts[-1]:
            return
        self._heading_var = float(var)
        ts.append(t)
        ys.append(yaw if not ys else ys[-1] + wrap_scalar(yaw - ys[-1]))
        if len(ts) > 4096 and self.kf_t:
            i = bisect_left(ts, self.kf_t[-1] - self.cfg.lag_s - 2.0)
            if i > 0:
                del ts[:i], ys[:i]

    def _wheel_yaw_unfused(self) -> bool:
        """The odometry's yaw rate is not fused (handed as 0 with a variance of at least
        :data:`TWIST_VAR_MAX`): integrated as it is, every keyframe's chord would run straight
        along the heading at its start, whatever the robot turned."""
        return bool(self.odo_c) and self.odo_c[-1][5] >= TWIST_VAR_MAX

    def _odom_yaw_var(self, var: float, dyaw: float) -> float:
        """The odometry factor's yaw variance (rad^2) for an increment ``dyaw`` whose integrated
        variance is ``var``: scaled by the noise the wheels' yaw showed against the other yaw
        sources (``k^2``), plus their per-turn noise."""
        k_yaw, rel = self.inputs.noise("odom")
        return var * k_yaw * k_yaw + (rel * dyaw) ** 2

    def _heading_chord(self, t0: float, t1: float) -> bool:
        """Without a gyro over ``(t0, t1]``, the chord runs along the absolute heading's readings
        rather than the wheels' arc when their increment over the interval (two interpolated
        readings: twice a reading's variance) is better known than the wheels' yaw increment (a
        skid steer's wheels report several times the turn: their arc drives the path crabwise),
        or the wheels' yaw rate is not fused at all."""
        if not self.odo_c or not self.heading_hist[0]:
            return False
        if self._wheel_yaw_unfused():
            return True
        dt = t1 - t0
        var_w = self._odom_yaw_var(self.odo_c[-1][5] * dt * dt, self.odo_u[-1][2] * dt)
        return 2.0 * self._heading_var * self.inputs.noise(f"{self._heading_source}.yaw")[0] ** 2 < var_w

    def _heading_at(self, t: float) -> float:
        """The absolute heading's readings (unwrapped) linearly interpolated at ``t`` (held beyond them)."""
        hts, hys = self.heading_hist
        if len(hts) < 2:
            return hys[-1]
        i = min(max(bisect_right(hts, t), 1), len(hts) - 1)
        ta, tb = hts[i - 1], hts[i]
        f = min(max((t - ta) / (tb - ta), 0.0), 1.0) if tb > ta else 1.0
        return hys[i - 1] + f * (hys[i] - hys[i - 1])

    def _heading_reading_at(self, t: float) -> tuple[float, float] | None:
        """The absolute heading at ``t`` interpolated between its readings either side (at most
        0.25 s apart) and that value's sigma, or None when they do not bracket ``t``."""
        hts, hys = self.heading_hist
        if len(hts) < 2 or hts[0] > t or hts[-1] < t:
            return None
        i = min(max(bisect_right(hts, t), 1), len(hts) - 1)
        ta, tb = hts[i - 1], hts[i]
        if tb - ta > 0.25:
            return None
        f = (t - ta) / (tb - ta) if tb > ta else 1.0
        return (wrap_scalar(hys[i - 1] + f * (hys[i] - hys[i - 1])),
                math.sqrt(self._heading_var * (f * f + (1.0 - f) ** 2)))

    def _chord_along_heading(self, t0: float, t1: float
                             ) -> tuple[tuple[float, float, float], tuple[float, float, float]] | None:
        """:meth:`_chord_along_gyro`'s chord and covariance, the odometry's translation integrated
        along the absolute heading readings (a compass, an IMU's orientation: linearly interpolated)
        where no gyro covers the interval (:meth:`_heading_chord`); None when the
        readings do not cover ``[t0, t1]`` or are further apart than 0.25 s."""
        hts, hys = self.heading_hist
        if not self.odo_t or not hts or hts[0] > t0 + 1e-9 or hts[-1] < t1 - 1e-9:
            return None
        j0 = max(bisect_right(hts, t0) - 1, 0)
        j1 = min(bisect_left(hts, t1), len(hts) - 1)
        if j1 > j0 and max(map(sub, hts[j0 + 1:j1 + 1], hts[j0:j1])) > 0.25:
            return None

        heading = self._heading_at
        qx, qy = float(self._q_slip[0]), float(self._q_slip[1])
        ts = self.odo_t
        n = len(ts)
        i = bisect_right(ts, t0)
        h0 = heading(t0)
        t, x, y, th = t0, 0.0, 0.0, 0.0
        p00 = p01 = p11 = 0.0
        while t < t1 - 1e-12:
            j = min(i, n - 1)
            tn = min(ts[i], t1) if i < n else t1
            dt = tn - t
            if dt > 0:
                w = heading(tn) - h0 - th
                x, y, th, p00, p01, p11 = chord_step(self.odo_u[j], self.odo_c[j], dt, w, qx, qy,
                                                     x, y, th, p00, p01, p11)
            t = tn
            i += 1
        return (x, y, wrap_scalar(th)), (p00, p01, p11)

    def _rotation_between(self, t0: float, t1: float) -> float:
        """Heading change from ``t0`` to ``t1`` (negative if ``t1 < t0``): a gyro's when it covers
        the interval, else the odometry's (times its yaw-rate gain)."""
        if t0 == t1:
            return 0.0
        a, b = (t0, t1) if t1 > t0 else (t1, t0)
        for name in self.gyro:
            r = self._gyro_increment(name, a, b, want_var=False)
            if r is not None:
                return r[0] if t1 > t0 else -r[0]
        th = self._wheel_turn(a, b)
        return th if t1 > t0 else -th

    def _gyro_turn(self, name: str, t0: float, t1: float) -> float | None:
        """The gyro ``name``'s bias-free turn over ``(t0, t1]`` up to its last reading, the wheels' (times
        their yaw-rate gain) for the rest (a prediction to the newest odometry stamp is usually past the
        gyro's last reading; a gyro that stopped); None when its readings do not reach back to ``t0`` or
        leave a gap."""
        got = self.gyro.get(name)
        if got is None:
            return None
        ts = got[0]
        if not ts or ts[0] > t0 + 1e-9:
            return None
        last = ts[-1]
        if last >= t1 - 1e-9:
            r = self._gyro_increment(name, t0, t1, want_var=False)
            return None if r is None else r[0]
        turn = 0.0
        if last > t0:
            r = self._gyro_increment(name, t0, last, want_var=False)
            if r is None:
                return None
            turn = r[0]
        return turn + self._wheel_turn(t0 if t0 > last else last, t1)

    def _wheel_turn(self, a: float, b: float) -> float:
        """The odometry's heading change over ``(a, b]`` times its yaw-rate gain (``a <= b``)."""
        if not self.odo_t or b <= a:
            return 0.0
        i0, i1 = covering(self.odo_t, a, b)
        th = integrate_heading(self.odo_t, self.odo_u, i0, i1, a, b)
        return th * float(self._gains[1])

    def _reports_sideways(self) -> bool:
        """Whether the odometry has a sideways axis: a differential drive's reports no sideways speed and
        cannot creep sideways per metre (its drift's sideways part stays at 0)."""
        return self._odo_lateral_max > SIDEWAYS_REPORTED_MPS

    def _compass_measurement(self, t_k: float, readings: list[tuple[float, float, float, str]]
                             ) -> tuple[float, float] | None:
        """Readings carried to ``t_k`` by the odometry rotation and averaged (circularly)."""
        if not readings:
            return None
        ref = None
        acc = 0.0
        var = 0.0
        for tc, yaw, v, _src in readings:
            z = yaw + self._rotation_between(tc, t_k)
            if ref is None:
                ref = z
            acc += wrap_scalar(z - ref)
            var += v
        n = len(readings)
        assert ref is not None
        return wrap_scalar(ref + acc / n), math.sqrt(var / n / n)

    def _timing_var(self, t0: float, t1: float) -> float:
        """Yaw variance (rad^2) of a keyframe interval's odometry increment from where in time the odometry
        places the motion, when it is too slow to place it (mean message period over its last
        ``TIMING_MESSAGES`` messages above :data:`MAX_REF_PERIOD_S`: the latency estimator takes no pairs from
        it either): its pose at each keyframe stamp, against the scan's, is known to about one period, so
        ``(period * w)^2`` at each end, ``w`` the yaw rate there.  Not modelled, a scan stamped off its
        odometry (CARMEN logs: 80-120 ms) gives two consecutive increments degrees off in turns where
        they claim a fraction of that, and they outvote the keyframe's fix."""
        n = min(len(self.odo_t), TIMING_MESSAGES)
        if not (self.cfg.slow_odom_timing or self.odom_timing_unknown) or n < 3:
            return 0.0
        per = (self.odo_t[-1] - self.odo_t[-n]) / (n - 1)
        if not per > MAX_REF_PERIOD_S:
            return 0.0
        wa, wb = self._yaw_rate_at(t0), self._yaw_rate_at(t1)
        return per * per * (wa * wa + wb * wb)

    def _timing_s2(self) -> float:
        """Variance (s^2) of where in time a slow odometry places its pose at a stamp: within its period
        (mean over its last ``TIMING_MESSAGES`` messages, above :data:`MAX_REF_PERIOD_S`), uniform in it
        (``period^2 / 12``; the whole period squared where its timing is unknown); 0 for a faster one.
        Times the yaw rate squared, the yaw variance of its pose at that stamp: what the output
        covariance adds (``smoother.odom_timing_jitter``) at the pose's end and at the fix's it is
        carried from.  The errors of consecutive increments cancel (they share an end), so an
        increment carried over many keyframes has the same term, not their sum."""
        n = min(len(self.odo_t), TIMING_MESSAGES)
        if n < 3:
            return 0.0
        per = (self.odo_t[-1] - self.odo_t[-n]) / (n - 1)
        if not per > MAX_REF_PERIOD_S:
            return 0.0
        return per * per if (self.cfg.slow_odom_timing or self.odom_timing_unknown) else per * per / 12.0

    def _yaw_rate_at(self, t: float) -> float:
        """:meth:`_twist_at`'s yaw rate alone (no array made)."""
        if not self.odo_t:
            return 0.0
        w = self._gyro_rate_at(t)
        if w is not None:
            return float(w)
        return float(self.odo_u[min(bisect_left(self.odo_t, t), len(self.odo_t) - 1)][2] * float(self._gains[1]))

    def _twist_at(self, t: float) -> FloatArray:
        """The body twist at ``t``: odometry times its gains, the gyro's yaw rate when there is one."""
        if not self.odo_t:
            return np.zeros(3)
        u0, u1, _ = self.odo_u[min(bisect_left(self.odo_t, t), len(self.odo_t) - 1)]
        gv = float(self._gains[0])
        return np.array([u0 * gv, u1 * gv, self._yaw_rate_at(t)])

    def gyro_bias(self, source: str = "imu") -> float:
        """The estimated bias (rad/s) of ``source``'s gyro (0 before it is estimated)."""
        return self.gyro_bias_of(f"{source}.gyro")

    def gyro_bias_of(self, name: str) -> float:
        """The estimated bias (rad/s) of the gyro stream ``name`` (``SOURCE.gyro``)."""
        gb = self.inputs.gyro_bias.get(name)
        if gb is not None:
            return gb.x[0]   # its value() (read several times per keyframe and prediction)
        ch = self.chains.get(f"gyro_bias:{name}")
        return float(ch.estimate[0]) if ch is not None and ch.estimate is not None else 0.0
