"""The paper's EKF as a :class:`~fgloc.backends.base.Backend`.

Odometry twists are encoder updates, compass readings compass updates (heading
converted to the map frame with the calibrated offset, rate only until then; when
the joint ``[theta, w]`` update is gated the rate is applied alone), and keyframe
fixes map updates (a late fix, older than the filter time, is first carried forward by the
filter's velocities).  The online and the final trajectory are the same: the pose
right after each scan's fix (a filter does not smooth).

Beyond the paper, all switchable in ``ekf:``:

* a gyro's yaw rate (an IMU's, or the compass module's) measures ``w + b``; its bias ``b`` is
  estimated beside the filter (:class:`~fgloc.backends.health.GyroBias`: from the absolute
  headings and standstill, never from the wheels, whose scrub would be read as a bias);
* once another source measures the turn (a gyro, a compass's or an IMU's absolute yaw, a
  differential orientation), the odometry's yaw-rate scale (reported / true, a skid steer's
  scrub) is a state, as its logarithm (a scale cannot change sign) kept in a physical range
  (:data:`SCALE_MIN`, :data:`SCALE_MAX`): the encoder's yaw rate measures ``s_w * w``;
* the yaw sources are weighted by the noise they show against each other
  (:class:`~fgloc.backends.health.Arbiter`, the same as the smoother's);
* a compass heading gated for ``compass_recover_after`` readings in a row while the sources
  agree it is healthy re-opens the heading (the filter had drifted, not the compass);
* the scans' latency is estimated (:class:`~fgloc.backends.health.LatencyEstimator`) and a
  fix applied at ``stamp - latency`` (carried forward by the filter's velocities);
* ``omni: null``: the state becomes omni as soon as the odometry reports lateral velocity (without
  odometry: as soon as the fixes move sideways, :mod:`fgloc.backends.sideways`);
* ``odom_held_back`` (default): an odometry twist is the mean over the interval since the previous
  message (how fgloc's odometry tracker and the smoother integrate it, and what a pose-increment
  twist is), so it measures the velocity at the interval's start and the filter crosses the interval
  with it; the odometry alone (no gyro, no second odometry) sets that velocity whole.  Beside a gyro
  only across a gap (:data:`GAP_FACTOR`): at the regular rate the twist is the velocity at its stamp.  Stamps in
  bursts (two within :data:`BURST_STEP_S`) keep the paper's semantics: the localizer then hands
  velocities estimated over the last poses.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable, Mapping
from dataclasses import replace
from typing import Any

import numpy as np

from fgloc.backends.base import Backend, FloatArray
from fgloc.backends.compass import CompassCalibrator
from fgloc.backends.contract import SCANS_ALONE_AFTER_S, Capability, SourceNoise
from fgloc.backends.ekf import CHI2_999, EKF, OVX, OVY, OW, SCALE_EVIDENCE_SIGMAS, TH, EKFConfig, V, W, motion_model
from fgloc.backends.ekf_history import InOrder
from fgloc.backends.health import ANGLE_ABSOLUTE, INSTANT_RATE, RATE, Arbiter, SourceHealth
from fgloc.backends.inputs import InputBook, twist_covariance
from fgloc.backends.motion_integrals import MotionIntegrals
from fgloc.backends.relative_yaw import ANCHORED, GATED, REOPENED, RelativeYaw
from fgloc.backends.sideways import SidewaysEvidence
from fgloc.geometry import log as se2_log
from fgloc.geometry import with_rotation, wrap_scalar
from fgloc.types import PoseFix, Trajectory

GYRO_RECOVER_AFTER = 5     # gyro readings gated in a row before the filter's yaw rate is re-opened to it
STILL_TWIST = 1e-3          # |vx|, |vy| (m/s) and |w| (rad/s) below this: the wheels stand still
#: the odometry's yaw-rate scale (reported / true) stays in these bounds: a skid steer's wheels
#: report 1.4-7 times the turn; a yaw rate off by more than 10x either way carries no usable turn
#: (a negative scale, wheels that turn the other way than the robot, is not a scale: the
#: arbiter's noise estimate down-weights such a source)
SCALE_MIN, SCALE_MAX = 0.1, 10.0
YAW_SCALE_STATE = "odom_yaw_log_scale"
#: s: odometry stamps closer than this are a logger's burst (CARMEN logs: four 10 Hz poses within
#: 1.2 ms; a real e-puck's closest are 6 ms apart); while one is among the last BURST_WINDOW steps the
#: twists are velocities at their stamps, not held back over their steps (``ekf.odom_held_back``)
BURST_STEP_S = 0.002
BURST_WINDOW = 16
#: an odometry step longer than GAP_FACTOR times the median of the last BURST_WINDOW steps (and than
#: GAP_MIN_S) is a gap: its twist is taken as the mean over it even beside a gyro
GAP_FACTOR = 3.0
GAP_MIN_S = 0.2


def _median(values: Iterable[float]) -> float:
    """``np.median`` of a few floats (the middle one, or the mean of the two middle ones), without
    numpy's per-call overhead (every odometry message)."""
    d = sorted(values)
    m = len(d) // 2
    return float(d[m]) if len(d) % 2 else float((d[m - 1] + d[m]) / 2.0)


