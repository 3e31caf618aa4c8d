"""Factors of the further sources: a differential orientation's heading factor on its own offset
chain, and a further odometry source's between-keyframe factor (its alignment estimated)."""

from __future__ import annotations

import math
from bisect import bisect_left, bisect_right

import gtsam
import numpy as np

from fgloc.backends.base import FloatArray
from fgloc.backends.factors import aligned_between_factor, between_factor, relative_yaw_factor
from fgloc.backends.integration import integrate_twist
from fgloc.backends.relative_yaw import jumped
from fgloc.backends.smoother.covariance import TWIST_VAR_MAX, bounded_covariance
from fgloc.backends.smoother.window import FixedLagWindow
from fgloc.geometry import wrap_scalar

#: a further twist source's messages further apart than this (s) do not cover the gap (a lost
#: visual track): a twist held backwards over longer is not a measurement of the motion in it
MAX_TWIST_GAP_S = 0.5


#: a differential orientation that jumped past the gate (a re-initialized AHRS) and stayed gated at this
#: many keyframes in a row is anchored again; one that crept past it re-opens the heading at once
REANCHOR_AFTER = 5


#: rad, the prior of a differential orientation's offset at its anchor (its frame is its own: loose)
RELATIVE_YAW_PRIOR_SIGMA = 10.0


CHI2_3_999 = 16.27  # chi-square 99.9 % quantile, 3 degrees of freedom


