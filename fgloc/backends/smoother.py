"""Sliding-window smoother on ``gtsam.IncrementalFixedLagSmoother`` and its batch twin.

Graph (variables ``x<i>``: ``Pose2`` keyframes at scan times; ``o<j>``: the compass-to-map
offset, one per ``offset_interval`` seconds, ``compass_yaw = map_yaw + offset``, as the compass
frame's pose in the map ``Pose2(0, 0, -offset)``, so that every factor on it is a C++ one):

* encoder twist factors ``x<i-1> - x<i>``: the odometry twists between the two keyframes
  integrated with propagated covariance (:func:`~fgloc.backends.factors.integrate_twist`),
  a C++ ``BetweenFactorPose2``;
* compass factors ``x<i> - o<j>``: the compass readings since the previous keyframe, each
  carried to the keyframe time by the odometry rotation in between and averaged, a
  ``BetweenFactorPose2`` measuring the heading only (:func:`~fgloc.backends.factors.compass_factor`)
  with a robust kernel;
* offset random walk ``o<j-1> - o<j>``: ``BetweenFactorPose2`` with heading sigma
  ``offset_rw_sigma * sqrt(dt)``;
* scan-to-map fixes on ``x<i>``: robust (Huber) ``PriorFactorPose2`` with the front-end
  covariance, after a coarse gate against the prediction (``fix_gate_m``, ``fix_gate_theta``;
  an optional Mahalanobis gate ``fix_gate``).  The gate is deliberately loose: a tight gate
  against an odometry prediction locks out the good fixes once the wheels slip; the robust
  kernel bounds the pull of a wrong fix instead.  After ``max_rejections`` in a row the
  back-end is reset to the fix (the pipeline normally relocalizes first).  Measured on the
  Radish segments (issue 13, 800 scans, measured map accuracy): the prediction is the less
  reliable of the two there.  On mit-csail its NEES against SLAM averages 98 (fresh marginal),
  and half of the good fixes lie beyond chi-square's 99.9 % (16.27) from it, as do 16 of the 22
  gross ones (> 0.2 m or 3 deg from SLAM), so no threshold on that distance tells them apart.
  Tried and not kept, heading RMSE with undeclared map accuracy: a fix far from the prediction
  held until the next fix backs it (fr079 0.533 -> 0.752 deg; with the threshold scaled to the
  distances the run shows, intel 0.486 -> 1.001 too), and a Cauchy kernel on the fixes (fr079
  0.533 -> 1.538 deg, mit-csail 1.94 -> 15.4).
* the compass factors use a Cauchy kernel (redescending): a magnetic disturbance of tens of
  degrees is ignored rather than averaged in.
* gyro yaw-increment factors ``x<i-1> - x<i>``: the gyro integrated between the keyframes, its
  bias estimated beside the graph from absolute headings and standstill (the default,
  :class:`~fgloc.backends.health.GyroBias`, as the EKF) or, with ``gyro_bias_in_graph``, a graph
  variable (every yaw source, the wheels too, informs it there: a drone's placeholder yaw rate 0
  pulled it to a 0.0085 rad/s bias); where the gyro covers a keyframe interval the
  odometry's translation is integrated along its heading, the wheels' yaw-rate scale (``k<j>``)
  and speed scale (``g<j>``) are calibration variables.

A scan older than the newest keyframe but inside the window (late measurement) gets its own
keyframe at its own stamp: the twist factor spanning it is removed and replaced by two.
A keyframe waits (at most ``max_wait`` s) for the odometry that covers its stamp, so
odometry arriving after the scan is still integrated exactly.  Compass readings are
carried to the next keyframe's stamp by the odometry rotation in between (a late one
from further back too), so each reading counts at its own time.

``SlidingWindowSmoother`` is the online fixed-lag estimator; the online estimate is the
newest keyframe right after its update, the smoothed trajectory is each keyframe's estimate
as it leaves the window (i.e. smoothed over ``lag`` seconds of later data).
``BatchSmoother`` runs the same estimator online and keeps every factor; ``finish`` then
optimizes the whole run with Levenberg-Marquardt, initialized from the fixed-lag estimates.
"""

from __future__ import annotations

import math
from bisect import bisect_left, bisect_right
from collections import deque
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from operator import sub

import gtsam
import numpy as np

from fgloc.backends.base import Backend, FloatArray, twist_covariance_values
from fgloc.backends.compass import CompassCalibrator
from fgloc.backends.contract import Capability, SourceNoise, latency_fit_of
from fgloc.backends.factors import (
    aligned_between_factor,
    between_factor,
    compass_factor,
    fix_factor,
    gyro_factor,
    integrate_heading,
    integrate_twist,
    integrate_twist_lists,
    offset_pose,
    pose_offset,
    relative_yaw_factor,
    scaled_between_factor,
    scaled_delta,
    upper6,
    yaw_increment_factor,
)
from fgloc.backends.health import (
    ANGLE_ABSOLUTE,
    INSTANT_RATE,
    RATE,
    Arbiter,
    GyroBias,
    LatencyEstimator,
    SourceHealth,
    fix_speed,
)
from fgloc.config.schema import optional_radians, radians, setting
from fgloc.geometry import compose1, exp_coefficients, wrap_angle, wrap_scalar
from fgloc.geometry import exp as se2_exp
from fgloc.types import PoseFix, Trajectory


def _symbol(c: str, i: int) -> int:
    """``gtsam.symbol(c, i)`` in Python (GTSAM's layout: the character in the top 8 bits of the 64-bit
    key, the index below; no call into GTSAM per key)."""
    return (ord(c) << 56) | int(i)


def X(i: int) -> int:
    return _symbol("x", i)


def O(j: int) -> int:  # noqa: E743
    return _symbol("o", j)


MAX_REF_PERIOD_S = 0.06  # a latency reference (gyro, odometry) must be at least ~17 Hz
#: the odometry's mean message period for :meth:`SlidingWindowSmoother._timing_var` is taken over this many
TIMING_MESSAGES = 200
#: a further twist source's messages further apart than this (s) do not cover the gap (a lost
#: visual track): a twist held backwards over longer is not a measurement of the motion in it
MAX_TWIST_GAP_S = 0.5
#: a differential orientation gated at this many keyframes in a row is anchored again (re-initialized AHRS)
REANCHOR_AFTER = 5
#: s, a gyro whose last reading is older than this is not waited for (it stopped, or is that slow)
GYRO_LIVE_S = 0.25
#: rad, the prior of a differential orientation's offset at its anchor (its frame is its own: loose)
RELATIVE_YAW_PRIOR_SIGMA = 10.0
CHI2_3_999 = 16.27  # chi-square 99.9 % quantile, 3 degrees of freedom
#: m, the prior / random-walk sigma of a compass-offset variable's position (always 0: it enters
#: no other factor, any sigma holds it there; see factors.compass_factor)
OFFSET_XY_SIGMA = 1.0
BALLAST = "z"  # the inert variables that keep iSAM2's re-elimination incremental (_with_ballast)
_ZERO1 = np.zeros(1)
_UNIT1 = gtsam.noiseModel.Isotropic.Sigma(1, 1.0)


def _all_finite(*arrays: FloatArray) -> bool:
    """Every entry of the (small) arrays finite (scalar checks: np.all(np.isfinite(...)) costs ~4 us each)."""
    return all(math.isfinite(v) for a in arrays for v in np.asarray(a, dtype=float).ravel().tolist())


def _rate_integral(ts: list[float], rs: list[float], t0: float, t1: float, i: int, max_gap: float,
                   weights: dict[int, float] | None = None) -> float | None:
    """The integral over ``[t0, t1]`` of the rate readings ``rs`` at stamps ``ts``, linearly
    interpolated between them, from reading ``i`` on (the one at or before ``t0``); None where two
    readings the interval needs are more than ``max_gap`` apart.  ``weights``: each reading's
    weight in the integral is added there (for the variance of :meth:`SlidingWindowSmoother._gyro_increment`)."""
    d = 0.0
    n = len(ts)
    while i < n - 1 and ts[i] < t1:
        ta, tb = ts[i], ts[i + 1]
        a, b = max(ta, t0), min(tb, t1)
        if b > a:
            h = tb - ta
            if h > max_gap:
                return None
            fa, fb = (a - ta) / h, (b - ta) / h
            # weights of reading i and i+1 in the integral over [a, b]
            wi = (b - a) * (1.0 - 0.5 * (fa + fb))
            wj = (b - a) * 0.5 * (fa + fb)
            d += wi * rs[i] + wj * rs[i + 1]
            if weights is not None:
                weights[i] = weights.get(i, 0.0) + wi
                weights[i + 1] = weights.get(i + 1, 0.0) + wj
        i += 1
    return d


def carried_covariance(cov0_map: FloatArray, pose0: FloatArray, pose1: FloatArray, inc_cov: FloatArray) -> FloatArray:
    """The map-frame covariance of ``pose1 = pose0 (+) d``: ``cov0_map`` (``pose0``'s, map frame) carried
    along, its heading's uncertainty swept over the distance from ``pose0`` to ``pose1``, plus the
    increment's covariance ``inc_cov`` (frame of ``pose0``, as :func:`~fgloc.backends.factors.integrate_twist`
    gives it) rotated into the map.  (``inc_cov`` added as it is gave a robot heading along map +y its
    along-track variance on map x, and no heading sweep: tests/backends/test_smoother.py.)"""
    # J P J^T (J = [[1, 0, -dy], [0, 1, dx], [0, 0, 1]]) plus R c R^T, in scalars (at every prediction)
    dx, dy = float(pose1[0]) - float(pose0[0]), float(pose1[1]) - float(pose0[1])
    p00, p01, p02, _, p11, p12, _, _, p22 = np.asarray(cov0_map, dtype=float).reshape(9).tolist()
    c00, c01, c02, _, c11, c12, _, _, c22 = np.asarray(inc_cov, dtype=float).reshape(9).tolist()
    cs, sn = math.cos(float(pose0[2])), math.sin(float(pose0[2]))
    a00 = p00 - 2.0 * dy * p02 + dy * dy * p22 + cs * cs * c00 - 2.0 * cs * sn * c01 + sn * sn * c11
    a01 = p01 + dx * p02 - dy * p12 - dx * dy * p22 + cs * sn * (c00 - c11) + (cs * cs - sn * sn) * c01
    a02 = p02 - dy * p22 + cs * c02 - sn * c12
    a11 = p11 + 2.0 * dx * p12 + dx * dx * p22 + sn * sn * c00 + 2.0 * cs * sn * c01 + cs * cs * c11
    a12 = p12 + dx * p22 + sn * c02 + cs * c12
    a22 = p22 + c22
    return np.array([[a00, a01, a02], [a01, a11, a12], [a02, a12, a22]])


