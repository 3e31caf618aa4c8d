"""The fixed-lag smoother as a back-end: its start, its inputs, its prediction and its outputs (on
the layers below it, see the package's docstring)."""

from __future__ import annotations

import math
from bisect import bisect_left
from typing import Any

import gtsam
import numpy as np

from fgloc.backends.base import FloatArray
from fgloc.backends.contract import Capability
from fgloc.backends.health import ANGLE_ABSOLUTE, INSTANT_RATE, RATE
from fgloc.backends.inputs import twist_covariance_values
from fgloc.backends.integration import upper6
from fgloc.backends.smoother.covariance import (
    TWIST_VAR_MAX,
    bounded_covariance,
    carried_covariance,
    carried_covariance_upper,
    prior_covariance,
)
from fgloc.backends.smoother.keyframes import KeyframeGraph
from fgloc.geometry import compose1
from fgloc.types import Trajectory


class SlidingWindowSmoother(KeyframeGraph):
    """The online fixed-lag estimator (see the package's docstring for its graph)."""

    name = "smoother"
    config_section = "smoother"

    capabilities = frozenset({Capability.ODOMETRY_CLOCK, Capability.GYRO, Capability.VELOCITY,
                              Capability.RELATIVE_YAW, Capability.ODOM_SCALES, Capability.GYRO_BIAS,
                              Capability.LATENCY, Capability.LIVE})

    @classmethod
    def from_config(cls, config: Any = None) -> SlidingWindowSmoother:
        """With ``config.smoother``."""
        return cls(None if config is None else config.smoother)

    def initialize(self, t: float, pose: FloatArray, cov: FloatArray | None = None) -> None:
        """(Re)start at ``pose`` (map ``[x, y, yaw]``) with prior ``cov`` (made well-conditioned).

        A pose that is not finite is a counted ``bad_initial_pose`` and ignored (the smoother
        stays as it was); a solver failure on the start prior itself is counted and the start
        repeated with the default prior, so GTSAM's exceptions never leave the smoother."""
        pose = np.asarray(pose, dtype=float).reshape(-1)
        if pose.shape != (3,) or not np.all(np.isfinite(pose)) or not math.isfinite(float(t)):
            self.stats["bad_initial_pose"] = self.stats.get("bad_initial_pose", 0) + 1
            return
        keep_odo = (self.odo_t, self.odo_u, self.odo_c)
        if self.t0 is not None:
            self._flush_acc()
            self._flush_window()
        smoothed = self.smoothed
        cov = prior_covariance(cov)
        for attempt in range(2):
            self._reset_state()
            self.smoothed = smoothed
            self.odo_t, self.odo_u, self.odo_c = keep_odo
            self.t0 = float(t)
            k = self._new_x(t)
            graph = gtsam.NonlinearFactorGraph()
            vals = gtsam.Values()
            graph.add(gtsam.PriorFactorPose2(k, gtsam.Pose2(*pose),
                                             gtsam.noiseModel.Gaussian.Covariance(cov + np.eye(3) * 1e-9)))
            vals.insert(k, gtsam.Pose2(*pose))
            ts = {k: float(t)}
            self._init_yaw = float(pose[2])
            self._new_offset(t, graph, vals, ts)
            try:
                self._update(graph, vals, ts)
                break
            except RuntimeError:
                self.stats["solver_failures"] = self.stats.get("solver_failures", 0) + 1
                if attempt == 1:
                    raise
                cov = prior_covariance(None)
        self.kf_t.append(float(t))
        self.kf_key.append(k)
        self.window.append((float(t), k))
        self.kf_pose[k] = pose.copy()
        self._last_cov = cov
        self._record_online(t, pose, cov)

    # ------------------------------------------------------------------ inputs
    def add_odometry(self, t: float, twist: FloatArray, twist_cov: FloatArray | None) -> None:
        h = self.inputs.source("odom", "odometry")
        if self.odo_t and t <= self.odo_t[-1]:
            self.stats["late"] += 1
            h.skip("late")
            return
        u0, u1, u2 = np.asarray(twist, dtype=float).tolist()[:3]  # scalar checks: np.all costs ~10 us per call
        if not (math.isfinite(t) and math.isfinite(u0) and math.isfinite(u1) and math.isfinite(u2)):
            h.skip("not finite")
            return
        h.accepted += 1
        cl = twist_covariance_values(twist_cov, self.cfg.encoder_sigmas)  # the entries as floats, once
        still = abs(u0) < 1e-3 and abs(u1) < 1e-3 and abs(u2) < 1e-3
        t = float(t)
        self.inputs.standstill(t, still)
        self.odo_t.append(t)
        self.odo_u.append((u0, u1, u2))
        sp = math.hypot(u0, u1)
        if sp > self._odo_speed_max:
            self._odo_speed_max = sp
        if abs(u2) > self._odo_rate_max and cl[8] <= TWIST_VAR_MAX:
            self._odo_rate_max = abs(u2)
        if abs(u1) > self._odo_lateral_max and cl[4] <= TWIST_VAR_MAX:
            self._odo_lateral_max = abs(u1)
        if cl[0] <= TWIST_VAR_MAX and cl[4] <= TWIST_VAR_MAX and cl[8] <= TWIST_VAR_MAX:
            self.odo_c.append((cl[0], cl[1], cl[2], cl[4], cl[5], cl[8]))   # upper6(c): bounded_covariance leaves it
        else:
            self.odo_c.append(upper6(bounded_covariance(np.array(cl).reshape(3, 3), TWIST_VAR_MAX)))
        if cl[8] <= TWIST_VAR_MAX:  # a yaw rate the source does not fuse is no yaw source to weigh
            self.inputs.reading("odom", RATE, 0.05, t, u2, cl[8])
        if self.pending_kf:
            self._process_pending(t)
        # keep a bounded history: the window plus a margin
        if len(self.odo_t) > 4096 and self.kf_t:
            horizon = self.kf_t[-1] - self.cfg.lag_s - 1.0
            i = int(np.searchsorted(self.odo_t, horizon))
            if i > 0:
                del self.odo_t[:i], self.odo_u[:i], self.odo_c[:i]

    def add_compass(self, t: float, yaw: float | None, yaw_var: float,
                    rate: float | None, rate_var: float, source: str = "imu") -> None:
        if rate is not None and self.cfg.gyro:
            self.add_gyro(t, rate, rate_var, source)
        if yaw is None:
            return
        name = f"{source}.yaw"
        h = self.inputs.source(name, "heading")
        self.calib.add_compass(t, yaw, rate)
        var = self.inputs.variance(yaw_var, self.cfg.compass_sigma)
        tf, yf, vf = float(t), float(yaw), float(var)
        self.inputs.heading(name, tf, yf, vf * self.inputs.noise(name)[0] ** 2)
        h.accepted += 1
        self.inputs.reading(name, ANGLE_ABSOLUTE, 0.02, tf, yf, vf)
        self.compass_pending.append((tf, yf, vf, source))
        self._add_heading_reading(tf, yf, vf, source)
        if self.pending_kf:
            self._process_pending(tf)

    def add_gyro(self, t: float, rate: float, rate_var: float, source: str = "imu") -> None:
        """A yaw rate (rad/s, base_link z) from a gyro: integrated between keyframes, bias estimated."""
        name = f"{source}.gyro"
        h = self.inputs.source(name, "gyro")
        buf = self.gyro.get(name)
        if buf is None:
            buf = self.gyro[name] = ([], [], [])
        if buf[0] and t <= buf[0][-1]:
            h.skip("late or repeated stamp")
            return
        if not self.inputs.finite(h, t, rate):
            return
        var = self.inputs.variance(rate_var, self.cfg.gyro_sigma_radps)
        h.accepted += 1
        tf, rf, vf = float(t), float(rate), float(var)
        if not self.cfg.gyro_bias_in_graph:
            gb = self.inputs.gyro(name, self.cfg.gyro_bias_prior_radps, self.cfg.gyro_bias_rw_radps)
            gb.add_rate(tf, rf, vf)
            self.inputs.arb.set_correction(name, bias=gb.value())
        buf[0].append(tf)
        buf[1].append(rf)
        buf[2].append(vf)
        self._gyro_done.setdefault(name, -np.inf)
        self.inputs.reading(name, INSTANT_RATE, 0.01, tf, rf, vf)
        if len(buf[0]) > 8192 and self.kf_t:
            horizon = self.kf_t[-1] - self.cfg.lag_s - 2.0
            i = bisect_left(buf[0], horizon)
            if i > 0:
                del buf[0][:i], buf[1][:i], buf[2][:i]

    def add_relative_yaw(self, t: float, yaw: float, var: float, source: str = "imu") -> None:
        """An orientation whose increments are used, not its frame (robot_localization's
        ``imuN_differential``): at each keyframe the readings since the previous one, carried to
        its stamp by the rotation in between and averaged, are a heading factor ``z = theta + c``
        (:func:`~fgloc.backends.factors.relative_yaw_factor`) on the source's own offset chain ``c``
        (``r<j>``: anchored at the first reading with a loose prior, a random walk of
        ``relative_yaw_rw_sigma_deg``), as the compass's ``o<j>``.

        Not as the rate ``d_yaw / d_t`` between stamps: with jittered stamps (two messages 0.2 ms
        apart) that rate spikes to several rad/s; as a heading the increments enter whole, whatever
        the stamps.  A reading that jumped beyond ``fix_gate_theta`` of the graph's heading plus the
        offset is not used; :data:`REANCHOR_AFTER` keyframes of it in a row (a re-initialized AHRS)
        and the offset is anchored again.  One that crept there (the wheels' turn lies: a skid
        steer's scrub) re-opens the keyframe's heading to the source's at once
        (:func:`~fgloc.backends.relative_yaw.jumped` tells the two apart, as in the EKF)."""
        name = f"{source}.yaw"
        h = self.inputs.source(name, "heading")
        if not self.inputs.finite(h, t, yaw):
            return
        v = self.inputs.variance(var, self.cfg.compass_sigma)
        self.inputs.reading(name, ANGLE_ABSOLUTE, 0.02, float(t), float(yaw), float(v))
        # its increments observe a gyro's bias (its frame never enters)
        self.inputs.heading(name, float(t), float(yaw), float(v) * self.inputs.noise(name)[0] ** 2)
        if not self.initialized:
            return
        self.rel_pending.append((float(t), float(yaw), float(v), source))
        if self.pending_kf:
            self._process_pending(float(t))

    def add_velocity(self, t: float, twist: FloatArray, twist_cov: FloatArray, used: tuple[bool, bool, bool],
                     source: str) -> None:
        """Another odometry source's body twist ``[vx, vy, wz]`` (a visual odometer beside the
        wheels, robot_localization's ``odom1``): integrated between keyframes like the first
        source's (:func:`~fgloc.backends.factors.integrate_twist`, its own propagated covariance)
        into a between-keyframe factor of its own, a second independent measurement of the same
        motion.  Its unused components are unmeasured (variance :data:`TWIST_VAR_MAX`), its yaw
        noise is what it shows against the other yaw sources; an increment beyond the chi-square
        99.9 % gate against the keyframes' current relative pose (a lost visual track) is not
        used; the factor is robust (``odom_kernel``).  Where it reports translation, that
        translation's scale and yaw misalignment on the base (``a<j>``, a random walk as the first
        source's gains; :func:`~fgloc.backends.factors.aligned_between_factor`) are estimated
        against the graph: r_l's groovy test1.bag's stereo odometer reports 11 % less distance than
        the wheels and 2.3 deg sideways.  The first source alone carries the yaw-rate scale, the
        standstill and the motion integrals."""
        h = self.inputs.source(source, "odometry")
        tw = np.asarray(twist, dtype=float).reshape(-1)
        cov = np.asarray(twist_cov, dtype=float).reshape(3, 3)
        if tw.shape != (3,) or not (math.isfinite(t) and np.all(np.isfinite(tw)) and np.all(np.isfinite(cov))):
            h.skip("not finite")
            return
        buf = self.vel.setdefault(source, ([], [], []))
        if buf[0] and t <= buf[0][-1]:
            h.skip("late or repeated stamp")
            return
        c = 0.5 * (cov + cov.T)
        for i in range(3):
            if not used[i] or not c[i, i] > 0:
                c[i, :] = 0.0
                c[:, i] = 0.0
                c[i, i] = TWIST_VAR_MAX
        if used[2]:
            self.inputs.reading(source, RATE, 0.05, float(t), float(tw[2]), float(c[2, 2]))
        buf[0].append(float(t))
        buf[1].append(tw)
        buf[2].append(bounded_covariance(c, TWIST_VAR_MAX))
        self._vel_done.setdefault(source, -np.inf)
        self._vel_translates[source] = bool(used[0] or used[1])
        h.accepted += 1
        if len(buf[0]) > 4096 and self.kf_t:
            i = bisect_left(buf[0], self.kf_t[-1] - self.cfg.lag_s - 2.0)
            if i > 0:
                del buf[0][:i], buf[1][:i], buf[2][:i]

    def predict(self, t: float) -> tuple[FloatArray, FloatArray]:
        assert self.kf_key, "smoother not initialized"
        k = self.kf_key[-1]
        key = (k, float(t), len(self.odo_t))
        if self._pred_cache is not None and self._pred_cache[0] == key:
            return self._pred_cache[1], self._pred_cache[2]
        t0 = self.kf_t[-1]
        p0 = self.kf_pose[k]
        tol = self._odom_gap_s()
        if self.odo_t and self._unmeasured_tail(t0, t, tol) <= 0.0 and self._gap_s(t0, t, tol) <= 0.0:
            # the odometry measures the whole interval (_motion's own integral): in floats, no arrays between
            x, y, th, c00, c01, c02, c11, c12, c22 = self._integrate_values(t0, t)
            pose = compose1(p0, self._corrected_values(x, y, th, t0, t))
            cov = carried_covariance_upper(self._last_cov, p0, pose, c00, c01, c02, c11, c12, c22)
        else:
            d, c = self._motion(t0, t)
            pose = compose1(p0, self._corrected(d, t0, t))
            cov = carried_covariance(self._last_cov, p0, pose, c)
        self._pred_cache = (key, pose, cov)
        return pose, cov

    def motion_summary(self, vy_max_mps: float | None = None) -> str:
        """The odometry's twist as integrated (:meth:`Backend.motion_summary`); without odometry, the
        graph's own velocity carried on."""
        if self.initialized and "odom" not in self.inputs.health:   # it ran without odometry
            turn = "; the gyro's yaw rate turns it" if self.gyro else ""
            return ("no odometry: the graph's own velocity is carried from keyframe to keyframe (constant "
                    f"velocity, a random walk of it between the scans' fixes){turn}")
        return super().motion_summary(vy_max_mps)

    def motion_correction(self, t0: float, t1: float, delta: FloatArray) -> FloatArray:
        """The odometry increment with the estimated gains and the gyro's rotation where it covers it."""
        if t1 <= t0:
            return delta
        return self._corrected(np.asarray(delta, dtype=float), t0, t1)

    def finish(self) -> Trajectory:
        self._process_pending(np.inf)
        self._flush_acc()
        self._velocity_tail()
        self._flush_window()
        if not self.smoothed:
            return Trajectory(np.zeros(0), np.zeros((0, 3)))
        items = sorted(self.smoothed.values(), key=lambda v: v[0])
        return Trajectory.from_unsorted(np.array([v[0] for v in items]), np.array([v[1] for v in items]))