class FurtherSourceFactors(FixedLagWindow):
    """The factors of differential orientations and further twist sources."""

    def _add_relative_yaw_factors(self, k: int, t: float, pred: FloatArray, graph: gtsam.NonlinearFactorGraph,
                                  vals: gtsam.Values, ts: dict) -> None:
        """Keyframe ``k``'s heading factor of each differential orientation source with readings
        up to ``t`` (``pred``: the keyframe's initial value)."""
        if not self.rel_pending:
            return
        now = [r for r in self.rel_pending if r[0] <= t + 1e-9]
        self.rel_pending = [r for r in self.rel_pending if r[0] > t + 1e-9]
        horizon = t - self.cfg.lag_s
        gate = self.cfg.fix_gate_theta
        got = []
        for source in dict.fromkeys(r[3] for r in now):
            readings = [r for r in now if r[3] == source and r[0] >= horizon]
            m = self._compass_measurement(t, readings)
            if m is None:
                continue
            ch = self._chain(f"relative_yaw:{source}", "r", [0.0], [RELATIVE_YAW_PRIOR_SIGMA],
                             [self.cfg.relative_yaw_rw_sigma])
            e = None
            if ch.key is not None and ch.estimate is not None:
                e = wrap_scalar(float(pred[2]) + float(ch.estimate[0]) - m[0])
            got.append((source, readings, m, ch, e))
        # another differential source that agrees with the prediction: the sources disagree, and one
        # that crept away is not followed
        agreed = sum(1 for g in got if g[4] is not None and gate is not None and abs(g[4]) <= gate)
        for source, readings, (z, sigma), ch, e in got:
            name = f"{source}.yaw"
            h = self.inputs.source(name, "heading")
            sigma *= self.inputs.noise(name)[0]
            if e is not None and gate is not None:
                prev = self._rel_innov.get(source, e)
                self._rel_innov[source] = e
                crept = self._rel_gated.get(source, 0) == 0 and not jumped(e, prev, gate)
                if abs(e) > gate and crept and agreed == 0:
                    # crept past the gate (the other yaw sources' turn lies): the heading re-opened to
                    # the source's, as its initial value; a re-anchor later would keep the drift
                    pred[2] = wrap_scalar(float(pred[2]) - e)   # z - c
                    vals.update(k, pose2=gtsam.Pose2(float(pred[0]), float(pred[1]), float(pred[2])))
                    self.stats["relative_yaw_reopened"] = self.stats.get("relative_yaw_reopened", 0) + 1
                    agreed = 1
                elif abs(e) > gate:
                    h.gated += len(readings)
                    n = self._rel_gated[source] = self._rel_gated.get(source, 0) + 1
                    if n < REANCHOR_AFTER:
                        continue
                    self.stats["relative_yaw_reanchored"] = self.stats.get("relative_yaw_reanchored", 0) + 1
                    ch.key = None
            if ch.key is None:  # anchored here: c = z - theta (the source's frame is its own)
                ch.prior_mean = np.array([wrap_scalar(z - float(pred[2]))])
                ch.estimate = ch.prior_mean.copy()
                self._rel_innov[source] = 0.0
            self._rel_gated[source] = 0
            kc = self._chain_key(ch, t, graph, vals, ts)
            graph.add(relative_yaw_factor(k, kc, z, sigma, "huber", self.cfg.compass_kernel_k))
            # its changes are a heading source's for the consistency check (a new anchor: a new source)
            n = self.stats.get("relative_yaw_reanchored", 0)
            self._heading_inputs[1][f"{name}#{n}" if n else name] = (z, sigma * sigma)
            h.accepted += len(readings)
            self.stats["relative_yaw_factors"] = self.stats.get("relative_yaw_factors", 0) + 1

    def _add_velocity_factors(self, t_now: float, graph: gtsam.NonlinearFactorGraph, vals: gtsam.Values,
                              ts: dict) -> None:
        """A between factor per further twist source for every keyframe interval it now covers
        (its messages may arrive after the keyframe: its factors follow at the next one)."""
        for name, (vts, _, _) in self.vel.items():
            if len(vts) < 2:
                continue
            for ta, tb, ka, kb in self._covered_intervals(t_now, self._vel_done.get(name, -np.inf), vts[-1]):
                self._vel_done[name] = tb
                f = self._velocity_factor(name, ka, kb, ta, tb, graph, vals, ts)
                if f is None:
                    continue
                graph.add(f)
                if ka not in ts:
                    ts[ka] = ta
                self.stats["velocity_factors"] = self.stats.get("velocity_factors", 0) + 1

    def _velocity_tail(self) -> None:
        """At the end: the further twist sources' factors on the last keyframe intervals (their
        messages arrive after the keyframe; no later keyframe adds them)."""
        if not self.vel or not self.kf_t or not self.initialized:
            return
        graph, vals = gtsam.NonlinearFactorGraph(), gtsam.Values()
        ts: dict[int, float] = {}
        self._add_velocity_factors(self.kf_t[-1], graph, vals, ts)
        if graph.size() == 0:
            return
        self._register(graph, vals, ts)
        try:
            self._update(graph, vals, ts)
        except RuntimeError:
            self.stats["solver_failures"] = self.stats.get("solver_failures", 0) + 1

    def _velocity_factor(self, name: str, ka: int, kb: int, ta: float, tb: float, graph: gtsam.NonlinearFactorGraph,
                         vals: gtsam.Values, ts: dict) -> gtsam.NonlinearFactor | None:
        """Source ``name``'s twists integrated over ``(ta, tb]`` as a between factor, or None (not
        covered: a gap over :data:`MAX_TWIST_GAP_S`; gated)."""
        vts, vus, vcs = self.vel[name]
        j0 = bisect_right(vts, ta)        # its twist covers ta (held backwards)
        j1 = bisect_left(vts, tb)         # the first message at or after tb
        if j0 == 0 or j1 >= len(vts):
            return None
        if max(vts[j] - vts[j - 1] for j in range(j0, j1 + 1)) > MAX_TWIST_GAP_S:
            self.stats["velocity_gaps"] = self.stats.get("velocity_gaps", 0) + 1
            return None
        d, c = integrate_twist(np.asarray(vts[j0 - 1:j1 + 1]), np.asarray(vus[j0 - 1:j1 + 1]),
                               np.asarray(vcs[j0 - 1:j1 + 1]), ta, tb, self._q_slip)
        k_yaw, rel = self.inputs.noise(name)
        if k_yaw != 1.0 or rel > 0.0:
            c[2, :] *= k_yaw
            c[:, 2] *= k_yaw
            c[2, 2] += (rel * d[2]) ** 2
        ch = None
        if self.cfg.odom_gains and self._vel_translates.get(name, False):
            # its translation's scale and yaw misalignment on the base, (a, b) = s (cos, sin) of it
            ch = self._chain(f"alignment:{name}", "a", [1.0, 0.0], [self.cfg.odom_speed_scale_prior] * 2,
                             [self.cfg.odom_scale_rw] * 2)
        d_true = d.copy()
        if ch is not None and ch.estimate is not None:
            a_, b_ = float(ch.estimate[0]), float(ch.estimate[1])
            n2 = a_ * a_ + b_ * b_
            if math.isfinite(n2) and n2 > 0.0025:
                d_true[0], d_true[1] = (a_ * d[0] + b_ * d[1]) / n2, (-b_ * d[0] + a_ * d[1]) / n2
        # gate: against the keyframes' current relative pose, with the first source's uncertainty too
        pa, pb = self.kf_pose[ka], self.kf_pose[kb]
        ca, sa = math.cos(pa[2]), math.sin(pa[2])
        dx, dy = float(pb[0] - pa[0]), float(pb[1] - pa[1])
        rel_pose = np.array([ca * dx + sa * dy, -sa * dx + ca * dy, wrap_scalar(float(pb[2] - pa[2]))])
        e = rel_pose - d_true
        e[2] = wrap_scalar(float(e[2]))
        _, c1 = self._integrate(ta, tb)
        c1 = bounded_covariance(np.asarray(c1, dtype=float), TWIST_VAR_MAX)
        for g in self.gyro:  # the keyframes' turn is the gyro's where it covers them: its uncertainty
            r = self._gyro_increment(g, ta, tb)
            if r is not None:
                gb = self.inputs.gyro_bias.get(g)
                c1 = c1.copy()
                c1[2, :2] = c1[:2, 2] = 0.0
                c1[2, 2] = r[1] + ((gb.sigma() if gb is not None else 0.0) * (tb - ta)) ** 2
                break
        S = c + c1 + np.eye(3) * 1e-8
        try:
            d2 = float(e @ np.linalg.solve(S, e))
        except np.linalg.LinAlgError:
            d2 = math.inf
        h = self.inputs.source(name, "odometry")
        if not d2 <= CHI2_3_999:
            h.gated += 1
            return None
        if ch is None:
            return between_factor(ka, kb, d, c, kernel=self.cfg.odom_kernel, k=self.cfg.odom_kernel_k)
        kab = self._chain_key(ch, tb, graph, vals, ts)
        return aligned_between_factor(ka, kb, kab, d, c, kernel=self.cfg.odom_kernel, k=self.cfg.odom_kernel_k)