def _period(ts: list[float]) -> float:
    """Median spacing of the last readings (inf with fewer than 3)."""
    if len(ts) < 3:
        return math.inf
    last = ts[-50:]
    d = sorted(map(sub, last[1:], last[:-1]))  # np.median's, without numpy's overhead
    m = len(d) // 2
    return float(d[m]) if len(d) % 2 else float((d[m - 1] + d[m]) / 2.0)


#: a twist variance above this ((m/s)^2, (rad/s)^2) is "not measured" (a source's unused component,
#: robot_localization's 1e6): bounded to it, a weak prior, so the integrated odometry factor stays
#: a well-conditioned system (1e6 made iSAM2 report an indeterminate system on r_l's test1.bag)
TWIST_VAR_MAX = 100.0
#: m^2, m^2, rad^2: the prior of a restart after a solver failure is the last marginal's diagonal,
#: at most this.  A restart from the marginal inflated (x4 per failure, up to 100 m^2 / pi^2) or
#: with its correlations failed again at the next keyframe: on a run without any heading source
#: (r_l's test1.bag with odom0 vx, vy only) every keyframe after the first failure was one
RESTART_VAR_MAX = np.array([1.0, 1.0, 1.0])
#: the prior of a start when none is given (m, m, rad)
DEFAULT_INITIAL_SIGMAS = np.array([0.1, 0.1, np.deg2rad(5.0)])


def prior_covariance(cov: FloatArray | None, var_max: FloatArray | None = None) -> FloatArray:
    """A prior covariance GTSAM can use: symmetric, finite, positive semi-definite (when it is not,
    its eigenvalues are raised to 1e-6 of the largest), each variance at most ``var_max``; the
    default start prior when ``cov`` is None or not finite.  (The prior factor adds 1e-9 to each
    variance.)"""
    if cov is None:
        return np.diag(DEFAULT_INITIAL_SIGMAS**2)
    c = np.asarray(cov, dtype=float).reshape(3, 3)
    if not np.all(np.isfinite(c)):
        return np.diag(DEFAULT_INITIAL_SIGMAS**2)
    c = 0.5 * (c + c.T)
    w, v = np.linalg.eigh(c)
    if w[0] < 0.0:
        c = (v * np.maximum(w, 1e-6 * max(float(w[-1]), 1e-9))) @ v.T
    return _bounded(c, var_max) if var_max is not None else c


def _bounded(c: FloatArray, var_max: float | FloatArray) -> FloatArray:
    """``c`` with each variance at most ``var_max`` (rows / columns scaled: stays positive definite)."""
    if isinstance(var_max, float) and c[0, 0] <= var_max and c[1, 1] <= var_max and c[2, 2] <= var_max:
        return c  # (the common case, without numpy's per-call overhead)
    d = np.diag(c)
    if np.all(d <= var_max):
        return c
    f = np.sqrt(np.minimum(1.0, np.asarray(var_max, dtype=float) / np.maximum(d, 1e-300)))
    return np.asarray(c, dtype=float) * np.outer(f, f)


@dataclass
class _Chain:
    """A slowly varying calibration variable (``Vector``): one per ``offset_interval_s``, tied by a random walk."""

    char: str
    prior_mean: FloatArray
    prior_sigma: FloatArray
    rw_sigma: FloatArray           # per sqrt(s)
    key: int | None = None
    t: float = -np.inf
    estimate: FloatArray | None = None


KERNELS = ("huber", "cauchy", "none")


@dataclass
class SmootherConfig:
    """``smoother:`` section (the defaults are here and only here; angles in degrees, see the properties)."""

    lag_s: float = setting(2.0, "smoothing window of the fixed-lag smoother", gt=0)
    encoder_sigmas: tuple[float, float, float] = setting(
        (0.01, 0.01, 0.02), "[vx m/s, vy m/s, w rad/s] twist noise when /odom carries no covariance", gt=0)
    q_slip: tuple[float, float, float] = setting(
        (1e-5, 1e-5, 1e-5), "extra spectral density on integrated twist (slip, model error)", min=0)
    odom_kernel: str = setting("huber", "robust kernel on twist factors (wheel slip)", choices=KERNELS)
    odom_kernel_k: float = setting(1.345, "its scale", gt=0)
    compass_sigma_deg: float = setting(0.5, "per reading; readings between keyframes are averaged", gt=0)
    compass_kernel: str = setting("cauchy", "robust kernel on compass factors (cauchy ignores magnetic disturbances)",
                                  choices=KERNELS)
    compass_kernel_k: float = setting(1.345, "its scale", gt=0)
    offset_interval_s: float = setting(1.0, "one compass-offset variable per interval", gt=0)
    offset_rw_sigma_deg: float = setting(0.05, "deg/sqrt(s), random walk of the compass-to-map offset", gt=0)
    offset_prior_sigma_deg: float = setting(30.0, "prior on the compass offset when it is unknown", gt=0)
    calibrated_offset_sigma_deg: float = setting(1.0, "prior on the compass offset when it is known", gt=0)
    fix_kernel: str = setting("huber", "robust kernel on scan-to-map fixes", choices=KERNELS)
    fix_kernel_k: float = setting(1.345, "its scale", gt=0)
    fix_min_sigma_xy: float = setting(0.003, "m, floor on the front-end's position sigma", min=0)
    fix_min_sigma_theta_deg: float = setting(0.1, "floor on the front-end's heading sigma", min=0)
    fix_gate: float | None = setting(None, "optional Mahalanobis (squared) gate of a fix against the prediction",
                                     gt=0)
    fix_gate_m: float | None = setting(1.0, "reject a fix this far from the prediction (null: no gate)", gt=0)
    fix_gate_theta_deg: float | None = setting(30.0, "... or this far in heading; the robust kernel does the rest",
                                               gt=0)
    max_rejections: int = setting(1000000, "fixes gated in a row before the back-end is reset to one (the "
                                  "localizer relocalizes first: pipeline.relocalize_after)", min=1)
    relinearize_threshold: float = setting(0.01, "iSAM2 relinearization threshold", gt=0)
    relinearize_skip: int = setting(1, "iSAM2 relinearize every n-th update", min=1)
    online_covariance: bool = setting(False, "marginal covariance at every keyframe; false: only when asked "
                                      "(each /fused_pose)")
    update_every: int = setting(1, "keyframes per iSAM2 update (2 halves solver time; the keyframe in between "
                                "is reported as its odometry prediction)", min=1)
    min_keyframe_dt_s: float = setting(0.005, "a scan closer than this to the previous keyframe gets none", min=0)
    max_wait_s: float = setting(0.1, "wait this long for odometry to reach a keyframe stamp", min=0)
    calibration_fixes: int = setting(3, "map fixes used to calibrate the compass offset", min=1)
    gyro: bool = setting(True, "yaw rates (IMU gyro, compass rate) as between-keyframe yaw-increment factors "
                         "with an estimated bias")
    gyro_sigma_radps: float = setting(0.02, "gyro noise per reading when the message carries none (unknown: "
                                      "a cautious 1 deg/s, as the EKF's compass_rate_sigma_deg)", gt=0)
    gyro_bias_prior_radps: float = setting(0.02, "prior sigma of a gyro's bias", gt=0)
    gyro_bias_rw_radps: float = setting(2e-5, "random walk of the gyro bias (rad/s per sqrt(s))", gt=0)
    # false by default: beside the graph is closer to robot_localization on 4 of its 5 real bags and
    # equal on the paper bench and the simulator table; the live divergence it once showed
    # (tests/live/test_end_to_end.py) was the STM32 emulator's gyro not scaled with the replay speed
    gyro_bias_in_graph: bool = setting(False, "the gyro bias as a graph variable, observed by every yaw source (the "
                                       "wheels too); false: estimated beside the graph from absolute headings "
                                       "and standstill only (health.GyroBias, as the EKF)")
    odom_gains: bool = setting(True, "estimate the odometry's speed and yaw-rate scales (reported / true) as "
                               "calibration variables")
    gyro_chord: bool = setting(True, "where a gyro covers a keyframe interval, the odometry's translation is "
                               "integrated along the gyro's heading (a skid steer's wheel yaw, which lies, does "
                               "not bend the odometry factor's chord); its yaw stays the wheels'")
    odom_speed_scale_prior: float = setting(0.2, "prior sigma of the speed scale around 1", gt=0)
    odom_yaw_scale_prior: float = setting(1.0, "prior sigma of the yaw-rate scale around 1 (a skid steer "
                                          "reports 1.4-7 times the turn)", gt=0)
    odom_scale_rw: float = setting(0.003, "random walk of the scales (per sqrt(s))", gt=0)
    slow_odom_timing: bool = setting(
        False, "an odometry slower than ~17 Hz carries its timing in the keyframe factor's yaw, (period * w)^2 "
        "at each end: better heading in turns on a fully mapped route (CARMEN fr079 / intel), but off by "
        "default: through unmapped space it let the dead-reckoned heading drift further (mit-csail)")
    odom_clock: bool = setting(True, "a slow odometry's clock offset against the scans (a driver's latency) "
                               "estimated from the fixes' yaw increments and applied to its stamps once confident "
                               "(fgloc/localization/clock.py; the localizer applies it for the smoothers, not the "
                               "EKF: its odometry run ahead of the scans made CARMEN logs worse)")
    adapt_noise: bool = setting(True, "weight the yaw sources by the noise they show against each other "
                                "(wheel, gyro, heading, fixes)")
    latency: bool = setting(True, "estimate the scan stamps' latency (a fix is the pose that long before its "
                            "stamp) from how the fixes' increments lag the gyro / odometry; corrected once "
                            "significant")
    latency_s: float | None = setting(None, "a known scan latency (s): overrides the estimate")
    relative_yaw_rw_sigma_deg: float = setting(0.057, "deg/sqrt(s), random walk of a differential orientation "
                                               "source's own offset (how fast its heading may drift from the "
                                               "graph's; the EKF's relative_yaw_q 1e-6 rad^2/s)", gt=0)

    # the angle settings in radians
    compass_sigma = radians()
    offset_rw_sigma = radians()
    offset_prior_sigma = radians()
    calibrated_offset_sigma = radians()
    fix_min_sigma_theta = radians()
    fix_gate_theta = optional_radians()
    relative_yaw_rw_sigma = radians()


