"""Graph building at each keyframe: the odometry factor (scales estimated), the compass and fix
factors, the gyro's yaw-increment factors, and a late scan's keyframe between its neighbours."""

from __future__ import annotations

import math
from bisect import bisect_left, bisect_right
from collections import deque

import gtsam
import numpy as np

from fgloc.backends.base import FloatArray
from fgloc.backends.contract import SCANS_ALONE_AFTER_S
from fgloc.backends.ekf import SCALE_EVIDENCE_SIGMAS
from fgloc.backends.factors import (
    between_factor,
    compass_factor,
    fix_factor,
    gyro_factor,
    heading_factor,
    pose2,
    scaled_between_factor,
    yaw_increment_factor,
)
from fgloc.backends.health import ANGLE_ABSOLUTE
from fgloc.backends.integration import integrate_twist_values, twist_covariance_array
from fgloc.backends.smoother.covariance import (
    carried_covariance,
    carried_covariance_upper,
    covariance_bound,
    timing_covariance,
)
from fgloc.backends.smoother.further import FurtherSourceFactors
from fgloc.geometry import compose1, mahalanobis2_3x3, wrap_scalar
from fgloc.geometry import exp as se2_exp
from fgloc.types import PoseFix, all_finite

#: s, a gyro whose last reading is older than this is not waited for (it stopped, or is that slow)
GYRO_LIVE_S = 0.25