class EKFBackend(Backend):
    name = "ekf"
    config_section = "ekf"
    #: the odometry twist measures the filter's velocity state (its pose integrates that state)
    capabilities = frozenset({Capability.MEASURES_VELOCITY, Capability.GYRO, Capability.VELOCITY,
                              Capability.RELATIVE_YAW, Capability.ODOM_SCALES, Capability.GYRO_BIAS,
                              Capability.LATENCY, Capability.LIVE, Capability.STATE_COVARIANCE})

    @classmethod
    def from_config(cls, config: Any = None) -> EKFBackend:
        """With ``config.ekf``."""
        return cls(None if config is None else config.ekf)

    def __init__(self, config: EKFConfig | None = None) -> None:
        super().__init__()
        c = config or EKFConfig()
        self.cfg = c
        self.ekf = EKF(c)
        self.ekf.x = np.zeros(self.ekf.n)
        self.ekf.P = np.eye(self.ekf.n)
        # measurements in stamp order: a late one put in its place (ekf_history.py)
        self.order = InOrder(self.ekf, c.history_s)
        self.compass_sigma = c.compass_sigma
        self.compass_rate_sigma = c.compass_rate_sigma
        self.use_compass_yaw = c.use_compass_yaw
        self.calib = CompassCalibrator(c.calibration_fixes)
        self.max_rejections = c.max_rejections
        self._consecutive_rejects = 0
        self._compass_gated_run = 0
        self._gyro_gated_run = 0
        self._rel: dict[str, RelativeYaw] = {}   # the differential orientation sources
        self.inputs = InputBook(Arbiter(), c.adapt_noise, c.latency, c.latency_s)
        # motion integrals for the latency estimate: (t, yaw, w) from the gyro (or the odometry),
        # (t, distance, v) from the odometry, each at its own stamps
        self.motion = MotionIntegrals()
        self._turned = 0.0
        self._last_odom_t: float | None = None
        self._odom_before_start: float | None = None  # the last odometry stamp before the filter started
        self._start_t: float | None = None
        self._sideways = SidewaysEvidence()   # without odometry: whether the fixes move sideways
        self._odom_steps: deque[float] = deque(maxlen=BURST_WINDOW)  # the last odometry stamp steps (s)
        self.stats["omni"] = bool(self.ekf.omni)

    # ------------------------------------------------------------------ helpers
    @property
    def initialized(self) -> bool:
        return self.ekf.initialized

    @property
    def encoder_sigmas(self) -> tuple[float, float, float]:
        return self.cfg.encoder_sigmas

    def source_health(self) -> Mapping[str, SourceHealth]:
        return self.inputs.health

    def source_noise(self, name: str) -> SourceNoise | None:
        return self.inputs.source_noise(name)

    def motion_summary(self, vy_max_mps: float | None = None) -> str:
        """The filter's state (differential or omni) and why."""
        if self.initialized and "odom" not in self.inputs.health:   # it ran without odometry
            om = self.ekf.omni
            why = "configured" if self.cfg.omni is not None else f"the fixes {'' if om else 'never '}moved sideways"
            state = f"{'omni [x, y, yaw, vx, vy, w]' if om else 'differential [x, y, yaw, v, w]'} ({why})"
            return f"no odometry: the filter's own velocity carries the pose from fix to fix; {state}"
        v = self.cfg.omni_vy_mps
        if self.stats.get("omni_since") is not None:
            return ("omni [x, y, yaw, vx, vy, w]: the odometry reported lateral velocity"
                    + (f" (> {v} m/s)" if v else ""))
        if self.stats.get("omni"):
            return "omni [x, y, yaw, vx, vy, w] (configured: ekf.omni true)"
        if self.cfg.omni is False:
            why = "configured: ekf.omni false"
        elif vy_max_mps:
            why = (f"the lateral velocity it was handed stayed under ekf.omni_vy_mps {v} m/s; the messages reported "
                   f"up to {vy_max_mps:.3f} m/s")
        else:
            why = "the odometry never reported lateral velocity"
        return f"differential [x, y, yaw, v, w] ({why})"

    def initialize(self, t: float, pose: FloatArray, cov: FloatArray | None = None) -> None:
        self.ekf.initialize(t, pose, cov)
        self._start_t = float(t)
        self.order.clear()
        self._consecutive_rejects = 0
        self._record_online(t, self.ekf.pose(), self.ekf.pose_cov())

    def set_compass_offset(self, offset: float) -> None:
        self.calib.offset = float(offset)

    def compass_offset(self) -> float | None:
        return self.calib.offset

    def odom_scales(self) -> FloatArray:
        """The odometry's ``[speed, yaw-rate]`` scales (reported / true); the EKF keeps speed at 1."""
        return np.array([1.0, self._yaw_scale()])

    def _yaw_scale(self) -> float:
        """The odometry's yaw-rate scale (1 until it is a state)."""
        i = self.ekf.aug.get(YAW_SCALE_STATE)
        return math.exp(float(self.ekf.x[i])) if i is not None else 1.0

    def gyro_bias(self, source: str = "imu") -> float:
        gb = self.inputs.gyro_bias.get(f"{source}.gyro")
        return gb.value() if gb is not None else 0.0

    def latency_estimate(self) -> float:
        return self.inputs.latency.value()

    def latency_fit(self) -> tuple[float, float] | None:
        return self.inputs.latency.fit()

    def motion_correction(self, t0: float, t1: float, delta: FloatArray) -> FloatArray:
        """The odometry increment with the gyro's rotation where it covers ``(t0, t1]`` (else the
        odometry's yaw times its estimated gain)."""
        if t1 <= t0:
            return delta
        rot = self.motion.rotation(t0, t1)
        if rot is not None:
            return with_rotation(delta, rot)
        if YAW_SCALE_STATE in self.ekf.aug:
            return with_rotation(delta, float(se2_log(np.asarray(delta, dtype=float))[2]) / self._yaw_scale())
        return delta

    # ------------------------------------------------------------------ inputs
    def add_odometry(self, t: float, twist: FloatArray, twist_cov: FloatArray | None) -> None:
        tw = np.asarray(twist, dtype=float)
        h = self.inputs.source("odom", "odometry")
        if self.cfg.omni is None and not self.ekf.omni and abs(float(tw[1])) > self.cfg.omni_vy_mps:
            self.ekf.to_omni()  # the odometry reports lateral velocity: a mecanum / omni base
            self.stats["omni"] = True
            self.stats["omni_since"] = float(t)
        cov = np.array(twist_covariance(twist_cov, self.encoder_sigmas), dtype=float)
        still = bool(np.all(np.abs(tw) < STILL_TWIST))
        self.inputs.standstill(float(t), still)
        self.inputs.reading("odom", RATE, 0.05, t, float(tw[2]), float(cov[2, 2]))
        si = self.ekf.aug.get(YAW_SCALE_STATE)
        gain = 1.0 / self._yaw_scale()
        self.inputs.arb.set_correction("odom", gain=gain)
        # motion integrals (held backwards, as the twist is the mean since the last message)
        self.motion.add_odometry(t, float(np.hypot(tw[0], tw[1])),
                                 None if self._has_gyro() else float(tw[2]) * gain)
        if not self.initialized:
            self._odom_before_start = float(t)
            return
        # the scale's evidence floor from the twist's own yaw noise (the arbiter's weight may shrink
        # it below the flicker of a yaw rate differenced from ticks)
        scale_min_rate = SCALE_EVIDENCE_SIGMAS * math.sqrt(max(float(cov[2, 2]), 0.0))
        k, rel = self.inputs.noise("odom")
        if k != 1.0 or rel > 0.0:
            cov[2, :] *= k
            cov[:, 2] *= k
            cov[2, 2] += (rel * float(tw[2])) ** 2
        held_from = None
        sole = self._odometry_sole()
        if self._last_odom_t is not None and t > self._last_odom_t:
            step = t - self._last_odom_t
            w_abs = abs(float(tw[2]))
            if w_abs > scale_min_rate:   # a turn, not a yaw rate differenced from ticks flickering about zero
                self._turned += w_abs * step
            typical = _median(self._odom_steps) if self._odom_steps else math.inf
            self._odom_steps.append(step)
            # the interval's mean velocity: for the odometry alone (nothing else measures the velocity
            # it crosses the interval with), or across a gap while other sensors carry the filter (at
            # the regular rate beside a gyro the velocity at the stamp, as robot_localization, whose
            # ported configs are tuned so, takes it)
            if self.cfg.odom_held_back and (sole or step > max(GAP_FACTOR * typical, GAP_MIN_S)):
                held_from = self._last_odom_t
        elif self.cfg.odom_held_back and sole and self._odom_before_start is not None and self._start_t is not None:
            # the first message since the start: its twist is the mean since the message before the start,
            # of which the part after the start moved the robot from the start pose (a slow odometry's first
            # interval, crossed with no velocity, would turn the whole path by its turn)
            held_from = max(self._odom_before_start, self._start_t)
        if held_from is not None and any(d < BURST_STEP_S for d in self._odom_steps):
            # stamps in bursts: the localizer hands velocities it estimated over the last poses, not
            # the twist of each increment (OdometryTracker.velocity_measurement): measured at their stamps
            held_from = None
        self._last_odom_t = float(t)
        if self.cfg.odom_yaw_scale and si is None and self._turned > 0.3 and self._heading_measured():
            # observable once turning beside another yaw source (early: a gyro's bias state would take
            # its error)
            si = self.ekf.add_state(YAW_SCALE_STATE, 0.0, self.cfg.odom_yaw_scale_prior**2, self.cfg.odom_yaw_scale_q,
                                    bounds=(math.log(SCALE_MIN), math.log(SCALE_MAX)))
        h.accepted += 1
        keep_w = self._has_gyro()

        def encoder() -> bool:
            return self.ekf.update_encoder(t, tw, cov, yaw_log_scale_index=si, held_from=held_from,
                                           keep_w_noise=keep_w, sole=sole, scale_min_rate=scale_min_rate)

        def again(_: bool) -> None:
            encoder()

        self.order.apply(t, encoder, again)
        self.inputs.latency.evaluate(self.motion)

    def add_velocity(self, t: float, twist: FloatArray, twist_cov: FloatArray, used: tuple[bool, bool, bool],
                     source: str) -> None:
        """Another odometry source's body twist ``[vx, vy, wz]`` (visual odometry beside the wheels):
        the ``used`` components are velocity measurements of the state (the unicycle has no vy),
        gated at the chi-square 99.9 % quantile (a lost visual track), its yaw rate weighted by the
        noise it shows against the other yaw sources.  The first odometry source alone drives the
        motion integrals, scale and standstill (:meth:`add_odometry`)."""
        h = self.inputs.source(source, "odometry")
        tw = np.asarray(twist, dtype=float).reshape(-1)
        cov = np.asarray(twist_cov, dtype=float).reshape(3, 3)
        if tw.shape != (3,) or not (math.isfinite(t) and np.all(np.isfinite(tw))):
            h.skip("not finite")
            return
        comps = [i for i in range(3) if used[i] and (self.ekf.omni or i != 1) and float(cov[i, i]) > 0]
        if not comps:
            return
        if used[2]:
            self.inputs.reading(source, RATE, 0.05, t, float(tw[2]), float(cov[2, 2]))
        if not self.initialized:
            return
        c = cov[np.ix_(comps, comps)].copy()
        if 2 in comps:
            k, rel = self.inputs.noise(source)
            j = comps.index(2)
            c[j, :] *= k
            c[:, j] *= k
            c[j, j] += (rel * float(tw[2])) ** 2
        rows = [((OVX, OVY, OW) if self.ekf.omni else (V, -1, W))[i] for i in comps]
        z = tw[comps]

        def again(ok: bool) -> None:
            if ok:
                self.ekf.update(t, z, rows, c, None, source)
            else:
                self.ekf.predict(t)

        if self.order.apply(t, lambda: self.ekf.update(t, z, rows, c, CHI2_999[len(comps)], source), again):
            h.accepted += 1
        else:
            h.gated += 1

    def _has_gyro(self) -> bool:
        return bool(self.inputs.gyro_bias)

    def _heading_measured(self) -> bool:
        """Whether a source besides the wheels measures the turn: a gyro (the yaw rate), a compass's or
        an IMU's absolute yaw in use (the heading), a differential orientation (its increments).  The
        wheels' yaw-rate scale is observable against any of them through the yaw rate the heading
        integrates."""
        return self._has_gyro() or bool(self._rel) or (
            self.use_compass_yaw and self.calib.calibrated and self.calib.has_readings)

    def _odometry_sole(self) -> bool:
        """Whether the odometry is the only source of the velocities (no gyro, no second odometry)."""
        return not self.inputs.gyro_bias and not any(h.kind == "odometry" and n != "odom"
                                                     for n, h in self.inputs.health.items())

    def add_compass(self, t: float, yaw: float | None, yaw_var: float,
                    rate: float | None, rate_var: float, source: str = "imu") -> None:
        if rate is not None and self.cfg.gyro:
            self.add_gyro(t, rate, rate_var, source)
            rate = None
        if yaw is not None:
            self.calib.add_compass(t, yaw, rate)
            vy = self.inputs.variance(yaw_var, self.compass_sigma)
            self.inputs.reading(f"{source}.yaw", ANGLE_ABSOLUTE, 0.02, t, float(yaw), float(vy))
            self.inputs.heading(f"{source}.yaw", t, float(yaw), vy * self.inputs.noise(f"{source}.yaw")[0] ** 2)
        if not self.initialized:
            return
        th = self.calib.to_map(yaw) if (yaw is not None and self.use_compass_yaw) else None
        if th is None and rate is None:
            return
        vy = self.inputs.variance(yaw_var, self.compass_sigma)
        vr = self.inputs.variance(rate_var, self.compass_rate_sigma)
        vth = vy * self.inputs.noise(f"{source}.yaw")[0] ** 2 if th is not None else vy

        def first() -> str:
            """What was applied: ``both``, ``reopened`` (+ ``-gated``), ``rate`` or ``none``."""
            if th is not None:
                h = self.inputs.source(f"{source}.yaw", "heading")
                if self.ekf.update_compass(t, th, vth, rate, vr):
                    h.accepted += 1
                    self._compass_gated_run = 0
                    return "both"
                h.gated += 1
                self._compass_gated_run += 1
                k_y, _ = self.inputs.noise(f"{source}.yaw")
                if self._compass_gated_run >= self.cfg.compass_recover_after and k_y < 3.0:
                    # gated for a while although it agrees with the other sources: the filter's heading
                    # drifted (e.g. on a wheel yaw that lies), not the compass; re-open the heading
                    self._reopen_heading(th, vth)
                    ok = self.ekf.update_compass(t, th, vth, None, vr)
                    self.stats["compass_recoveries"] = self.stats.get("compass_recoveries", 0) + 1
                    self._compass_gated_run = 0
                    return "reopened" if ok else "reopened-gated"
            if rate is not None:
                return "rate" if self.ekf.update_compass(t, None, vy, rate, vr) else "none"
            return "none"

        def again(how: str) -> None:
            if how == "both":
                self.ekf.update_compass(t, th, vth, rate, vr, gated=False)
            elif how.startswith("reopened") and th is not None:
                self.ekf.predict(t)
                self._reopen_heading(th, vth)
                if how == "reopened":
                    self.ekf.update_compass(t, th, vth, None, vr, gated=False)
            elif how == "rate":
                self.ekf.update_compass(t, None, vy, rate, vr, gated=False)
            else:
                self.ekf.predict(t)

        self.order.apply(t, first, again)

    def _reopen_heading(self, th: float, var: float) -> None:
        """The heading's variance at least the innovation of ``th`` (map frame) squared plus ``var``."""
        innov = wrap_scalar(th - float(self.ekf.x[TH]))
        self.ekf.P[TH, TH] = max(self.ekf.P[TH, TH], innov * innov + var)

    def add_gyro(self, t: float, rate: float, rate_var: float, source: str = "imu") -> None:
        """A yaw rate (rad/s, base_link z) measuring ``w + bias`` (a bias state per gyro)."""
        name = f"{source}.gyro"
        h = self.inputs.source(name, "gyro")
        if not self.inputs.finite(h, t, rate):
            return
        var = self.inputs.variance(rate_var, self.compass_rate_sigma)
        self.inputs.reading(name, INSTANT_RATE, 0.01, t, float(rate), float(var))
        gb = self.inputs.gyro(name, self.cfg.gyro_bias_prior_radps, math.sqrt(self.cfg.gyro_bias_q))
        gb.add_rate(float(t), float(rate), float(var))
        b = gb.value()
        self.inputs.arb.set_correction(name, bias=b)
        # the motion integral (readings interpolated)
        self.motion.add_gyro(t, rate, b)
        if not self.initialized:
            return
        k, rel = self.inputs.noise(name)
        var = k * k * var + (rel * rate) ** 2 + gb.sigma() ** 2
        z = float(rate) - b

        def first() -> str:
            """What was applied: ``used``, ``reopened`` or ``gated``."""
            if self.ekf.update_gyro(t, z, var, None, CHI2_999[1] * 4):
                h.accepted += 1
                self._gyro_gated_run = 0
                return "used"
            h.gated += 1
            self._gyro_gated_run += 1
            k_g, _ = self.inputs.noise(name)
            if self._gyro_gated_run >= GYRO_RECOVER_AFTER and k_g < 3.0:
                # gated again and again while it agrees with the other yaw sources: the filter's
                # yaw rate is what is off (a slow process noise, a lying wheel), not the gyro
                self._reopen_rate(z)
                self.ekf.update_gyro(t, z, var, None, None)
                self.stats["gyro_recoveries"] = self.stats.get("gyro_recoveries", 0) + 1
                self._gyro_gated_run = 0
                return "reopened"
            return "gated"

        def again(how: str) -> None:
            self.ekf.predict(t)
            if how == "reopened":
                self._reopen_rate(z)
            if how != "gated":
                self.ekf.update_gyro(t, z, var, None, None)

        self.order.apply(t, first, again)
        self.inputs.latency.evaluate(self.motion)

    def _reopen_rate(self, rate: float) -> None:
        """The yaw rate's variance at least the innovation of ``rate`` (bias removed) squared."""
        wi = self.ekf.w_index
        innov = rate - float(self.ekf.x[wi])
        self.ekf.P[wi, wi] = max(self.ekf.P[wi, wi], innov * innov)

    def add_relative_yaw(self, t: float, yaw: float, var: float, source: str = "imu") -> None:
        """An orientation whose increments are used, not its frame (robot_localization's
        ``imuN_differential``): ``z = theta + c`` with the source's own offset ``c`` a state
        (anchored at the first reading, a random walk of ``relative_yaw_q``).

        Not as the rate ``d_yaw / d_t`` between stamps: with jittered stamps (two messages
        0.2 ms apart) that rate spikes to several rad/s, its claimed variance ``(C1 + C2) dt``
        shrinks as it grows, the gate drops it and its increment is lost (r_l's groovy
        test_bag1: 3130 of 12954 such rates gated).  As a heading the increments enter whole,
        whatever the stamps.  Gated as :mod:`fgloc.backends.relative_yaw` says (a jump is gated, then
        re-anchored; a heading that crept off re-opened)."""
        name = f"{source}.yaw"
        h = self.inputs.source(name, "heading")
        if not self.inputs.finite(h, t, yaw):
            return
        v = self.inputs.variance(var, self.compass_sigma)
        self.inputs.reading(name, ANGLE_ABSOLUTE, 0.02, t, float(yaw), float(v))
        k, _ = self.inputs.noise(name)
        v *= k * k
        self.inputs.heading(name, t, float(yaw), v)
        if not self.initialized:
            return
        rel = self._rel.get(source)
        if rel is None:
            rel = self._rel[source] = RelativeYaw(f"yaw_offset:{source}", self.cfg.relative_yaw_q,
                                                  self.cfg.gate_compass, self.cfg.compass_recover_after)
        y = float(yaw)

        def first() -> str:
            self.ekf.predict(t)
            reanchor = rel.key in self.ekf.aug
            how = rel.first(self.ekf, y, v)
            if how == GATED:
                h.gated += 1
            else:
                h.accepted += 1
            if how == ANCHORED and reanchor:
                self.stats["relative_yaw_reanchored"] = self.stats.get("relative_yaw_reanchored", 0) + 1
            elif how == REOPENED:
                self.stats["relative_yaw_reopened"] = self.stats.get("relative_yaw_reopened", 0) + 1
            return how

        def again(how: str) -> None:
            self.ekf.predict(t)
            rel.again(self.ekf, how, y, v)

        self.order.apply(t, first, again)

    def add_keyframe(self, t: float, fix: PoseFix | None) -> bool:
        if not self.initialized:
            return False
        used = False
        if self.cfg.adapt_noise:
            self.inputs.arb.update(t)
        if "odom" not in self.inputs.health and t - (self._start_t or t) >= SCANS_ALONE_AFTER_S \
                and self.ekf.config is self.cfg:   # scans alone: the velocity is the fixes' alone
            self.ekf.config = replace(self.cfg, q_v=self.cfg.scans_alone_q[0], q_w=self.cfg.scans_alone_q[1])
        if fix is not None and self.cfg.omni is None and not self.ekf.omni and "odom" not in self.inputs.health \
                and self._sideways.add(t, fix.pose):
            self.ekf.to_omni(self.cfg.q_v)   # scans alone, and the fixes move sideways (fgloc.backends.sideways)
        if fix is not None:
            force = self._consecutive_rejects >= self.max_rejections
            pose, cov = np.asarray(fix.pose, dtype=float), np.asarray(fix.cov, dtype=float)
            self.inputs.latency.add_fix(t, pose, cov)
            self.inputs.reading("scan", ANGLE_ABSOLUTE, 0.005, t - self.latency_estimate(), float(pose[2]),
                                float(cov[2, 2]))
            t_meas = t - self.latency_estimate()  # a late-stamped scan shows the pose this long before
            heading = (t_meas, float(pose[2]), max(float(cov[2, 2]), self.cfg.map_min_sigma_theta**2))
            if self.ekf.t is not None and t_meas < self.ekf.t and not self.order.in_history(t_meas):
                # a late fix older than the history: carried forward to the filter time by the
                # filter's own velocities, with their motion noise
                dt = self.ekf.t - t_meas
                s = self.ekf.x.copy()
                s[:3] = pose
                pose = motion_model(s, dt, self.ekf.omni)[:3]
                cov = cov + self.ekf.process_noise(dt)[:3, :3]
                t_meas = self.ekf.t
            # (within the history a late fix is applied at its stamp, the later measurements after it)
            z, R, tm = pose, cov, t_meas

            def again(ok: bool) -> None:
                if ok:
                    self.ekf.update_map(tm, z, R, gate=False)
                else:
                    self.ekf.predict(tm)

            rec = max(self.ekf.t or tm, tm)
            used = self.order.apply(tm, lambda: self.ekf.update_map(tm, z, R, gate=not force), again, record=rec)
            h = self.inputs.source("scan", "pose")
            if used:
                h.accepted += 1
                self._consecutive_rejects = 0
                self.stats["fixes_used"] += 1
                self.calib.add_fix(t_meas, float(pose[2]))
                self.inputs.heading("scan", *heading)
            else:
                h.gated += 1
                self._consecutive_rejects += 1
                self.stats["fixes_rejected"] += 1
        elif self.ekf.t is None or t > self.ekf.t:
            self.order.apply(t, lambda: self.ekf.predict(t), lambda _: self.ekf.predict(t), record=t)
        self.stats["keyframes"] += 1
        self._record_online(self.ekf.t or t, self.ekf.pose(), self.ekf.pose_cov())
        return used

    # ------------------------------------------------------------------ outputs
    def predict(self, t: float) -> tuple[FloatArray, FloatArray]:
        return self.ekf.predict_pose(t)

    def current(self, covariance: bool = True) -> tuple[float, FloatArray, FloatArray] | None:
        if not self.initialized:
            return None
        return float(self.ekf.t or 0.0), self.ekf.pose(), self.ekf.pose_cov()

    def finish(self) -> Trajectory:
        """The pose after each scan's fix, revised where a measurement stamped before it came after it."""
        self.stats["gated"] = dict(self.ekf.stats["gated"])
        self.stats["omni"] = bool(self.ekf.omni)
        for k in ("reordered", "late"):
            self.stats[k] = self.stats.get(k, 0) + self.order.stats[k]
        tr = self.online_trajectory()
        self.order.revise(tr.stamps, tr.poses, tr.covs)
        return tr