@dataclass
class BatchConfig:
    """``batch:`` section: the batch smoother uses the ``smoother:`` factors, then this."""

    max_iterations: int = setting(50, "Levenberg-Marquardt iterations over the whole run", min=1)


class SlidingWindowSmoother(Backend):
    name = "smoother"
    capabilities = frozenset({Capability.ODOMETRY_CLOCK, Capability.GYRO, Capability.VELOCITY,
                              Capability.RELATIVE_YAW, Capability.ODOM_SCALES, Capability.GYRO_BIAS,
                              Capability.LATENCY})

    def __init__(self, config: SmootherConfig | None = None) -> None:
        super().__init__()
        self.cfg = config or SmootherConfig()
        self.calib = CompassCalibrator(self.cfg.calibration_fixes)
        self._q_slip = np.asarray(self.cfg.q_slip, dtype=float)
        self.next_x = 0  # key counters never restart, so keys stay unique across resets
        self.next_o = 0
        self._next_sym: dict[str, int] = {}
        self.stats.update({"compass_factors": 0, "late_scans": 0, "dropped_late": 0, "gyro_factors": 0})
        # sensor streams and what is known about each source (kept across re-initializations)
        self.gyro: dict[str, tuple[list[float], list[float], list[float]]] = {}
        self._gyro_done: dict[str, float] = {}
        self.chains: dict[str, _Chain] = {}
        # long blocks: whether the fixes' heading errors vary slowly (see _fix_weighted_cov)
        self.arb = Arbiter(long_blocks=(4, 16))
        self.latency_est = LatencyEstimator()
        self._last_fix: tuple[float, FloatArray, FloatArray] | None = None
        self._recent_fixes: deque[tuple[float, FloatArray, FloatArray]] = deque(maxlen=64)
        self._long_pair_t = -np.inf
        self._fix_pairs: list[tuple[float, float, FloatArray, FloatArray, FloatArray, FloatArray]] = []
        self._periods: dict[tuple, tuple[list[float], float]] = {}   # _period_of's memory
        self.sources: dict[str, SourceHealth] = {}
        self.gbias: dict[str, GyroBias] = {}   # per gyro stream, unless cfg.gyro_bias_in_graph
        self._gains = np.ones(2)
        self._turned = 0.0
        #: the odometry's stamps cannot be placed against the scans' (set by the localizer: a slow
        #: odometry written in bursts, which its OdometryClock cannot shift): its timing variance is
        #: used as with ``slow_odom_timing`` (see :meth:`_timing_var`)
        self.odom_timing_unknown = False
        # differential orientation sources (readings until their keyframe) and further twist sources
        self.rel_pending: list[tuple[float, float, float, str]] = []
        self._rel_gated: dict[str, int] = {}
        self.vel: dict[str, tuple[list[float], list[FloatArray], list[FloatArray]]] = {}
        self._vel_done: dict[str, float] = {}
        self._vel_translates: dict[str, bool] = {}
        self._reset_state()

    # ------------------------------------------------------------------ state
    def _reset_state(self) -> None:
        p = gtsam.ISAM2Params()
        # per variable type: the poses and offsets at the configured threshold, the calibration
        # variables at their own scale (a 0.01 s / 0.01 rad/s threshold would never relinearize them)
        th = float(self.cfg.relinearize_threshold)
        tm = gtsam.ISAM2ThresholdMap()
        for sym, v in (("x", [th] * 3), ("o", [th] * 3), ("b", [th * 1e-2]), ("g", [th * 0.1]), ("k", [th * 0.1]),
                       ("l", [th * 1e-2]), ("r", [th]),
                       ("a", [th * 0.1, th * 0.1]), (BALLAST, [th])):
            tm.insert((sym, np.asarray(v, dtype=float)))
        p.setRelinearizeThreshold(tm)
        p.relinearizeSkip = self.cfg.relinearize_skip
        p.findUnusedFactorSlots = False
        self.isam = gtsam.IncrementalFixedLagSmoother(self.cfg.lag_s, p)
        self._ballast: list[int] = []     # inert variables (see _with_ballast)
        self._ballast_t = -np.inf         # when they were last stamped, and how many there were
        self._ballast_n = 0
        self._t_latest = -np.inf          # the newest timestamp given to the smoother
        self.kf_t: list[float] = []          # keyframe times, increasing (window + history)
        self.kf_key: list[int] = []          # keys, same order
        self.kf_pose: dict[int, FloatArray] = {}   # latest estimate per key
        self.window: deque[tuple[float, int]] = deque()
        self.smoothed: dict[int, tuple[float, FloatArray]] = {}
        self.between_idx: dict[tuple[int, int], int] = {}
        self.cur_o: int | None = None
        self.cur_o_t = -np.inf
        self.odo_t: list[float] = []
        self.odo_u: list[tuple[float, float, float]] = []   # (vx, vy, w) per message
        self.odo_c: list[tuple[float, float, float, float, float, float]] = []  # covariances (upper6)
        self.compass_pending: list[tuple[float, float, float, str]] = []  # t, yaw (compass), var, source
        self.t0: float | None = None
        self._rejects = 0
        self._last_cov = np.eye(3) * 1e-2
        self._cov_stale: int | None = None
        self._init_yaw = 0.0
        self.pending_kf: list[tuple[float, PoseFix | None]] = []
        self._pred_cache: tuple | None = None
        self._int_marks: dict[float, list[float]] = {}   # _integrate's resumable states, by start
        self._acc: tuple | None = None  # factors of keyframes not yet given to iSAM2
        for ch in self.chains.values():  # calibration carries over a re-initialization as a prior
            if ch.key is not None and ch.estimate is not None:
                ch.prior_mean = ch.estimate.copy()
            ch.key, ch.t = None, -np.inf
        for src in self._gyro_done:
            self._gyro_done[src] = -np.inf
        self.rel_pending.clear()
        self._vel_done = dict.fromkeys(self._vel_done, -np.inf)

    @property
    def initialized(self) -> bool:
        return self.t0 is not None

    @property
    def encoder_sigmas(self) -> tuple[float, float, float]:
        return self.cfg.encoder_sigmas

    def set_odometry_timing_unknown(self, unknown: bool) -> None:
        self.odom_timing_unknown = bool(unknown)

    def source_health(self) -> Mapping[str, SourceHealth]:
        return self.sources

    def source_noise(self, name: str) -> SourceNoise | None:
        if name not in self.arb.streams:
            return None
        k, c = self.arb.noise(name)
        return SourceNoise(k, c, self.arb.shown_sigma(name), self.arb.claimed_sigma(name))

    def set_compass_offset(self, offset: float) -> None:
        self.calib.offset = float(offset)

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

    def _new_x(self, t: float) -> int:
        k = X(self.next_x)
        self.next_x += 1
        return k

    def _arb_add(self, name: str, kind: str, rel_prior: float, t: float, value: float, var: float) -> None:
        """One reading of source ``name`` for the arbiter (registered at its first), when noise is adapted."""
        if self.cfg.adapt_noise:
            self.arb.add_reading(name, kind, rel_prior, t, value, var)

    def _source(self, name: str, kind: str) -> SourceHealth:
        h = self.sources.get(name)
        if h is None:
            h = self.sources[name] = SourceHealth(name, kind)
        return h

    def _chain(self, name: str, char: str, mean: list[float], sigma: list[float], rw: list[float]) -> _Chain:
        ch = self.chains.get(name)
        if ch is None:
            ch = self.chains[name] = _Chain(char, np.asarray(mean, dtype=float), np.asarray(sigma, dtype=float),
                                            np.asarray(rw, dtype=float))
            ch.estimate = ch.prior_mean.copy()
        return ch

    def _chain_key(self, ch: _Chain, t: float, graph: gtsam.NonlinearFactorGraph, vals: gtsam.Values,
                   ts: dict) -> int:
        """The chain's variable for time ``t`` (a new one each ``offset_interval_s``), kept in the window."""
        if ch.key is None or t - ch.t >= self.cfg.offset_interval_s:
            n = self._next_sym.get(ch.char, 0)
            self._next_sym[ch.char] = n + 1
            new = _symbol(ch.char, n)
            est = ch.prior_mean if ch.estimate is None else ch.estimate
            if ch.key is None:
                graph.add(gtsam.PriorFactorVector(new, ch.prior_mean, gtsam.noiseModel.Diagonal.Sigmas(ch.prior_sigma)))
            else:
                dt = max(t - ch.t, 1e-3)
                graph.add(gtsam.BetweenFactorVector(ch.key, new, np.zeros(len(ch.prior_mean)),
                                                    gtsam.noiseModel.Diagonal.Sigmas(ch.rw_sigma * math.sqrt(dt))))
                ts[ch.key] = float(t)
            vals.insert(new, np.asarray(est, dtype=float))
            ch.key, ch.t = new, float(t)
        ts[ch.key] = float(t)
        return ch.key

    def _refresh_chains(self) -> None:
        """Read the calibration estimates back after a solver update."""
        for name, ch in self.chains.items():
            if ch.key is None:
                continue
            try:
                ch.estimate = np.asarray(self.isam.calculateEstimateVector(ch.key), dtype=float)
            except (RuntimeError, IndexError):
                continue
            if name in ("odom_speed_scale", "odom_yaw_scale"):
                sc = float(ch.estimate[0])
                if math.isfinite(sc) and sc > 0.05:
                    self._gains[0 if name == "odom_speed_scale" else 1] = 1.0 / sc
                    self.arb.set_correction("odom", gain=float(self._gains[1]))
            elif name.startswith("gyro_bias:"):
                self.arb.set_correction(name.split(":", 1)[1], bias=float(ch.estimate[0]))

    def latency_estimate(self) -> float:
        """The scan latency (s) in use: configured, estimated once significant, or 0."""
        if self.cfg.latency_s is not None:
            return float(self.cfg.latency_s)
        return self.latency_est.value() if self.cfg.latency else 0.0

    def latency_fit(self) -> tuple[float, float] | None:
        return latency_fit_of(self.latency_est.estimate())

    def _latency_pairs(self) -> None:
        """Feed the latency estimator with the fix pairs the gyro / odometry now cover."""
        if not self.cfg.latency or self.cfg.latency_s is not None:
            self._fix_pairs.clear()
            return
        covered = self.odo_t[-1] if self.odo_t else -np.inf
        for ts_, _, _ in self.gyro.values():
            if ts_:
                covered = min(covered, ts_[-1])
        keep = []
        odo_period = self._period_of(self.odo_t)
        last_fix = self._recent_fixes[-1][0] if self._recent_fixes else -np.inf
        yaw_period = self._period_of(next(iter(self.gyro.values()))[0] if self.gyro else self.odo_t)
        for pair in self._fix_pairs:
            ta, tb, pa, pb, ca, cb = pair
            if tb > covered or tb > last_fix - 0.25:
                keep.append(pair)
                continue
            # a reference slower than ~20 Hz cannot resolve a lag of tens of ms (the motion inside
            # one of its periods is not known): such a reference gives no pairs
            # (the odometry also de-skews the scans: slow odometry bends the fixes in turns)
            if odo_period > MAX_REF_PERIOD_S:
                continue
            yaw_ref_ok = yaw_period <= MAX_REF_PERIOD_S
            if yaw_ref_ok:
                wa, wb = self._yaw_rate_at(ta), self._yaw_rate_at(tb)
                d_ref = self._rotation_between(ta, tb)
                r = wrap_scalar(float(pb[2] - pa[2]) - d_ref)
                var = float(ca[2, 2] + cb[2, 2]) + (self.cfg.gyro_sigma_radps * (tb - ta)) ** 2
                self.latency_est.add(-(wb - wa), r, var, d_ref, 0)
            # distance pairs only ~1 s long: a consecutive pair's few cm cannot tell a lag from slip
            if tb - ta < 0.5:
                continue
            d, c = self._integrate(ta, tb)  # the reported distance: its scale error is fitted alongside
            dist_ref = float(np.hypot(d[0], d[1]))
            dist_fix = float(np.hypot(pb[0] - pa[0], pb[1] - pa[1]))
            var_d = float(ca[0, 0] + ca[1, 1] + cb[0, 0] + cb[1, 1]) / 2 + float(c[0, 0])
            va, vb = fix_speed(self._recent_fixes, ta), fix_speed(self._recent_fixes, tb)
            if va is not None and vb is not None:
                self.latency_est.add(-(vb - va), dist_fix - dist_ref, var_d, dist_ref, 1)
        self._fix_pairs = keep

    def _period_of(self, ts: list[float]) -> float:
        """:func:`_period` of a stamp list, remembered until it changes (a stamp list only grows at
        its end with later stamps, or loses its oldest: its length and last stamp tell)."""
        key = (id(ts), len(ts), ts[-1] if ts else None)
        got = self._periods.get(key)
        if got is None or got[0] is not ts:
            if len(self._periods) > 8:
                self._periods.clear()
            got = self._periods[key] = (ts, _period(ts))
        return got[1]

    def gains(self) -> FloatArray:
        """The odometry's current ``[speed, yaw-rate]`` gains (true / reported = 1 / scale)."""
        return self._gains.copy()

    def odom_scales(self) -> FloatArray:
        """The odometry's estimated ``[speed, yaw-rate]`` scales (reported / true)."""
        return 1.0 / self._gains

    def _new_offset(self, t: float, graph: gtsam.NonlinearFactorGraph, vals: gtsam.Values,
                    ts: dict) -> None:
        o = O(self.next_o)
        self.next_o += 1
        if self.cur_o is None:
            if self.calib.calibrated:
                guess, sig = float(self.calib.offset or 0.0), self.cfg.calibrated_offset_sigma
            else:
                guess, sig = self._offset_guess(), self.cfg.offset_prior_sigma
            graph.add(gtsam.PriorFactorPose2(o, offset_pose(guess), gtsam.noiseModel.Diagonal.Sigmas(
                np.array([OFFSET_XY_SIGMA, OFFSET_XY_SIGMA, sig]))))
        else:
            guess = self._offset_estimate()
            dt = max(t - self.cur_o_t, 1e-3)
            sigmas = np.array([OFFSET_XY_SIGMA, OFFSET_XY_SIGMA, self.cfg.offset_rw_sigma * np.sqrt(dt)])
            graph.add(gtsam.BetweenFactorPose2(self.cur_o, o, gtsam.Pose2(0.0, 0.0, 0.0),
                                               gtsam.noiseModel.Diagonal.Sigmas(sigmas)))
            ts[self.cur_o] = float(t)
        vals.insert(o, offset_pose(guess))
        ts[o] = float(t)
        self.cur_o, self.cur_o_t = o, float(t)

    def _offset_guess(self) -> float:
        if self.calib.offset is not None:
            return float(self.calib.offset)
        if self.calib.has_readings:
            c = self.calib.compass_at(self.t0 or 0.0)
            if c is not None:
                return float(wrap_angle(c - self._init_yaw))
        return 0.0

    def _offset_estimate(self) -> float:
        if self.cur_o is None:
            return self._offset_guess()
        if self._acc is not None and self._acc[1].exists(self.cur_o):
            return pose_offset(self._acc[1].atPose2(self.cur_o))
        try:
            return pose_offset(self.isam.calculateEstimatePose2(self.cur_o))
        except (RuntimeError, IndexError):  # not (or no longer) in the window
            return self._offset_guess()

    def compass_offset(self) -> float | None:
        """Current estimate of the compass-to-map offset (radians), None before any is known."""
        if self.cur_o is None:
            return self.calib.offset
        return self._offset_estimate()

    def _update(self, graph: gtsam.NonlinearFactorGraph, vals: gtsam.Values, ts: dict,
                remove: list[int] | None = None) -> list[int]:
        tsm = gtsam.FixedLagSmootherKeyTimestampMap()
        for k, t in ts.items():
            tsm.insert((k, t))
        if ts:
            self._capture_leaving(max(ts.values()))
            self._t_latest = max(self._t_latest, max(ts.values()))
        n = graph.size()
        graph, vals = self._with_ballast(graph, vals, tsm)
        self.isam.update(graph, vals, tsm, remove or [])
        return list(self.isam.getISAM2Result().getNewFactorsIndices())[:n]

    def _with_ballast(self, graph: gtsam.NonlinearFactorGraph, vals: gtsam.Values,
                      tsm: gtsam.FixedLagSmootherKeyTimestampMap) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values]:
        """The update's factors and values with enough inert variables in iSAM2 (``z<j>``: a
        ``Vector1`` each, under its own prior, tied to nothing, kept in the window) that its
        re-elimination stays incremental.

        iSAM2 re-eliminates in batch, relinearizing every factor of the window, whenever the
        variables an update affects reach 65 % of all it holds (GTSAM's fixed ``batchThreshold``).
        The fixed-lag marginalization marks the path from the oldest keyframe to the root at
        every update, so on a 2 s window (~35 variables) 29 % of the office log's updates went
        batch: 3 of 4 calls of the Python factors were relinearizations of factors whose
        variables had not moved, which give the cached linear factors again (a factor's
        linearization depends on its variables' linearization points only).  With at least 0.6
        inert variables per live one the affected share stays below 0.65: the same linear
        systems, solved incrementally (results equal to rounding; the inert ones never move, so
        they are never relinearized)."""
        live = self.isam.getLinearizationPoint().size() - len(self._ballast) + vals.size()
        want = int(0.6 * live) + 2
        if len(self._ballast) < want:
            graph, vals = gtsam.NonlinearFactorGraph(graph), gtsam.Values(vals)
            for _ in range(want - len(self._ballast)):
                n = self._next_sym.get(BALLAST, 0)
                self._next_sym[BALLAST] = n + 1
                k = _symbol(BALLAST, n)
                graph.add(gtsam.PriorFactorVector(k, _ZERO1, _UNIT1))
                vals.insert(k, _ZERO1)
                self._ballast.append(k)
        t = self._t_latest if math.isfinite(self._t_latest) else 0.0
        if t - self._ballast_t > 0.5 * self.cfg.lag_s or len(self._ballast) > self._ballast_n:
            # stamped anew every half lag (new ones at once): they stay in the window, never among the
            # keys the update marginalizes, and every key keeps its ordering group (GTSAM puts every
            # stamped key in group 1 whatever its stamp), so the same update as stamping them every time
            for k in self._ballast:
                tsm.insert((k, t))
            self._ballast_t, self._ballast_n = t, len(self._ballast)
        return graph, vals

    # ------------------------------------------------------------------ inputs
    def add_odometry(self, t: float, twist: FloatArray, twist_cov: FloatArray | None) -> None:
        h = self._source("odom", "odometry")
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
        for gb in self.gbias.values():
            gb.set_still(t, still)
        self.odo_t.append(t)
        self.odo_u.append((u0, u1, u2))
        if cl[0] <= TWIST_VAR_MAX and cl[4] <= TWIST_VAR_MAX and cl[8] <= TWIST_VAR_MAX:
            self.odo_c.append((cl[0], cl[1], cl[2], cl[4], cl[5], cl[8]))   # upper6(c): _bounded leaves it
        else:
            self.odo_c.append(upper6(_bounded(np.array(cl).reshape(3, 3), TWIST_VAR_MAX)))
        self._arb_add("odom", RATE, 0.05, t, u2, cl[8])
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
        h = self._source(f"{source}.yaw", "heading")
        self.calib.add_compass(t, yaw, rate)
        var = yaw_var if math.isfinite(yaw_var) and yaw_var > 0 else self.cfg.compass_sigma**2
        for gb in self.gbias.values():
            gb.add_heading(f"{source}.yaw", float(t), float(yaw), float(var) * self._noise_of(f"{source}.yaw")[0] ** 2)
        h.accepted += 1
        self._arb_add(f"{source}.yaw", ANGLE_ABSOLUTE, 0.02, float(t), float(yaw), float(var))
        self.compass_pending.append((float(t), float(yaw), float(var), source))
        self._process_pending(float(t))

    def add_gyro(self, t: float, rate: float, rate_var: float, source: str = "imu") -> None:
        """A yaw rate (rad/s, base_link z) from a gyro: integrated between keyframes, bias estimated."""
        name = f"{source}.gyro"
        h = self._source(name, "gyro")
        buf = self.gyro.get(name)
        if buf is None:
            buf = self.gyro[name] = ([], [], [])
        if buf[0] and t <= buf[0][-1]:
            h.skip("late or repeated stamp")
            return
        if not (math.isfinite(t) and math.isfinite(rate)):
            h.skip("not finite")
            return
        var = rate_var if math.isfinite(rate_var) and rate_var > 0 else self.cfg.gyro_sigma_radps**2
        h.accepted += 1
        if not self.cfg.gyro_bias_in_graph:
            gb = self.gbias.get(name)
            if gb is None:
                gb = self.gbias[name] = GyroBias(self.cfg.gyro_bias_prior_radps, self.cfg.gyro_bias_rw_radps)
            gb.add_rate(float(t), float(rate), float(var))
            self.arb.set_correction(name, bias=gb.value())
        buf[0].append(float(t))
        buf[1].append(float(rate))
        buf[2].append(float(var))
        self._gyro_done.setdefault(name, -np.inf)
        self._arb_add(name, INSTANT_RATE, 0.01, float(t), float(rate), float(var))
        if len(buf[0]) > 8192 and self.kf_t:
            horizon = self.kf_t[-1] - self.cfg.lag_s - 2.0
            i = bisect_left(buf[0], horizon)
            if i > 0:
                del buf[0][:i], buf[1][:i], buf[2][:i]

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
        it is once keyframes come faster than readings (paper run: 25 Hz scans, 20 Hz gyro), and
        the gyro's random walk wobbled the heading.  With the shares the factors of consecutive
        intervals add up to the exact variance of the gyro's integral over them.  ``want_var=False``:
        the variance is not computed (returned as 0)."""
        got = self.gyro.get(name)   # (no default: .get's would build three lists at every call)
        if got is None:
            return None
        ts, rs, vs = got
        if not ts or ts[-1] < t1 - 1e-9 or ts[0] > t0 + 1e-9:
            return None
        n = len(ts)
        w: dict[int, float] = {}
        d = _rate_integral(ts, rs, t0, t1, max(bisect_right(ts, t0) - 1, 0), max_gap, w if want_var else None)
        if d is None:
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
            var += vs[m] * ww * max(0.5 * (min(before, max_gap) + min(after, max_gap)), ww)
        return d - self.gyro_bias_of(name) * (t1 - t0), var

    def _gyro_rate_at(self, t: float) -> float | None:
        """The first gyro's bias-corrected rate at ``t`` (interpolated), or None."""
        for name, (ts, rs, _) in self.gyro.items():
            if ts and ts[0] <= t <= ts[-1]:
                i = min(max(bisect_left(ts, t), 1), len(ts) - 1)
                ta, tb = ts[i - 1], ts[i]
                f = (t - ta) / (tb - ta) if tb > ta else 1.0
                return rs[i - 1] + f * (rs[i] - rs[i - 1]) - self.gyro_bias_of(name)
        return None

    def _integrate(self, t0: float, t1: float) -> tuple[FloatArray, FloatArray]:
        if not self.odo_t:
            return np.zeros(3), np.diag(np.square(self.cfg.encoder_sigmas)) * max(t1 - t0, 1e-3) ** 2
        # only the samples that cover (t0, t1]: from the last one <= t0 to the first one >= t1
        i0 = max(bisect_right(self.odo_t, t0) - 1, 0)
        i1 = min(bisect_left(self.odo_t, t1) + 1, len(self.odo_t))
        # the predictions integrate from the newest keyframe again and again (~4 times per keyframe,
        # to later and later stamps): each resumes from the last one's completed steps
        mark = self._int_marks.get(t0)
        if mark is None:
            if len(self._int_marks) >= 4:
                del self._int_marks[next(iter(self._int_marks))]
            mark = self._int_marks[t0] = []
        return integrate_twist_lists(self.odo_t, self.odo_u, self.odo_c, i0, i1, t0, t1, self._q_slip, mark)

    def _chord_along_gyro(self, t0: float, t1: float) -> FloatArray | None:
        """The odometry's translation over ``(t0, t1]`` integrated along the first gyro's
        (bias-corrected) heading, ``[x, y, gyro yaw]`` in the frame at ``t0``; None when no gyro
        covers the interval (each odometry twist held backwards, as :func:`integrate_twist`)."""
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
        ts = self.odo_t
        n = len(ts)
        i = bisect_right(ts, t0)
        g = max(bisect_right(gts, t0) - 1, 0)   # the gyro reading at or before the step's start
        t, x, y, th = t0, 0.0, 0.0, 0.0
        while t < t1 - 1e-12:
            j = min(i, n - 1)
            tn = min(ts[i], t1) if i < n else t1
            dt = tn - t
            if dt > 0:
                # _gyro_increment(name, t, tn, want_var=False) for this step, the gyro index carried
                # from step to step instead of searched
                while g + 1 < ng and gts[g + 1] <= t:
                    g += 1
                d = _rate_integral(gts, grs, t, tn, g, max_gap)
                if d is None:
                    return None
                w = d - bias * (tn - t)
                u = self.odo_u[j]
                vx, vy = float(u[0]) * dt, float(u[1]) * dt
                a, b = exp_coefficients(w)
                dx, dy = a * vx - b * vy, b * vx + a * vy
                c, s_ = math.cos(th), math.sin(th)
                x, y, th = x + c * dx - s_ * dy, y + s_ * dx + c * dy, th + w
            t = tn
            i += 1
        return np.array([x, y, wrap_scalar(th)])

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
        if not self.odo_t:
            return 0.0
        i0 = max(bisect_right(self.odo_t, a) - 1, 0)
        i1 = min(bisect_left(self.odo_t, b) + 1, len(self.odo_t))
        th = integrate_heading(np.asarray(self.odo_t[i0:i1]), np.asarray(self.odo_u[i0:i1]), a, b)
        th *= float(self._gains[1])
        return th if t1 > t0 else -th

    def predict(self, t: float) -> tuple[FloatArray, FloatArray]:
        assert self.kf_key, "smoother not initialized"
        k = self.kf_key[-1]
        key = (k, float(t), len(self.odo_t))
        if self._pred_cache is not None and self._pred_cache[0] == key:
            return self._pred_cache[1], self._pred_cache[2]
        d, c = self._integrate(self.kf_t[-1], t)
        d = self._corrected(d, self.kf_t[-1], t)
        p0 = self.kf_pose[k]
        pose = compose1(p0, d)
        cov = carried_covariance(self._last_cov, p0, pose, c)
        self._pred_cache = (key, pose, cov)
        return pose, cov

    def motion_correction(self, t0: float, t1: float, delta: FloatArray) -> FloatArray:
        """The odometry increment with the estimated gains and the gyro's rotation where it covers it."""
        if t1 <= t0:
            return delta
        return self._corrected(np.asarray(delta, dtype=float), t0, t1)

    def _corrected(self, d: FloatArray, t0: float, t1: float) -> FloatArray:
        """An odometry increment with the current gains (and the gyro's rotation when it covers it)."""
        if not self.gyro and abs(self._gains[0] - 1.0) <= 1e-8 and abs(self._gains[1] - 1.0) <= 1e-8:
            return d
        for name in self.gyro:  # the first gyro that covers the interval turns it
            r = self._gyro_increment(name, t0, t1, want_var=False)
            if r is not None and abs(d[2]) > 1e-9:
                return scaled_delta(d, (float(self._gains[0]), r[0] / d[2]), jacobian=False)[0]
            if r is not None:
                out = scaled_delta(d, self._gains, jacobian=False)[0]
                out[2] = r[0]
                return out
        return scaled_delta(d, self._gains, jacobian=False)[0]

    def _gate(self, fix: PoseFix, pred: FloatArray, pred_cov: FloatArray) -> bool:
        e = fix.pose - pred
        e[2] = wrap_scalar(float(e[2]))
        if self.cfg.fix_gate_m is not None and float(np.hypot(e[0], e[1])) > self.cfg.fix_gate_m:
            return False
        if self.cfg.fix_gate_theta is not None and abs(float(e[2])) > self.cfg.fix_gate_theta:
            return False
        if self.cfg.fix_gate is None:
            return True
        S = pred_cov + fix.cov
        try:
            d2 = float(e @ np.linalg.solve(S, e))
        except np.linalg.LinAlgError:
            return False
        return bool(np.isfinite(d2) and d2 <= self.cfg.fix_gate)

    def _fix_weighted_cov(self, cov: FloatArray) -> FloatArray:
        """A fix's covariance as its factor uses it: floored (:meth:`_fix_cov`), its heading
        weighted by the noise the fixes' headings show against the other yaw sources (the arbiter's
        :meth:`~fgloc.backends.health.Arbiter.shown_k`: over 0.125 s blocks and, for slowly varying
        errors, over 0.5 s and 2 s blocks).  Without it, a front-end whose headings are 5-10x better
        than the floor left the heading to the relative sources between fixes over a long window: the
        paper run's smoother heading took on the gyro's random walk and the wheels' drift on
        straight legs (online 0.032 deg against its fixes' 0.024)."""
        a = self._fix_cov_list(cov)
        if self.cfg.adapt_noise:
            k = self.arb.shown_k("scan")
            if k != 1.0:  # the heading's row, then its column, times k
                a[6], a[7], a[8] = a[6] * k, a[7] * k, a[8] * k
                a[2], a[5], a[8] = a[2] * k, a[5] * k, a[8] * k
        return np.array(a).reshape(3, 3)

    def _fix_cov(self, cov: FloatArray) -> FloatArray:
        return np.array(self._fix_cov_list(cov)).reshape(3, 3)

    def _fix_cov_list(self, cov: FloatArray) -> list[float]:
        """A fix's covariance with its floors, row by row as 9 floats (scalar maths: once per keyframe)."""
        a = np.asarray(cov, dtype=float).reshape(9).tolist()
        a[0] = max(a[0], self.cfg.fix_min_sigma_xy**2)
        a[4] = max(a[4], self.cfg.fix_min_sigma_xy**2)
        a[8] = max(a[8], self.cfg.fix_min_sigma_theta**2)
        return a

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

    # ------------------------------------------------------------------ keyframes
    def add_keyframe(self, t: float, fix: PoseFix | None) -> bool:
        """Queue a keyframe; it is added once odometry up to ``t`` has arrived (or ``max_wait`` passed).

        Returns True if the fix passed the gate against the prediction.
        """
        if not self.initialized or not math.isfinite(float(t)):
            return False
        t = float(t)
        if fix is not None and not _all_finite(fix.pose, fix.cov):
            self._source("scan", "pose").skip("fix not finite")
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
            if not (have_odo or now - t >= self.cfg.max_wait_s):
                return
            t, fix = self.pending_kf.pop(0)
            self._add_keyframe_now(t, fix)

    def _gyros_cover(self, t: float) -> bool:
        """Every gyro still reading (one within :data:`GYRO_LIVE_S` of ``t``) has reached ``t``, so
        the keyframe's chord can run along its heading.  A keyframe made before (its gyro reading
        arriving after the odometry's) kept the wheels' own arc, bent by their yaw: on r_l's
        Jackal bag, IMU and wheels both at 50 Hz, 75 % of the keyframes, with wheels that report
        4.7 times the turn, drove the smoother's path 1.0 deg crabwise."""
        if not self.cfg.gyro_chord:
            return True
        for ts_, _, _ in self.gyro.values():
            if ts_ and t - GYRO_LIVE_S <= ts_[-1] < t - 1e-9:
                return False
        return True

    def _add_keyframe_now(self, t: float, fix: PoseFix | None) -> None:
        used = fix is not None
        k_prev, t_prev = self.kf_key[-1], self.kf_t[-1]
        k = self._new_x(t)
        if self._acc is None:
            self._acc = (gtsam.NonlinearFactorGraph(), gtsam.Values(), {}, [], [])
        graph, vals, ts, pairs, keys = self._acc
        ts[k] = t
        d, c = self._integrate(t_prev, t)
        chord = self._chord_along_gyro(t_prev, t) if self.cfg.gyro_chord else None
        if chord is None:
            pred = compose1(self.kf_pose[k_prev], self._corrected(d, t_prev, t))
        else:  # the translation along the gyro's heading, the gyro's rotation; the wheels' yaw in the factor
            pred = compose1(self.kf_pose[k_prev], np.array([chord[0] * self._gains[0], chord[1] * self._gains[0],
                                                            chord[2]]))
            d = np.array([chord[0], chord[1], d[2]])
        graph.add(self._odometry_factor(k_prev, k, d, c, t, graph, vals, ts, bend=chord is None))
        pairs.append(((k_prev, k), graph.size() - 1))
        # initial value: the odometry prediction, so robust weights start from a consistent point
        vals.insert(k, gtsam.Pose2(*pred))
        if t - self.cur_o_t >= self.cfg.offset_interval_s:
            self._new_offset(t, graph, vals, ts)
        # compass readings since the previous keyframe (late ones go to this keyframe too)
        readings = [r for r in self.compass_pending if r[0] <= t + 1e-9]
        self.compass_pending = [r for r in self.compass_pending if r[0] > t + 1e-9]
        m = self._compass_measurement(t, readings)
        if m is not None:
            sigma = m[1]
            if self.cfg.adapt_noise and readings:
                sigma *= self._noise_of(f"{readings[0][3]}.yaw")[0]
            graph.add(compass_factor(k, self.cur_o, m[0], sigma,  # type: ignore[arg-type]
                                     self.cfg.compass_kernel, self.cfg.compass_kernel_k))
            ts[self.cur_o] = t  # type: ignore[index]
            self.stats["compass_factors"] += 1
        self._add_relative_yaw_factors(k, t, pred, graph, vals, ts)
        if used:
            assert fix is not None
            graph.add(self._fix_factor(k, t, fix, graph, vals, ts))
            self.stats["fixes_used"] += 1
            self._source("scan", "pose").accepted += 1
            lat = self.latency_estimate()
            yaw_fix = float(fix.pose[2])
            self.calib.add_fix(t - lat, yaw_fix)
            var_yaw = self._fix_cov_list(fix.cov)[8]
            for gb in self.gbias.values():
                gb.add_heading("scan", t - lat, yaw_fix, var_yaw)
            self._arb_add("scan", ANGLE_ABSOLUTE, 0.005, t - lat, yaw_fix, var_yaw)
        self.kf_t.append(t)
        self.kf_key.append(k)
        self.window.append((t, k))
        self.kf_pose[k] = pred
        keys.append(k)
        self._add_gyro_factors(t, graph, vals, ts)
        self._add_velocity_factors(t, graph, vals, ts)
        if self.cfg.adapt_noise:
            self.arb.update(t)
        self._latency_pairs()
        if len(keys) >= max(1, int(self.cfg.update_every)):
            self._flush_acc()
        else:  # online estimate until the next solver update: the odometry prediction
            self.stats["keyframes"] += 1
            self._record_online(t, pred, carried_covariance(self._last_cov, self.kf_pose[k_prev], pred, c))

    def _noise_of(self, name: str) -> tuple[float, float]:
        return self.arb.noise(name) if self.cfg.adapt_noise else (1.0, 0.0)

    def _odometry_factor(self, ki: int, kj: int, d: FloatArray, c: FloatArray, t: float,
                         graph: gtsam.NonlinearFactorGraph, vals: gtsam.Values, ts: dict,
                         bend: bool = True) -> gtsam.NonlinearFactor:
        """The integrated-odometry factor: yaw noise as the odometry showed it, gains estimated
        (``bend=False``: ``d``'s translation was integrated along the gyro's heading)."""
        # the yaw row and column times k_yaw, the yaw variance plus (rel * yaw)^2 and the timing's: as
        # floats (the same operations as on the array), one array made at the end
        a = np.asarray(c, dtype=float).reshape(9).tolist()
        k_yaw, rel = self._noise_of("odom")
        if k_yaw != 1.0 or rel > 0.0:
            a[6], a[7], a[8] = a[6] * k_yaw, a[7] * k_yaw, a[8] * k_yaw
            a[2], a[5], a[8] = a[2] * k_yaw, a[5] * k_yaw, a[8] * k_yaw
            a[8] += (rel * float(d[2])) ** 2
        a[8] += self._timing_var(self.kf_t[-1], t)
        c = np.array(a).reshape(3, 3)
        if not self.cfg.odom_gains:
            return between_factor(ki, kj, d, c, kernel=self.cfg.odom_kernel, k=self.cfg.odom_kernel_k)
        # a scale is estimated only once something else observes it (held at its estimate until
        # then): the speed scale from positions (fixes), the yaw-rate scale from any other yaw source
        ks_v = ks_w = None
        latency_known = not self.cfg.latency or self.cfg.latency_s is not None or self.latency_est.settled()
        if (self.stats["fixes_used"] > 0 and latency_known) or "odom_speed_scale" in self.chains:
            ch = self._chain("odom_speed_scale", "g", [1.0], [self.cfg.odom_speed_scale_prior],
                             [self.cfg.odom_scale_rw])
            ks_v = self._chain_key(ch, t, graph, vals, ts)
        self._turned += abs(float(d[2]))
        if (self._turned > 1.0 and (self.gyro or self.calib.has_readings or self.stats["fixes_used"] > 0)) \
                or "odom_yaw_scale" in self.chains:
            # observable once the robot has turned (a radian) with another yaw source to compare;
            # 0.1 rad (3218db0) let a barely observable scale add noise: the paper run replayed from
            # a live recording went 7.1 -> 8.2 mm online RMSE (tests/live/test_end_to_end.py flaked)
            ch = self._chain("odom_yaw_scale", "k", [1.0], [self.cfg.odom_yaw_scale_prior], [self.cfg.odom_scale_rw])
            ks_w = self._chain_key(ch, t, graph, vals, ts)
        fixed = (1.0 / float(self._gains[0]), 1.0 / float(self._gains[1]))
        return scaled_between_factor(ki, kj, ks_v, ks_w, d, c, fixed, kernel=self.cfg.odom_kernel,
                                     k=self.cfg.odom_kernel_k, bend=bend)

    def _timing_var(self, t0: float, t1: float) -> float:
        """Yaw variance (rad^2) of a keyframe interval's odometry increment from where in time the odometry
        places the motion, when it is too slow to place it (mean message period over its last
        ``TIMING_MESSAGES`` messages above :data:`MAX_REF_PERIOD_S`: the latency estimator takes no pairs from
        it either): its pose at each keyframe stamp, against the scan's, is known to about one period, so
        ``(period * w)^2`` at each end, ``w`` the yaw rate there.  Not modelled, a scan stamped off its
        odometry (CARMEN: 80-120 ms on fr079 / aces, intel's bursts) gave two consecutive increments
        +-5-13 deg off in turns where they claimed 0.3-1.4 deg, and they outvoted the keyframe's fix."""
        n = min(len(self.odo_t), TIMING_MESSAGES)
        if not (self.cfg.slow_odom_timing or self.odom_timing_unknown) or n < 3:
            return 0.0
        per = (self.odo_t[-1] - self.odo_t[-n]) / (n - 1)
        if not per > MAX_REF_PERIOD_S:
            return 0.0
        wa, wb = self._yaw_rate_at(t0), self._yaw_rate_at(t1)
        return per * per * (wa * wa + wb * wb)

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

    def _fix_factor(self, k: int, t: float, fix: PoseFix, graph: gtsam.NonlinearFactorGraph,
                    vals: gtsam.Values, ts: dict) -> gtsam.NonlinearFactor:
        """The scan-to-map fix on keyframe ``k`` (at the scan stamp): with its latency estimated,
        configured, or none."""
        cov = self._fix_weighted_cov(fix.cov)
        pose = np.asarray(fix.pose, dtype=float)
        # a fix stamped late is the pose that long before its stamp: carried forward by the motion
        lat = self.latency_estimate()
        if lat != 0.0:
            pose = compose1(pose, se2_exp(self._twist_at(t) * lat))
        # pairs for the latency estimate: consecutive fixes (turns starting / ending) and, once a
        # second, fixes ~1 s apart (a start from standstill: the lag is v * latency)
        p_now = np.asarray(fix.pose, dtype=float)
        if self._last_fix is not None and 0.0 < t - self._last_fix[0] <= 0.3:
            self._fix_pairs.append((self._last_fix[0], t, self._last_fix[1], p_now, self._last_fix[2], cov))
        if t - self._long_pair_t >= 1.0:
            old = [f for f in self._recent_fixes if 0.8 <= t - f[0] <= 1.2]
            if old:
                f0 = old[0]
                self._fix_pairs.append((f0[0], t, f0[1], p_now, f0[2], cov))
                self._long_pair_t = t
        self._last_fix = (t, p_now, cov)
        self._recent_fixes.append(self._last_fix)
        return fix_factor(k, pose, cov, self.cfg.fix_kernel, self.cfg.fix_kernel_k)

    def _covered_intervals(self, t_now: float, done: float,
                           last_t: float) -> Iterator[tuple[float, float, int, int]]:
        """The keyframe intervals ``(ta, tb, ka, kb)`` a source's readings up to ``last_t`` now cover and
        that have no factor of it yet: starting at a keyframe >= ``done`` (the end of its last interval)
        and inside the window (never on a keyframe about to be marginalized)."""
        horizon = t_now - self.cfg.lag_s + 0.25
        i = max(bisect_right(self.kf_t, max(done, horizon) - 1e-9), 1)
        while i < len(self.kf_t):
            ta, tb = self.kf_t[i - 1], self.kf_t[i]
            if tb > last_t + 1e-9:
                return
            ka, kb = self.kf_key[i - 1], self.kf_key[i]
            i += 1
            if ta < done - 1e-9 or ta < horizon or ka not in self.kf_pose or kb not in self.kf_pose:
                continue
            yield ta, tb, ka, kb

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
                k_g, rel = self._noise_of(name)
                var = k_g * k_g * (r[1] + 1e-10 * (tb - ta)) + (rel * r[0]) ** 2
                gb = self.gbias.get(name)
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

    # ------------------------------------------------------------------ differential orientations, further twists
    def add_relative_yaw(self, t: float, yaw: float, var: float, source: str = "imu") -> None:
        """An orientation whose increments are used, not its frame (robot_localization's
        ``imuN_differential``): at each keyframe the readings since the previous one, carried to
        its stamp by the rotation in between and averaged, are a heading factor ``z = theta + c``
        (:func:`~fgloc.backends.factors.relative_yaw_factor`) on the source's own offset chain ``c``
        (``r<j>``: anchored at the first reading with a loose prior, a random walk of
        ``relative_yaw_rw_sigma_deg``), as the compass's ``o<j>``.

        Not as the rate ``d_yaw / d_t`` between stamps: with jittered stamps (two messages 0.2 ms
        apart) that rate spikes to several rad/s; as a heading the increments enter whole, whatever
        the stamps.  A reading beyond ``fix_gate_theta`` of the graph's heading plus the offset is
        not used; :data:`REANCHOR_AFTER` keyframes of it in a row (a re-initialized AHRS) and the
        offset is anchored again."""
        name = f"{source}.yaw"
        h = self._source(name, "heading")
        if not (math.isfinite(t) and math.isfinite(yaw)):
            h.skip("not finite")
            return
        v = var if math.isfinite(var) and var > 0 else self.cfg.compass_sigma**2
        self._arb_add(name, ANGLE_ABSOLUTE, 0.02, float(t), float(yaw), float(v))
        for gb in self.gbias.values():  # its increments observe a gyro's bias (its frame never enters)
            gb.add_heading(name, float(t), float(yaw), float(v) * self._noise_of(name)[0] ** 2)
        if not self.initialized:
            return
        self.rel_pending.append((float(t), float(yaw), float(v), source))
        self._process_pending(float(t))

    def _add_relative_yaw_factors(self, k: int, t: float, pred: FloatArray, graph: gtsam.NonlinearFactorGraph,
                                  vals: gtsam.Values, ts: dict) -> None:
        """Keyframe ``k``'s heading factor of each differential orientation source with readings
        up to ``t`` (``pred``: the keyframe's initial value)."""
        if not self.rel_pending:
            return
        now = [r for r in self.rel_pending if r[0] <= t + 1e-9]
        self.rel_pending = [r for r in self.rel_pending if r[0] > t + 1e-9]
        horizon = t - self.cfg.lag_s
        for source in dict.fromkeys(r[3] for r in now):
            readings = [r for r in now if r[3] == source and r[0] >= horizon]
            m = self._compass_measurement(t, readings)
            if m is None:
                continue
            z, sigma = m
            name = f"{source}.yaw"
            h = self._source(name, "heading")
            sigma *= self._noise_of(name)[0]
            ch = self._chain(f"relative_yaw:{source}", "r", [0.0], [RELATIVE_YAW_PRIOR_SIGMA],
                             [self.cfg.relative_yaw_rw_sigma])
            gate = self.cfg.fix_gate_theta
            if ch.key is not None and ch.estimate is not None and gate is not None:
                e = wrap_scalar(float(pred[2]) + float(ch.estimate[0]) - z)
                if abs(e) > gate:
                    h.gated += len(readings)
                    n = self._rel_gated[source] = self._rel_gated.get(source, 0) + 1
                    if n < REANCHOR_AFTER:
                        continue
                    self.stats["relative_yaw_reanchored"] = self.stats.get("relative_yaw_reanchored", 0) + 1
                    ch.key = None
            if ch.key is None:  # anchored here: c = z - theta (the source's frame is its own)
                ch.prior_mean = np.array([wrap_scalar(z - float(pred[2]))])
                ch.estimate = ch.prior_mean.copy()
            self._rel_gated[source] = 0
            kc = self._chain_key(ch, t, graph, vals, ts)
            graph.add(relative_yaw_factor(k, kc, z, sigma, "huber", self.cfg.compass_kernel_k))
            h.accepted += len(readings)
            self.stats["relative_yaw_factors"] = self.stats.get("relative_yaw_factors", 0) + 1

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
        h = self._source(source, "odometry")
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
            self._arb_add(source, RATE, 0.05, float(t), float(tw[2]), float(c[2, 2]))
        buf[0].append(float(t))
        buf[1].append(tw)
        buf[2].append(_bounded(c, TWIST_VAR_MAX))
        self._vel_done.setdefault(source, -np.inf)
        self._vel_translates[source] = bool(used[0] or used[1])
        h.accepted += 1
        if len(buf[0]) > 4096 and self.kf_t:
            i = bisect_left(buf[0], self.kf_t[-1] - self.cfg.lag_s - 2.0)
            if i > 0:
                del buf[0][:i], buf[1][:i], buf[2][:i]

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
        k_yaw, rel = self._noise_of(name)
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
        c1 = _bounded(np.asarray(c1, dtype=float), TWIST_VAR_MAX)
        for g in self.gyro:  # the keyframes' turn is the gyro's where it covers them: its uncertainty
            r = self._gyro_increment(g, ta, tb)
            if r is not None:
                gb = self.gbias.get(g)
                c1 = c1.copy()
                c1[2, :2] = c1[:2, 2] = 0.0
                c1[2, 2] = r[1] + ((gb.sigma() if gb is not None else 0.0) * (tb - ta)) ** 2
                break
        S = c + c1 + np.eye(3) * 1e-8
        try:
            d2 = float(e @ np.linalg.solve(S, e))
        except np.linalg.LinAlgError:
            d2 = math.inf
        h = self._source(name, "odometry")
        if not d2 <= CHI2_3_999:
            h.gated += 1
            return None
        if ch is None:
            return between_factor(ka, kb, d, c, kernel=self.cfg.odom_kernel, k=self.cfg.odom_kernel_k)
        kab = self._chain_key(ch, tb, graph, vals, ts)
        return aligned_between_factor(ka, kb, kab, d, c, kernel=self.cfg.odom_kernel, k=self.cfg.odom_kernel_k)

    def gyro_bias(self, source: str = "imu") -> float:
        """The estimated bias (rad/s) of ``source``'s gyro (0 before it is estimated)."""
        return self.gyro_bias_of(f"{source}.gyro")

    def gyro_bias_of(self, name: str) -> float:
        """The estimated bias (rad/s) of the gyro stream ``name`` (``SOURCE.gyro``)."""
        gb = self.gbias.get(name)
        if gb is not None:
            return gb.value()
        ch = self.chains.get(f"gyro_bias:{name}")
        return float(ch.estimate[0]) if ch is not None and ch.estimate is not None else 0.0

    def _flush_acc(self) -> None:
        """Hand the accumulated keyframes' factors to iSAM2 (one update)."""
        if self._acc is None:
            return
        graph, vals, ts, pairs, keys = self._acc
        self._acc = None
        self._register(graph, vals, ts)
        try:
            idx = self._update(graph, vals, ts)
        except RuntimeError:
            self._restart_after_failure(keys)
            return
        for pair, pos in pairs:
            self.between_idx[pair] = idx[pos]
        self._refresh_chains()
        for kk in keys[:-1]:
            p = self.isam.calculateEstimatePose2(kk)
            self.kf_pose[kk] = np.array([p.x(), p.y(), p.theta()])
        self._after_keyframe(self.kf_t[-1])

    def _restart_after_failure(self, drop: list[int]) -> None:
        """GTSAM found the system ill-conditioned (e.g. ``Indeterminate linear system`` on degenerate
        input): counted, and the smoother restarts at the newest keyframe's prediction with the
        last marginal as its prior (bounded, :data:`RESTART_VAR_MAX`); the keyframes in ``drop``
        (not solved) leave the window."""
        self.stats["solver_failures"] = self.stats.get("solver_failures", 0) + 1
        t_last, k_last = self.kf_t[-1], self.kf_key[-1]
        pose = self.kf_pose.get(k_last)
        if pose is None or not np.all(np.isfinite(pose)):
            pose = next((p for _, p in sorted(self.smoothed.values(), key=lambda v: -v[0])
                         if np.all(np.isfinite(p))), np.zeros(3))
        self.window = deque(w for w in self.window if w[1] not in drop)
        self.initialize(t_last, np.array(pose, dtype=float), np.diag(np.minimum(
            np.abs(np.diag(self._last_cov)), RESTART_VAR_MAX)))

    def _register(self, graph: gtsam.NonlinearFactorGraph, vals: gtsam.Values, ts: dict) -> None:
        """Hook for the batch smoother (keeps a copy of every factor)."""

    def _after_keyframe(self, t: float) -> None:
        k = self.kf_key[-1]
        pose = self.isam.calculateEstimatePose2(k)
        self.kf_pose[k] = np.array([pose.x(), pose.y(), pose.theta()])
        self._cov_stale = k
        if self.cfg.online_covariance:
            self._update_covariance()
        self.stats["keyframes"] += 1
        self._record_online(t, self.kf_pose[k], self._last_cov)

    def _capture_leaving(self, t_new: float) -> None:
        """Record the keyframes the next update will marginalize (their final smoothed value)."""
        horizon = t_new - self.cfg.lag_s + 1e-6
        while self.window and self.window[0][0] < horizon:
            tk, kk = self.window.popleft()
            try:
                p = self.isam.calculateEstimatePose2(kk)
                self.smoothed[kk] = (tk, np.array([p.x(), p.y(), p.theta()]))
            except (RuntimeError, IndexError):
                if kk in self.kf_pose:
                    self.smoothed[kk] = (tk, self.kf_pose[kk].copy())
            self.kf_pose.pop(kk, None)

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

    def _remove_registered(self, isam_index: int) -> None:
        """Hook for the batch smoother."""

    def _update_covariance(self) -> None:
        """Marginal covariance of the newest solved keyframe, rotated into the map frame."""
        k = self._cov_stale
        if k is None or k not in self.kf_pose:
            return
        self._cov_stale = None
        self._pred_cache = None
        try:
            body = np.asarray(self.isam.marginalCovariance(k))
        except (RuntimeError, IndexError):
            return
        c, s_ = math.cos(self.kf_pose[k][2]), math.sin(self.kf_pose[k][2])
        R = np.array([[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]])
        self._last_cov = R @ body @ R.T

    def current(self, covariance: bool = True) -> tuple[float, FloatArray, FloatArray] | None:
        """Newest keyframe estimate; its covariance is computed here on demand (iSAM2 marginal;
        ``covariance=False``: the last one computed)."""
        if not self.kf_key:
            return None
        if covariance:
            self._update_covariance()
        return self.kf_t[-1], self.kf_pose[self.kf_key[-1]].copy(), self._last_cov.copy()

    def _flush_window(self) -> None:
        for tk, kk in self.window:
            try:
                p = self.isam.calculateEstimatePose2(kk)
            except (RuntimeError, IndexError):
                continue
            self.smoothed[kk] = (tk, np.array([p.x(), p.y(), p.theta()]))
        self.window.clear()

    def finish(self) -> Trajectory:
        self._process_pending(np.inf)
        self._flush_acc()
        self._velocity_tail()
        self._flush_window()
        if not self.smoothed:
            return Trajectory(np.zeros(0), np.zeros((0, 3)))
        items = sorted(self.smoothed.values(), key=lambda v: v[0])
        return Trajectory.from_unsorted(np.array([v[0] for v in items]), np.array([v[1] for v in items]))