class KeyframeGraph(FurtherSourceFactors):
    """The factors of each keyframe."""

    def add_keyframe(self, t: float, fix: PoseFix | None) -> bool:
        """Queue a keyframe; it is added once odometry up to ``t`` has arrived (or ``max_wait`` passed).

        Returns True if the fix passed the gate against the prediction.
        """
        if not self.initialized or not math.isfinite(float(t)):
            return False
        t = float(t)
        if fix is not None and not all_finite(fix.pose, fix.cov):
            self.inputs.source("scan", "pose").skip("fix not finite")
            fix = None
        if t <= self.kf_t[-1]:
            if t == self.kf_t[-1]:
                return False
            return self._late_keyframe(t, fix)
        last = self.pending_kf[-1][0] if self.pending_kf else self.kf_t[-1]
        if t - last < self.cfg.min_keyframe_dt_s:
            # a scan right on top of the previous keyframe adds nothing but conditioning trouble
            self.stats["merged_keyframes"] = self.stats.get("merged_keyframes", 0) + 1
            return False
        if fix is not None and self.cfg.fix_gate is not None:
            # the gate's marginal is fresh (it is otherwise computed only when an output asks for it:
            # without outputs, the gate judged against the start prior the whole run)
            self._update_covariance()
        pred, pred_cov = self.predict(t)
        used = False
        if fix is not None:
            if self._gate(fix, pred, pred_cov):
                used = True
                self._rejects = 0
            else:
                self._rejects += 1
                self.stats["fixes_rejected"] += 1
                if self._rejects >= self.cfg.max_rejections:
                    self._process_pending(np.inf)
                    self.stats["resets"] = self.stats.get("resets", 0) + 1
                    self.initialize(t, fix.pose, self._fix_cov(fix.cov))
                    self.stats["keyframes"] += 1
                    return True
        self.pending_kf.append((t, fix if used else None))
        self.pending_kf.sort(key=lambda p: p[0])
        self._process_pending(t)
        return used

    def _process_pending(self, now: float) -> None:
        while self.pending_kf:
            t = self.pending_kf[0][0]
            have_odo = bool(self.odo_t) and self.odo_t[-1] >= t - 1e-9 and self._gyros_cover(t)
            if not self.odo_t and t - float(self.t0 or t) >= SCANS_ALONE_AFTER_S:
                have_odo = self._gyros_cover(t)   # no odometry to wait for: scans on a map
            if not (have_odo or now - t >= self.cfg.max_wait_s):
                return
            t, fix = self.pending_kf.pop(0)
            self._add_keyframe_now(t, fix)

    def _gyros_cover(self, t: float) -> bool:
        """Every gyro still reading (one within :data:`GYRO_LIVE_S` of ``t``) has reached ``t``, so
        the keyframe's chord can run along its heading.  A keyframe made before (its gyro reading
        arriving after the odometry's) would keep the wheels' own arc, bent by their yaw (a skid
        steer's wheels report several times the turn: the path drives crabwise).  Without a gyro,
        where the wheels' yaw rate is not fused, the chord runs along the absolute heading: its
        reading at ``t`` is waited for the same way."""
        if not self.cfg.gyro_chord:
            return True
        for ts_, _, _ in self.gyro.values():
            if ts_ and t - GYRO_LIVE_S <= ts_[-1] < t - 1e-9:
                return False
        hts = self.heading_hist[0]
        if not self.gyro and hts and t - GYRO_LIVE_S <= hts[-1] < t - 1e-9 and self._heading_chord(self.kf_t[-1], t):
            return False   # the chord runs along the absolute heading: wait for its reading at t
        return True

    def _add_keyframe_now(self, t: float, fix: PoseFix | None) -> None:
        used = fix is not None
        k_prev, t_prev = self.kf_key[-1], self.kf_t[-1]
        k = self._new_x(t)
        if self._acc is None:
            self._acc = (gtsam.NonlinearFactorGraph(), gtsam.Values(), {}, [], [])
        graph, vals, ts, pairs, keys = self._acc
        ts[k] = t
        d, c = self._motion(t_prev, t)
        # (a chord holds the odometry's last twist: not where the odometry stopped)
        use_chord = self.cfg.gyro_chord and self._unmeasured_tail(t_prev, t) <= 0.0
        got = self._chord_along_gyro(t_prev, t) if use_chord else None
        heading_chord = got is None and use_chord and self._heading_chord(t_prev, t)
        if heading_chord:
            got = self._chord_along_heading(t_prev, t)
        if got is None:
            pred = compose1(self.kf_pose[k_prev], self._corrected(d, t_prev, t))
            cl = c.reshape(9).tolist()
        else:  # the translation along the gyro's heading, the gyro's rotation; the wheels' yaw in the factor
            chord, (p00, p01, p11) = got
            gv = float(self._gains[0])
            pred = compose1(self.kf_pose[k_prev], (chord[0] * gv, (chord[1] - self._drift[0] * chord[0]) * gv,
                                                   chord[2]))
            d = np.array([chord[0], chord[1], d[2]])
            # its translation's covariance is the chord's, uncorrelated with the wheels' yaw
            cl = [p00, p01, 0.0, p01, p11, 0.0, 0.0, 0.0, float(c[2, 2])]
        graph.add(self._odometry_factor(k_prev, k, d, cl, t, graph, vals, ts, bend=got is None))
        pairs.append(((k_prev, k), graph.size() - 1))
        # initial value: the odometry prediction, so robust weights start from a consistent point (by the
        # overload's name: pybind11 tries Values.insert's overloads in turn, the Pose2 one is the ninth)
        vals.insert(k, pose2=pose2(pred))
        if t - self.cur_o_t >= self.cfg.offset_interval_s:
            self._next_offset(t, graph, vals, ts)
        # compass readings since the previous keyframe (late ones go to this keyframe too)
        readings = [r for r in self.compass_pending if r[0] <= t + 1e-9]
        self.compass_pending = [r for r in self.compass_pending if r[0] > t + 1e-9]
        relative = self._relative_yaw_increments(t_prev, t, float(d[2]))
        incs, absolute = self._heading_inputs
        for name, (dy, v) in relative.items():
            a0, v0 = incs.get(name, (0.0, 0.0))
            incs[name] = (a0 + dy, v0 + v)
        m = self._compass_measurement(t, readings)
        if m is not None and heading_chord and all(r[3] == self._heading_source for r in readings):
            # the readings are not carried to t by the wheels' turn, which is worse known than the
            # heading's own increments (and a skid steer's is several times too large): interpolated
            m = self._heading_reading_at(t) or m
        if m is not None:
            sigma = m[1]
            if self.cfg.adapt_noise and readings:
                sigma *= self.inputs.noise(f"{readings[0][3]}.yaw")[0]
            kernel_k = self._compass_kernel_k(sigma, relative)
            if self._offset_held():
                # the frame's only absolute heading: a redescending kernel would drop it for good once
                # the relative sources' integral had carried the heading a few sigmas away (nothing
                # else could bring it back); Huber bounds each reading's pull and never drops it
                kernel = "huber" if self.cfg.compass_kernel == "cauchy" else self.cfg.compass_kernel
                graph.add(heading_factor(k, wrap_scalar(m[0] - float(self.calib.offset or 0.0)), sigma,
                                         kernel, kernel_k))
            else:
                graph.add(compass_factor(k, self.cur_o, m[0], sigma,  # type: ignore[arg-type]
                                         self.cfg.compass_kernel, kernel_k))
                ts[self.cur_o] = t  # type: ignore[index]
            self.stats["compass_factors"] += 1
            absolute[f"{readings[0][3]}.yaw" if readings else "compass"] = (m[0], sigma * sigma)
        self._add_relative_yaw_factors(k, t, pred, graph, vals, ts)
        if used:
            assert fix is not None
            floored = self._fix_cov_list(fix.cov)   # (the factor's, the floor's and the heading's: once)
            graph.add(self._fix_factor(k, t, fix, graph, vals, ts, floored))
            self._fix_floor = (t, np.asarray(fix.pose, dtype=float), np.array(floored).reshape(3, 3))
            self.stats["fixes_used"] += 1
            self.inputs.source("scan", "pose").accepted += 1
            lat = self.latency_estimate()
            yaw_fix = float(fix.pose[2])
            self.calib.add_fix(t - lat, yaw_fix)
            var_yaw = floored[8]
            absolute["scan"] = (yaw_fix, var_yaw)
            self.inputs.heading("scan", t - lat, yaw_fix, var_yaw)
            self.inputs.reading("scan", ANGLE_ABSOLUTE, 0.005, t - lat, yaw_fix, var_yaw)
        self.kf_t.append(t)
        self.kf_key.append(k)
        self.window.append((t, k))
        self.kf_pose[k] = pred
        keys.append(k)
        self._add_gyro_factors(t, graph, vals, ts)
        self._add_velocity_factors(t, graph, vals, ts)
        if self.cfg.adapt_noise:
            self.inputs.arb.update(t)
        self.inputs.latency.evaluate(self)
        if len(keys) >= max(1, int(self.cfg.update_every)):
            self._flush_acc()
        else:  # online estimate until the next solver update: the odometry prediction
            self.stats["keyframes"] += 1
            self._record_online(t, pred, carried_covariance(self._last_cov, self.kf_pose[k_prev], pred,
                                                            np.array(cl).reshape(3, 3)))

    def _record_online(self, t: float, pose: FloatArray, cov: FloatArray) -> None:
        """The online pose with its output covariance: the marginal (or the prediction's), but never
        below the last fix the graph took carried along the odometry since (:func:`covariance_bound`).
        The graph weighs successive fixes as independent; their errors are not (the same map, the same
        matcher, the same place scan after scan), so averaging many of them does not make the pose
        better known than one of them says."""
        super()._record_online(t, pose, self.output_covariance(t, pose, cov))

    def output_covariance(self, t: float, pose: FloatArray, cov: FloatArray) -> FloatArray:
        """``cov`` bounded below by the last fix the graph took, carried along the odometry since (see
        :meth:`_record_online`)."""
        fl = self._fix_floor
        if fl is None or t < fl[0]:
            return cov
        # the same prediction asked again (the online pose, then the fused pose of the same scan: the
        # prediction cache hands out the same arrays) under the same floor: the same answer
        memo = self._output_cov_memo
        if memo is not None and memo[0] == t and memo[1] is pose and memo[2] is cov and memo[3] is fl:
            return memo[4]
        s2 = self._timing_s2() if self.cfg.odom_timing_jitter else 0.0
        own = cov
        if s2 > 0.0:
            u1 = self._twist_at(t)
            own = cov + timing_covariance(s2, u1, float(pose[2]))
        if t == fl[0]:
            floor = fl[2]
        elif s2 <= 0.0:
            floor = carried_covariance_upper(fl[2], fl[1], pose, *self._floor_increment(fl[0], t))
        else:
            inc = twist_covariance_array((0.0, 0.0, 0.0, *self._floor_increment(fl[0], t)))
            # the timing at each end of the increment (frame of the fix's pose); the start's turn
            # w0 dt turns the whole increment: its end moves by w0 dt across the chord
            y0 = float(fl[1][2])
            c0, s0 = math.cos(y0), math.sin(y0)
            ex, ey = float(pose[0]) - float(fl[1][0]), float(pose[1]) - float(fl[1][1])
            cx, cy = c0 * ex + s0 * ey, -s0 * ex + c0 * ey
            u0 = self._twist_at(fl[0])
            u0 = np.array([float(u0[0]) - float(u0[2]) * cy, float(u0[1]) + float(u0[2]) * cx, float(u0[2])])
            inc = inc + timing_covariance(s2, u0, 0.0) + timing_covariance(s2, u1, float(pose[2]) - y0)
            floor = carried_covariance(fl[2], fl[1], pose, inc)
        out = covariance_bound(own, floor)
        self._output_cov_memo = (t, pose, cov, fl, out)
        return out

    def _floor_increment(self, t0: float, t1: float) -> tuple[float, float, float, float, float, float]:
        """The upper triangle of the odometry increment's covariance over ``(t0, t1]`` (as :meth:`_motion`,
        whose upper triangle is what it carries), resumed from its own mark (the fix's stamp stays, the end
        grows): the predictions' marks stay theirs."""
        tol = self._odom_gap_s()
        if not self.odo_t or self._unmeasured_tail(t0, t1, tol) > 0.0 or self._gap_s(t0, t1, tol) > 0.0:
            c = self._motion(t0, t1)[1].reshape(9).tolist()
            return c[0], c[1], c[2], c[4], c[5], c[8]
        memo = self._integrate_memo   # the prediction's integral from the same keyframe: the same numbers
        if memo is not None and memo[0] == (t0, t1, len(self.odo_t), self.odo_t[0], self.odo_t[-1]):
            return memo[1][3:]
        mark = self._floor_mark
        if not mark or mark[0] < t0 - 1e-12 or self._floor_mark_t0 != t0:
            mark.clear()
            self._floor_mark_t0 = t0
        i0 = max(bisect_right(self.odo_t, t0) - 1, 0)
        i1 = min(bisect_left(self.odo_t, t1) + 1, len(self.odo_t))
        return integrate_twist_values(self.odo_t, self.odo_u, self.odo_c, i0, i1, t0, t1, self._q_slip, mark)[3:]

    def _relative_yaw_increments(self, t0: float, t1: float, d_odom: float) -> dict[str, tuple[float, float]]:
        """Each relative yaw source's increment over ``(t0, t1]`` and its variance as its factor
        weighs it: every gyro covering the interval (bias-corrected) and the odometry (``d_odom``,
        times its yaw gain) unless its yaw rate is not fused."""
        out: dict[str, tuple[float, float]] = {}
        for name in self.gyro:
            r = self._gyro_increment(name, t0, t1)
            if r is not None:
                k_g, rel = self.inputs.noise(name)
                out[name] = (r[0], k_g * k_g * r[1] + (rel * r[0]) ** 2)
        if not self._wheel_yaw_unfused() and math.isfinite(self._odom_factor_yaw_var):
            out["odom"] = (float(d_odom) * float(self._gains[1]), self._odom_factor_yaw_var)
        return out

    def _compass_kernel_k(self, sigma: float, relative: dict[str, tuple[float, float]]) -> float:
        """The compass factor's kernel scale (whitened units): the configured one on the
        innovation, whose variance is the reading's ``sigma^2`` plus how well the other yaw sources
        predict the heading change since the previous keyframe (the best of ``relative``'s
        variances; without any, the odometry factor's).  Scaled on the reading's sigma alone,
        a redescending kernel drops a good compass as soon as the heading is off by a few of its
        sigmas, which a noisy relative source (a skid steer's wheels) does within a keyframe, and
        the heading then follows that source."""
        q = min((v for _, v in relative.values()), default=self._odom_factor_yaw_var)
        k = float(self.cfg.compass_kernel_k)
        if not (sigma > 0.0 and math.isfinite(q)):
            return k
        return k * math.sqrt(1.0 + q / (sigma * sigma))

    def _odometry_factor(self, ki: int, kj: int, d: FloatArray, cl: list[float], t: float,
                         graph: gtsam.NonlinearFactorGraph, vals: gtsam.Values, ts: dict,
                         bend: bool = True) -> gtsam.NonlinearFactor:
        """The integrated-odometry factor on the increment ``d`` with covariance ``cl`` (its 9 entries
        row by row, as floats): yaw noise as the odometry showed it, gains estimated
        (``bend=False``: ``d``'s translation was integrated along the gyro's heading)."""
        # the yaw row and column times k_yaw, the yaw variance plus (rel * yaw)^2 and the timing's: as
        # floats (the same operations as on the array), one array made at the end
        a = list(cl)
        k_yaw, rel = self.inputs.noise("odom")
        if k_yaw != 1.0 or rel > 0.0:
            a[6], a[7], a[8] = a[6] * k_yaw, a[7] * k_yaw, a[8] * k_yaw
            a[2], a[5], a[8] = a[2] * k_yaw, a[5] * k_yaw, a[8] * k_yaw
            a[8] += (rel * float(d[2])) ** 2
        a[8] += self._timing_var(self.kf_t[-1], t)
        self._odom_factor_yaw_var = a[8]
        c = np.array(a).reshape(3, 3)
        if not self.cfg.odom_gains or not self.odo_t:   # no odometry: no scales to estimate
            return between_factor(ki, kj, d, c, kernel=self.cfg.odom_kernel, k=self.cfg.odom_kernel_k)
        # a scale is estimated only once something else observes it (held at its estimate until
        # then): the speed scale from positions (fixes), the yaw-rate scale from any other yaw source
        ks_v = ks_w = None
        latency_known = not self.inputs.latency.estimated or self.inputs.latency.est.settled()
        if (self.stats["fixes_used"] > 0 and latency_known) or "odom_speed_scale" in self.chains:
            ch = self._chain("odom_speed_scale", "g", [1.0], [self.cfg.odom_speed_scale_prior],
                             [self.cfg.odom_scale_rw])
            ks_v = self._chain_key(ch, t, graph, vals, ts)
        self._turned += abs(float(d[2]))
        # the yaw-rate scale only where the wheels report a turn: a reported yaw within its noise of zero
        # says nothing of it (linked there, the fixes' heading jitter at a standstill is explained by a
        # scale going to zero); the EKF's evidence rule
        turning = abs(float(d[2])) > SCALE_EVIDENCE_SIGMAS * math.sqrt(max(a[8], 0.0))
        heading = self._heading_measured()
        if turning and ((heading and not self.gyro) or "odom_yaw_scale" in self.chains
                        or (self._turned > 1.0 and (heading or self.gyro or self.stats["fixes_used"] > 0))):
            # observable once another source measures the turn: at once beside a heading of the
            # robot's own (nothing else takes the wheels' excess turn: waited for, a skid steer's first
            # turns overshoot), after a radian of turning beside a gyro (early, its bias would take the
            # scale's error) or the fixes (a barely observable scale adds noise)
            ch = self._chain("odom_yaw_scale", "k", [1.0], [self.cfg.odom_yaw_scale_prior], [self.cfg.odom_scale_rw])
            ks_w = self._chain_key(ch, t, graph, vals, ts)
        kd = None
        beside_relative = not self.gyro and self._relative_heading()
        if "odom_drift" in self.chains or ((self.cfg.odom_drift and self.stats["fixes_used"] > 0) or beside_relative):
            # the sideways creep and turn per metre forward: observed by the fixes' positions (a scan
            # latency moves them along the track, not across it: not waited for, unlike the speed scale);
            # the turn, always, by a differential orientation without a gyro: unmodelled, the wheels'
            # turn on straights (unequal wheel radii) is split between the heading and the orientation's
            # walking offset in their noises' ratio, and the offset's share stays in the heading
            ch = self._chain("odom_drift", "d", [0.0, 0.0], list(self.cfg.odom_drift_prior),
                             list(self.cfg.odom_drift_rw))
            kd = self._chain_key(ch, t, graph, vals, ts)
        fixed = (1.0 / float(self._gains[0]), 1.0 / float(self._gains[1]))
        return scaled_between_factor(ki, kj, ks_v, ks_w, d, c, fixed, kernel=self.cfg.odom_kernel,
                                     k=self.cfg.odom_kernel_k, bend=bend, kd=kd,
                                     lateral=self._reports_sideways())

    def _relative_heading(self) -> bool:
        """Whether a differential orientation is in the graph (its own offset chain, a random walk)."""
        return any(name.startswith("relative_yaw:") for name in self.chains)

    def _heading_measured(self) -> bool:
        """Whether a heading source of the robot's own measures the turn: an absolute yaw (a
        compass's, an IMU's orientation) or a differential orientation (its increments)."""
        return self.calib.has_readings or self._relative_heading()

    def _gate(self, fix: PoseFix, pred: FloatArray, pred_cov: FloatArray) -> bool:
        e = fix.pose - pred
        e[2] = wrap_scalar(float(e[2]))
        if self.cfg.fix_gate_m is not None and float(np.hypot(e[0], e[1])) > self.cfg.fix_gate_m:
            return False
        if self.cfg.fix_gate_theta is not None and abs(float(e[2])) > self.cfg.fix_gate_theta:
            return False
        if self.cfg.fix_gate is None:
            return True
        S = np.asarray(pred_cov, dtype=float) + np.asarray(fix.cov, dtype=float)
        d2 = mahalanobis2_3x3(float(e[0]), float(e[1]), float(e[2]), S.reshape(9).tolist())
        return math.isfinite(d2) and d2 <= self.cfg.fix_gate

    def _fix_weighted_cov(self, cov: FloatArray, floored: list[float] | None = None) -> FloatArray:
        """A fix's covariance as its factor uses it: floored (:meth:`_fix_cov`), its heading
        weighted by the noise the fixes' headings show against the other yaw sources (the arbiter's
        :meth:`~fgloc.backends.health.Arbiter.shown_k`: over 0.125 s blocks and, for slowly varying
        errors, over 0.5 s and 2 s blocks).  Without it, a front-end whose headings are 5-10x better
        than the floor would leave the heading to the relative sources between fixes over a long
        window (the gyro's random walk, the wheels' drift on straight legs).  ``floored``: ``cov``'s
        :meth:`_fix_cov_list` when the caller has it (not changed here)."""
        a = self._fix_cov_list(cov) if floored is None else list(floored)
        if self.cfg.adapt_noise:
            k = self.inputs.arb.shown_k("scan")
            if k != 1.0:  # the heading's row, then its column, times k
                a[6], a[7], a[8] = a[6] * k, a[7] * k, a[8] * k
                a[2], a[5], a[8] = a[2] * k, a[5] * k, a[8] * k
        return np.array(a).reshape(3, 3)

    def _fix_cov(self, cov: FloatArray) -> FloatArray:
        return np.array(self._fix_cov_list(cov)).reshape(3, 3)

    def _fix_cov_list(self, cov: FloatArray) -> list[float]:
        """A fix's covariance with its floors, row by row as 9 floats (scalar maths: once per keyframe)."""
        a = np.asarray(cov, dtype=float).reshape(9).tolist()
        fxy, fth = self.cfg.fix_min_sigma_xy**2, self.cfg.fix_min_sigma_theta**2
        a[0] = fxy if fxy > a[0] else a[0]   # max(a[0], fxy), ... as conditionals
        a[4] = fxy if fxy > a[4] else a[4]
        a[8] = fth if fth > a[8] else a[8]
        return a

    def _fix_factor(self, k: int, t: float, fix: PoseFix, graph: gtsam.NonlinearFactorGraph,
                    vals: gtsam.Values, ts: dict, floored: list[float] | None = None) -> gtsam.NonlinearFactor:
        """The scan-to-map fix on keyframe ``k`` (at the scan stamp): with its latency estimated,
        configured, or none (``floored``: as :meth:`_fix_weighted_cov`'s)."""
        cov = self._fix_weighted_cov(fix.cov, floored)
        pose = np.asarray(fix.pose, dtype=float)
        # a fix stamped late is the pose that long before its stamp: carried forward by the motion
        lat = self.latency_estimate()
        if lat != 0.0:
            pose = compose1(pose, se2_exp(self._twist_at(t) * lat))
        # pairs for the latency estimate: consecutive fixes (turns starting / ending) and, once a
        # second, fixes ~1 s apart (a start from standstill: the lag is v * latency)
        self.inputs.latency.add_fix(t, fix.pose, cov)
        return fix_factor(k, pose, cov, self.cfg.fix_kernel, self.cfg.fix_kernel_k)

    def _add_gyro_factors(self, t_now: float, graph: gtsam.NonlinearFactorGraph, vals: gtsam.Values,
                          ts: dict) -> None:
        """Gyro yaw-increment factors for every keyframe interval the gyro now covers (a bursty
        IMU's readings arrive after the keyframe: its factors follow at the next one)."""
        if not self.cfg.gyro:
            return
        for name, (gts, _, _) in self.gyro.items():
            if not gts:
                continue
            for ta, tb, ka, kb in self._covered_intervals(t_now, self._gyro_done.get(name, -np.inf), gts[-1]):
                r = self._gyro_increment(name, ta, tb)
                self._gyro_done[name] = tb
                if r is None:
                    continue
                k_g, rel = self.inputs.noise(name)
                var = k_g * k_g * (r[1] + 1e-10 * (tb - ta)) + (rel * r[0]) ** 2
                gb = self.inputs.gyro_bias.get(name)
                if gb is not None:  # the bias known beside the graph: its uncertainty on the increment
                    graph.add(yaw_increment_factor(ka, kb, r[0], math.sqrt(var + (gb.sigma() * (tb - ta)) ** 2)))
                else:
                    d_raw = r[0] + self.gyro_bias_of(name) * (tb - ta)  # the factor carries the bias variable
                    ch = self._chain(f"gyro_bias:{name}", "b", [0.0], [self.cfg.gyro_bias_prior_radps],
                                     [self.cfg.gyro_bias_rw_radps])
                    kbias = self._chain_key(ch, tb, graph, vals, ts)
                    graph.add(gyro_factor(ka, kb, kbias, d_raw, tb - ta, math.sqrt(var)))
                if ka not in ts:
                    ts[ka] = ta
                self.stats["gyro_factors"] += 1

    def _late_keyframe(self, t: float, fix: PoseFix | None) -> bool:
        """A scan older than the newest keyframe: own keyframe between its neighbours."""
        self._flush_acc()
        i = int(np.searchsorted(self.kf_t, t))  # kf_t[i-1] < t < kf_t[i]
        if i == 0 or not self.window or self.kf_t[i - 1] < self.window[0][0]:
            self.stats["dropped_late"] += 1
            return False
        ka, kb = self.kf_key[i - 1], self.kf_key[i]
        ta, tb = self.kf_t[i - 1], self.kf_t[i]
        idx_ab = self.between_idx.get((ka, kb))
        if idx_ab is None or ka not in self.kf_pose:
            self.stats["dropped_late"] += 1
            return False
        k = self._new_x(t)
        graph = gtsam.NonlinearFactorGraph()
        vals = gtsam.Values()
        d1, c1 = self._integrate(ta, t)
        d2, c2 = self._integrate(t, tb)
        graph.add(between_factor(ka, k, d1, c1, kernel=self.cfg.odom_kernel, k=self.cfg.odom_kernel_k))
        graph.add(between_factor(k, kb, d2, c2, kernel=self.cfg.odom_kernel, k=self.cfg.odom_kernel_k))
        pa = self.isam.calculateEstimatePose2(ka)
        guess = compose1(np.array([pa.x(), pa.y(), pa.theta()]), d1)
        vals.insert(k, gtsam.Pose2(*guess))
        used = False
        if fix is not None:
            if self.cfg.fix_gate is not None:
                self._update_covariance()
            pred_cov = carried_covariance(self._last_cov, np.array([pa.x(), pa.y(), pa.theta()]), guess, c1)
            if self._gate(fix, guess, pred_cov):
                graph.add(fix_factor(k, fix.pose, self._fix_weighted_cov(fix.cov), self.cfg.fix_kernel,
                                     self.cfg.fix_kernel_k))
                used = True
                self.stats["fixes_used"] += 1
            else:
                self.stats["fixes_rejected"] += 1
        ts = {k: t}
        self._register(graph, vals, ts)
        self._remove_registered(idx_ab)
        try:
            idx = self._update(graph, vals, ts, remove=[idx_ab])
        except RuntimeError:
            self._restart_after_failure([])
            return False
        del self.between_idx[(ka, kb)]
        self.between_idx[(ka, k)] = idx[0]
        self.between_idx[(k, kb)] = idx[1]
        self.kf_t.insert(i, t)
        self.kf_key.insert(i, k)
        w = list(self.window)
        j = next((n for n, (tw, _) in enumerate(w) if tw > t), len(w))
        w.insert(j, (t, k))
        self.window = deque(w)
        p = self.isam.calculateEstimatePose2(k)
        self.kf_pose[k] = np.array([p.x(), p.y(), p.theta()])
        self.stats["late_scans"] += 1
        self.stats["keyframes"] += 1
        return used