class BatchSmoother(SlidingWindowSmoother):
    """All factors of the run, optimized at :meth:`finish` by Levenberg-Marquardt."""

    name = "batch"

    def __init__(self, config: SmootherConfig | None = None, batch: BatchConfig | None = None) -> None:
        self.max_iterations = (batch or BatchConfig()).max_iterations
        self.all_graph: list[gtsam.NonlinearFactor | None] = []
        self.isam_to_all: dict[int, int] = {}
        self.key_t: dict[int, float] = {}
        self.init_vals = gtsam.Values()
        self._pending_register: list[int] = []
        super().__init__(config)

    def initialize(self, t: float, pose: FloatArray, cov: FloatArray | None = None) -> None:
        super().initialize(t, pose, cov)
        # the prior / offset of (re)initialization go into the batch graph too
        g = self.isam.getFactors()
        ballast = set(self._ballast)
        for i in range(g.size()):
            f = g.at(i)
            if f is not None and not ballast.intersection(f.keys()):
                self.all_graph.append(f)
        for key in self.isam.getLinearizationPoint().keys():
            if key not in ballast and not self.init_vals.exists(key):
                self.key_t[key] = t
                c = gtsam.Symbol(key).chr()
                if c == ord("x"):
                    self.init_vals.insert(key, self.isam.calculateEstimatePose2(key))
                elif c == ord("o"):
                    self.init_vals.insert(key, self.isam.calculateEstimatePose2(key))
                else:
                    self.init_vals.insert(key, self.isam.calculateEstimateVector(key))

    def _register(self, graph: gtsam.NonlinearFactorGraph, vals: gtsam.Values, ts: dict) -> None:
        self._pending_register = []
        for i in range(graph.size()):
            self._pending_register.append(len(self.all_graph))
            self.all_graph.append(graph.at(i))
        for key in vals.keys():
            c = gtsam.Symbol(key).chr()
            if c == ord("x"):
                self.init_vals.insert(key, vals.atPose2(key))
            elif c == ord("o"):
                self.init_vals.insert(key, vals.atPose2(key))
            else:
                self.init_vals.insert(key, vals.atVector(key))
            self.key_t[key] = ts.get(key, 0.0)

    def _update(self, graph: gtsam.NonlinearFactorGraph, vals: gtsam.Values, ts: dict,
                remove: list[int] | None = None) -> list[int]:
        idx = super()._update(graph, vals, ts, remove)
        if self._pending_register and len(self._pending_register) == len(idx):
            for a, b in zip(idx, self._pending_register, strict=True):
                self.isam_to_all[a] = b
        self._pending_register = []
        return idx

    def _remove_registered(self, isam_index: int) -> None:
        j = self.isam_to_all.get(isam_index)
        if j is not None:
            self.all_graph[j] = None

    def _after_keyframe(self, t: float) -> None:
        super()._after_keyframe(t)
        # refresh the initial guess with the fixed-lag estimate as keyframes leave the window
        for kk, (_, p) in list(self.smoothed.items())[-4:]:
            if self.init_vals.exists(kk):
                self.init_vals.update(kk, gtsam.Pose2(*p))

    def finish(self) -> Trajectory:
        fl = super().finish()
        for kk, (_, p) in self.smoothed.items():
            if self.init_vals.exists(kk):
                self.init_vals.update(kk, gtsam.Pose2(*p))
        graph = gtsam.NonlinearFactorGraph()
        for f in self.all_graph:
            if f is not None:
                graph.add(f)
        if graph.size() == 0:
            return fl
        params = gtsam.LevenbergMarquardtParams()
        params.setMaxIterations(self.max_iterations)
        try:
            result = gtsam.LevenbergMarquardtOptimizer(graph, self.init_vals, params).optimize()
        except RuntimeError:
            self.stats["batch_failed"] = 1
            return fl
        ts, ps = [], []
        for key, t in self.key_t.items():
            if gtsam.Symbol(key).chr() == ord("x") and result.exists(key):
                rp = result.atPose2(key)
                ts.append(t)
                ps.append([rp.x(), rp.y(), rp.theta()])
        self.stats["batch_error"] = float(graph.error(result))
        return Trajectory.from_unsorted(np.array(ts), np.array(ps))
