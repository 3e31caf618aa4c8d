"""The paper's Extended Kalman Filter (section 3 of ../shared/paper/PAPER.md), plus an omni variant.

Differential / unicycle model (the paper's), state ``[x_m, y_m, theta_rad, v_mps, w_radps]``
(indices :data:`X`, :data:`Y`, :data:`TH`, :data:`V`, :data:`W`), map frame pose and body
velocities::

    x += v dt cos(th);  y += v dt sin(th);  th += w dt;  v, w constant

with the eq. 3 Jacobian :func:`motion_jacobian`.  Measurements, all linear in the state:

=========  ================  ======================
sensor     z                 H
=========  ================  ======================
map fix    [x, y, theta]     rows X, Y, TH of I
encoder    [v, w]            rows V, W of I
compass    [theta, w]        rows TH, W of I
=========  ================  ======================

Predict ``X- = f(X+)``, ``P- = F P+ F^T + Q dt`` (``Q`` is a continuous-time spectral
density, so the filter is independent of the sensor rates); update
``K = P- H^T (H P- H^T + R)^-1``, ``X+ = X- + K (z - H X-)``, ``P+ = P- - K H P-`` exactly as
the paper, with heading innovations wrapped to ``[-pi, pi)`` and each update gated on its
Mahalanobis distance (chi-square quantile per sensor).  Every measurement is applied after
predicting to its own stamp; a stamp older than the filter time is applied at the filter
time (counted in ``stats['late']``), never predicted backwards.  Predictions longer than
:data:`MAX_PREDICT_STEP_S` are integrated in steps (an odometry gap while turning), and
:meth:`EKF.update_encoder` with ``held_from`` takes the twist as the mean over ``(held_from, t]``.

The omni variant (mecanum robots) has state ``[x, y, theta, vx, vy, w]`` (indices
:data:`OX`... :data:`OW`) and the encoder measures ``[vx, vy, w]``.

Core maths only: no I/O, no printing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from fgloc.config.schema import radians, setting
from fgloc.geometry import wrap_scalar

FloatArray = NDArray[np.float64]

# Paper (differential / unicycle) state indices.
X, Y, TH, V, W = 0, 1, 2, 3, 4
# Omni (mecanum) state indices.
OX, OY, OTH, OVX, OVY, OW = 0, 1, 2, 3, 4, 5

# chi-square 99.9 % quantiles for 1..3 degrees of freedom (the default gates).
CHI2_999 = {1: 10.828, 2: 13.816, 3: 16.266}
#: s: a prediction longer than this is integrated in steps of at most this (the constant-velocity model
#: is Euler: one step over an odometry gap of 1-2 s while turning moves the robot along its old heading)
MAX_PREDICT_STEP_S = 0.1
#: the variance a held-back odometry interval's velocity starts from when the odometry is its only
#: source ((m/s)^2, (rad/s)^2): uninformative, so that the interval moves by the twist's increment
VELOCITY_FREE_VAR = 100.0
#: the odometry's yaw-rate scale is updated only by a reported and a predicted yaw rate both this many
#: of the twist's yaw-rate sigmas away from zero (and of one sign): within, the rate is the noise's
SCALE_EVIDENCE_SIGMAS = 3.0


_IX: dict[tuple[int, ...], tuple[np.ndarray, ...]] = {}
_EYE: dict[int, FloatArray] = {}
_DIAG: dict[tuple[float, ...], FloatArray] = {}


def _ix(idx: tuple[int, ...]) -> tuple[np.ndarray, ...]:
    """``np.ix_(idx, idx)``, made once per index tuple (a few per encoder update otherwise)."""
    got = _IX.get(idx)
    if got is None:
        got = _IX[idx] = np.ix_(idx, idx)
    return got


def _eye(n: int) -> FloatArray:
    """A fresh ``np.eye(n)`` (a copy of one made once)."""
    e = _EYE.get(n)
    if e is None:
        e = _EYE[n] = np.eye(n)
    return e.copy()


def motion_model(state: FloatArray, dt: float, omni: bool = False) -> FloatArray:
    """Constant-velocity motion ``f(X)`` over ``dt`` seconds (unicycle or omni)."""
    s = np.array(state, dtype=float)
    th = s[TH]
    c, sn = np.cos(th), np.sin(th)
    if omni:
        vx, vy, w = s[OVX], s[OVY], s[OW]
        s[OX] += (vx * c - vy * sn) * dt
        s[OY] += (vx * sn + vy * c) * dt
        s[OTH] = wrap_scalar(float(th + w * dt))
    else:
        v, w = s[V], s[W]
        s[X] += v * dt * c
        s[Y] += v * dt * sn
        s[TH] = wrap_scalar(float(th + w * dt))
    return s


def motion_jacobian(state: FloatArray, dt: float, omni: bool = False) -> FloatArray:
    """``dF/dX`` of :func:`motion_model`; for the unicycle this is the paper's eq. 3."""
    th = float(state[TH])
    c, sn = np.cos(th), np.sin(th)
    if omni:
        vx, vy = float(state[OVX]), float(state[OVY])
        F = _eye(6)
        F[OX, OTH] = (-vx * sn - vy * c) * dt
        F[OY, OTH] = (vx * c - vy * sn) * dt
        F[OX, OVX] = c * dt
        F[OX, OVY] = -sn * dt
        F[OY, OVX] = sn * dt
        F[OY, OVY] = c * dt
        F[OTH, OW] = dt
        return F
    v = float(state[V])
    F = _eye(5)
    F[X, TH] = -v * dt * sn
    F[X, V] = dt * c
    F[Y, TH] = v * dt * c
    F[Y, V] = dt * sn
    F[TH, W] = dt
    return F


_SELECTIONS: dict[tuple[tuple[int, ...], int], FloatArray] = {}


def selection(rows: list[int], n: int) -> FloatArray:
    """Rows ``rows`` of the ``n x n`` identity (the paper's H matrices): a new array (a copy of the one
    made for these rows once: every update asks for one)."""
    key = (tuple(rows), n)
    h = _SELECTIONS.get(key)
    if h is None:
        if len(_SELECTIONS) >= 64:
            _SELECTIONS.clear()
        h = _SELECTIONS[key] = np.eye(n)[rows]
    return h.copy()


@dataclass
class EKFConfig:
    """``ekf:`` section: noise and gating of the paper's EKF (the defaults are here and only here).

    ``q_*`` are continuous-time process noise spectral densities (variance per second):
    ``q_xy`` m^2/s, ``q_theta`` rad^2/s, ``q_v`` (m/s)^2/s, ``q_w`` (rad/s)^2/s.
    ``gate_*`` are Mahalanobis (squared) thresholds; ``None`` disables that gate.
    Angles are configured in degrees; the ``*_sigma_theta`` / ``*_sigma`` properties give radians.
    """

    omni: bool | None = setting(None, "true: mecanum / omni state [x, y, theta, vx, vy, w]; false: the paper's "
                                "[x, y, theta, v, w]; null: omni as soon as the odometry reports lateral velocity")
    q_xy: float = setting(1e-4, "process noise spectral density of x, y (m^2/s)", min=0)
    q_theta: float = setting(1e-4, "process noise spectral density of the heading (rad^2/s)", min=0)
    q_v: float = setting(0.5, "how fast the speed may change ((m/s)^2/s)", min=0)
    q_w: float = setting(1.0, "how fast the yaw rate may change ((rad/s)^2/s)", min=0)
    scans_alone_q: tuple[float, float] = setting(
        (2.0, 4.0), "without odometry (scans alone on a map): q_v and q_w instead, the velocity known from the "
        "fixes alone (a Jackal's turns start faster than q_w 1.0 follows)", min=0)
    gate_map: float | None = setting(16.27, "chi-square 99.9 % (3 dof) Mahalanobis gate on map fixes; null = none",
                                     gt=0)
    gate_encoder: float | None = setting(None, "Mahalanobis gate on the encoder twist; null = none", gt=0)
    gate_compass: float | None = setting(10.83, "chi-square 99.9 % (1 dof) gate on the compass; null = none", gt=0)
    map_min_sigma_xy: float = setting(0.005, "m, floor on the front-end's position sigma", min=0)
    map_min_sigma_theta_deg: float = setting(0.2, "deg, floor on the front-end's heading sigma", min=0)
    encoder_sigmas: tuple[float, float, float] = setting(
        (0.01, 0.01, 0.02), "[vx m/s, vy m/s, w rad/s] twist noise when /odom carries no covariance", gt=0)
    compass_sigma_deg: float = setting(0.5, "compass heading noise when /imu carries no covariance", gt=0)
    compass_rate_sigma_deg: float = setting(1.0, "compass yaw-rate noise (deg/s)", gt=0)
    use_compass_yaw: bool = setting(True, "use the compass heading (false: only its yaw rate)")
    calibration_fixes: int = setting(5, "map fixes used to calibrate the compass offset", min=1)
    max_rejections: int = setting(10, "fixes gated in a row before one is forced in", min=1)
    omni_vy_mps: float = setting(0.05, "auto omni: lateral velocity that makes the state omni", gt=0)
    gyro: bool = setting(True, "yaw rates (IMU gyro, compass rate) as measurements of w + bias (a bias state)")
    gyro_bias_prior_radps: float = setting(0.02, "prior sigma of a gyro's bias", gt=0)
    gyro_bias_q: float = setting(4e-10, "bias random walk ((rad/s)^2/s)", min=0)
    odom_yaw_scale: bool = setting(True, "estimate the odometry's yaw-rate scale (reported / true) as a state "
                                   "once another source measures the turn (a gyro, an absolute or a "
                                   "differential yaw)")
    odom_yaw_scale_prior: float = setting(1.0, "prior sigma of the yaw-rate scale's logarithm around 0 (the "
                                          "scale is estimated as its log: it stays positive)", gt=0)
    odom_yaw_scale_q: float = setting(1e-5, "its random walk (1/s)", min=0)
    adapt_noise: bool = setting(True, "weight the yaw sources by the noise they show against each other")
    compass_recover_after: int = setting(40, "compass headings gated in a row, while the sources agree it is "
                                         "healthy, before the heading is re-opened to it", min=1)
    relative_yaw_q: float = setting(1e-6, "random walk of a differential orientation source's own offset "
                                    "(rad^2/s): how fast its heading may drift from the filter's (an AHRS without "
                                    "a magnetometer drifts ~1-10 deg/h)", min=0)
    latency: bool = setting(True, "estimate the scan stamps' latency from how the fixes lag the gyro / odometry")
    latency_s: float | None = setting(None, "a known scan latency (s): overrides the estimate")
    history_s: float = setting(1.0, "s: a measurement stamped up to this long before the filter time (odometry "
                               "delivered late, IMU bursts, a late scan) is applied at its stamp and the later ones "
                               "again after it (robot_localization's smooth_lagged_data); older ones, or 0, are "
                               "applied at the filter time", min=0)
    odom_held_back: bool = setting(True, "an odometry twist is the mean since the previous message (held backwards, "
                                   "as the smoother integrates it): it measures the velocity at the start of that "
                                   "interval; false: the velocity at its stamp (the paper's)")

    # the angle settings in radians
    map_min_sigma_theta = radians()
    compass_sigma = radians()
    compass_rate_sigma = radians()


@dataclass
class EKF:
    """The paper's EKF (``omni=False``) or its mecanum variant (``omni=True``).

    Calibration states (a gyro's bias, the odometry's yaw-rate scale) can be appended with
    :meth:`add_state` (random walks, indices in :attr:`aug`); :meth:`to_omni` switches a
    diff-drive filter to the omni state when the odometry turns out to report lateral velocity.
    """

    config: EKFConfig = field(default_factory=EKFConfig)
    t: float | None = None
    x: FloatArray = field(default_factory=lambda: np.zeros(5))
    P: FloatArray = field(default_factory=lambda: np.eye(5))
    stats: dict = field(default_factory=lambda: {"updates": 0, "gated": {}, "late": 0})
    omni: bool = False
    aug: dict = field(default_factory=dict)       # name -> state index
    q_aug: dict = field(default_factory=dict)     # name -> spectral density
    bounds: dict = field(default_factory=dict)    # name -> (low, high): the state is kept in these

    def __post_init__(self) -> None:
        self.omni = bool(self.config.omni)

    @property
    def n_base(self) -> int:
        return 6 if self.omni else 5

    @property
    def n(self) -> int:
        return self.n_base + len(self.aug)

    @property
    def w_index(self) -> int:
        return OW if self.omni else W

    @property
    def initialized(self) -> bool:
        return self.t is not None

    def initialize(self, t: float, pose: FloatArray, pose_cov: FloatArray | None = None,
                   vel_sigma: float = 0.1) -> None:
        """Start at ``pose`` (map ``[x, y, yaw]``) with velocity zero (calibration states kept)."""
        old_aug = {k: (float(self.x[i]), float(self.P[i, i])) for k, i in self.aug.items()} \
            if len(self.x) == self.n else {}
        n = self.n
        self.t = float(t)
        self.x = np.zeros(n)
        self.x[:3] = pose
        self.x[TH] = wrap_scalar(float(self.x[TH]))
        self.P = np.eye(n) * vel_sigma**2
        self.P[:3, :3] = pose_cov if pose_cov is not None else np.diag([0.1**2, 0.1**2, np.deg2rad(5) ** 2])
        for k, i in self.aug.items():
            v, var = old_aug.get(k, (0.0, 1.0))
            self.x[i], self.P[i, i] = v, var

    def add_state(self, name: str, value: float, var: float, q: float,
                  bounds: tuple[float, float] | None = None) -> int:
        """Append a random-walk state (spectral density ``q``); returns its index.  With ``bounds``
        the state is kept in ``[low, high]`` after every update (a physical range)."""
        if name in self.aug:
            return int(self.aug[name])
        i = self.n
        self.aug[name] = i
        self.q_aug[name] = float(q)
        if bounds is not None:
            self.bounds[name] = (float(bounds[0]), float(bounds[1]))
        x = np.zeros(i + 1)
        x[:i] = self.x[:i] if len(self.x) >= i else np.pad(self.x, (0, i - len(self.x)))
        x[i] = value
        P = np.zeros((i + 1, i + 1))
        m = min(len(self.P), i)
        P[:m, :m] = self.P[:m, :m]
        P[i, i] = var
        self.x, self.P = x, P
        return i

    def to_omni(self, vy_var: float | None = None) -> None:
        """Switch to the omni state ``[x, y, th, vx, vy, w, ...]`` (vy = 0, variance ``vy_var``, default
        ``q_v``; at least 0.01)."""
        if self.omni:
            return
        n_old = self.n
        keep = [X, Y, TH, V, W] + list(range(5, n_old))
        x = np.zeros(n_old + 1)
        P = np.zeros((n_old + 1, n_old + 1))
        new_idx = [0, 1, 2, 3, 5] + list(range(6, n_old + 1))
        x[new_idx] = self.x[keep]
        P[np.ix_(new_idx, new_idx)] = self.P[np.ix_(keep, keep)]
        P[OVY, OVY] = max(self.config.q_v if vy_var is None else vy_var, 0.01)
        self.x, self.P = x, P
        self.omni = True
        self.aug = {k: i + 1 for k, i in self.aug.items()}

    # ------------------------------------------------------------------ predict
    def process_noise(self, dt: float, quiet: tuple[int, ...] = ()) -> FloatArray:
        """``Q dt``; the states in ``quiet`` get none (their change was added at once beforehand)."""
        c = self.config
        if self.omni:
            q = [c.q_xy, c.q_xy, c.q_theta, c.q_v, c.q_v, c.q_w]
        else:
            q = [c.q_xy, c.q_xy, c.q_theta, c.q_v, c.q_w]
        q += [0.0] * len(self.aug)
        for k, i in self.aug.items():
            q[i] = self.q_aug[k]
        for i in quiet:
            q[i] = 0.0
        key = tuple(q)
        d = _DIAG.get(key)
        if d is None:   # np.diag of the same densities, made once (every prediction step asks)
            if len(_DIAG) > 64:
                _DIAG.clear()
            d = _DIAG[key] = np.diag(q)
        return d * dt

    def _propagate(self, x: FloatArray, P: FloatArray, dt: float,
                   quiet: tuple[int, ...] = ()) -> tuple[FloatArray, FloatArray]:
        """``x``, ``P`` carried over ``dt`` (> 0) in steps of at most :data:`MAX_PREDICT_STEP_S`."""
        n = max(1, math.ceil(dt / MAX_PREDICT_STEP_S - 1e-9))
        h = dt / n
        Q = self.process_noise(h, quiet)
        for _ in range(n):
            F = self._F_at(x, h)
            x = motion_model(x, h, self.omni)
            P = F @ P @ F.T + Q
        return x, P

    def _F_at(self, x: FloatArray, dt: float) -> FloatArray:
        Fb = motion_jacobian(x, dt, self.omni)
        if not self.aug:
            return Fb
        F = _eye(self.n)
        F[:self.n_base, :self.n_base] = Fb
        return F

    def predict(self, t: float, quiet: tuple[int, ...] = ()) -> None:
        """Predict to time ``t`` (no-op when ``t`` is not after the filter time); the states in
        ``quiet`` without process noise."""
        assert self.t is not None, "EKF not initialized"
        dt = float(t) - self.t
        if dt <= 0.0:
            return
        self.x, self.P = self._propagate(self.x, self.P, dt, quiet)
        self.t = float(t)

    def predict_pose(self, t: float) -> tuple[FloatArray, FloatArray]:
        """Pose and its covariance predicted to ``t`` without changing the filter."""
        assert self.t is not None, "EKF not initialized"
        dt = max(0.0, float(t) - self.t)
        if dt <= 0.0:
            return self.x[:3].copy(), self.P[:3, :3].copy()
        x, P = self._propagate(self.x, self.P, dt)
        return x[:3].copy(), P[:3, :3].copy()

    # ------------------------------------------------------------------ update
    def update(self, t: float, z: FloatArray, rows: list[int], R: FloatArray,
               gate: float | None = None, sensor: str = "") -> bool:
        """Generic linear update ``z = H X + v`` with ``H = I[rows]``; returns False if gated.

        Innovation components on the heading row are wrapped.
        """
        assert self.t is not None, "EKF not initialized"
        if t < self.t:
            self.stats["late"] += 1
        self.predict(t)
        H = selection(rows, self.n)
        return self.update_h(np.asarray(z, dtype=float), H @ self.x, H, R, gate, sensor,
                             [i for i, r in enumerate(rows) if r == TH])

    def update_h(self, z: FloatArray, hx: FloatArray, H: FloatArray, R: FloatArray, gate: float | None,
                 sensor: str, wrap_rows: list[int] | tuple[int, ...] = (), frozen: tuple[int, ...] = ()) -> bool:
        """Update at the filter time with a linearized measurement ``z ~ h(x)``, Jacobian ``H``; the
        states in ``frozen`` enter the innovation's covariance but are not updated."""
        y = np.asarray(z, dtype=float) - np.asarray(hx, dtype=float)
        for i in wrap_rows:
            y[i] = wrap_scalar(float(y[i]))
        S = H @ self.P @ H.T + R
        # one row (a gyro's, a compass's): LAPACK's solve and inverse of a 1x1 are the division (the
        # same numbers), without their ~10 us per call each
        s = float(S[0, 0]) if S.shape == (1, 1) else 0.0
        scalar = s != 0.0 and math.isfinite(s)
        if gate is not None:
            if scalar:
                y0 = float(y[0])
                d2 = y0 * (y0 / s)
            else:
                d2 = float(y @ np.linalg.solve(S, y))
            if not np.isfinite(d2) or d2 > gate:
                self.stats["gated"][sensor] = self.stats["gated"].get(sensor, 0) + 1
                return False
        K = self.P @ H.T @ (np.array([[1.0 / s]]) if scalar else np.linalg.inv(S))
        if frozen:
            # the states in ``frozen`` are considered, not estimated (Schmidt): no gain, and the
            # covariance of that suboptimal gain, P - K H P - P H^T K^T + K S K^T
            K[list(frozen), :] = 0.0
            PHt = self.P @ H.T
            self.P = self.P - K @ PHt.T - PHt @ K.T + K @ S @ K.T
        self.x = self.x + K @ y
        self.x[TH] = wrap_scalar(float(self.x[TH]))
        for name, (lo, hi) in self.bounds.items():
            i = self.aug[name]
            self.x[i] = min(max(float(self.x[i]), lo), hi)
        if not frozen:
            self.P = self.P - K @ H @ self.P
        self.P = 0.5 * (self.P + self.P.T)
        self.stats["updates"] += 1
        return True

    def update_map(self, t: float, pose: FloatArray, cov: FloatArray, gate: bool = True) -> bool:
        """Map (scan-matcher) fix ``[x, y, yaw]`` with 3x3 covariance ``cov``."""
        c = self.config
        R = np.array(cov, dtype=float).copy()
        R[0, 0] = max(R[0, 0], c.map_min_sigma_xy**2)
        R[1, 1] = max(R[1, 1], c.map_min_sigma_xy**2)
        R[2, 2] = max(R[2, 2], c.map_min_sigma_theta**2)
        return self.update(t, np.asarray(pose, dtype=float), [X, Y, TH], R,
                           c.gate_map if gate else None, "map")

    def update_encoder(self, t: float, twist: FloatArray, twist_cov: FloatArray,
                       yaw_log_scale_index: int | None = None, held_from: float | None = None,
                       keep_w_noise: bool = False, sole: bool = False, scale_min_rate: float = 0.0) -> bool:
        """Encoder body twist ``[vx, vy, wz]`` with 3x3 covariance; the unicycle uses ``[vx, wz]``.

        With ``yaw_log_scale_index`` (the state ``l = ln s_w``) the reported yaw rate is
        ``s_w * w = exp(l) * w`` (a skid steer's scrub; the scale cannot change sign).

        ``held_from``: the twist is the mean over ``(held_from, t]`` (an odometry's pose increment
        over its period, held backwards as the smoother integrates it), not the velocity at ``t``:
        it measures the velocity at the start of that interval (the filter time) and the filter is
        then carried to ``t`` with it, so that the pose moves by the increment the twist describes.
        Measured at ``t`` instead, the interval would be crossed with the previous message's velocity
        (an odometry with gaps of seconds ends metres off).  Where other
        sensors carried the filter past ``held_from`` with the old velocity, the position moves by
        the velocity's change over that part.  ``keep_w_noise``: the yaw rate keeps its process noise
        over the interval (a gyro measures it within).  ``sole``: the odometry is the only source of
        the velocities it measures, whose interval velocity it then is, not a random walk's step from
        the last (the filter's smoothing would keep only part of each step of a quantized yaw, whose
        pose-increment rates are exact only integrated whole).  ``scale_min_rate`` (rad/s): the yaw
        rate the scale needs, at least (besides :data:`SCALE_EVIDENCE_SIGMAS` of the twist's yaw sigma)."""
        tw = np.asarray(twist, dtype=float)
        cov = np.asarray(twist_cov, dtype=float)
        assert self.t is not None, "EKF not initialized"
        if held_from is None or not self.t < float(t):
            return self._encoder_at(float(t), tw, cov, yaw_log_scale_index, scale_min_rate)
        # the interval's velocity is a new one: the random walk over the interval added at its start,
        # and no tie to the pose already travelled (spread over the interval, or correlated with the
        # pose, a precise twist after a gap would move the pose travelled before it); a block of a
        # covariance and the rest with their cross terms zeroed stays positive semidefinite
        t_meas, dt = self.t, float(t) - self.t
        quiet = tuple(i for i in ((OVX, OVY) if self.omni else (V,)) + (() if keep_w_noise else (self.w_index,)))
        q = np.diag(self.process_noise(dt))
        keep = self.P[_ix(quiet)].copy()
        self.P[quiet, :] = 0.0
        self.P[:, quiet] = 0.0
        self.P[_ix(quiet)] = keep
        for i in quiet:
            self.P[i, i] += VELOCITY_FREE_VAR if sole else q[i]
        before = self.x.copy()
        ok = self._encoder_at(t_meas, tw, cov, yaw_log_scale_index, scale_min_rate)
        missed = t_meas - float(held_from)
        if ok and missed > 0.0:
            self._shift_position(before, missed)
        self.predict(float(t), quiet)
        return ok

    def _shift_position(self, before: FloatArray, dt: float) -> None:
        """Move the pose by the change of the body velocity (from ``before``) held over ``dt``."""
        th = float(self.x[TH])
        c, sn = math.cos(th), math.sin(th)
        if self.omni:
            dvx, dvy = float(self.x[OVX] - before[OVX]), float(self.x[OVY] - before[OVY])
        else:
            dvx, dvy = float(self.x[V] - before[V]), 0.0
        self.x[X] += (dvx * c - dvy * sn) * dt
        self.x[Y] += (dvx * sn + dvy * c) * dt

    def _encoder_at(self, t: float, tw: FloatArray, cov: FloatArray, yaw_log_scale_index: int | None,
                    scale_min_rate: float = 0.0) -> bool:
        if yaw_log_scale_index is None:
            if self.omni:
                return self.update(t, tw, [OVX, OVY, OW], cov, self.config.gate_encoder, "encoder")
            idx = [0, 2]
            return self.update(t, tw[idx], [V, W], cov[_ix((0, 2))], self.config.gate_encoder, "encoder")
        assert self.t is not None, "EKF not initialized"
        self.predict(t)
        rows = [OVX, OVY, OW] if self.omni else [V, W]
        comp = [0, 1, 2] if self.omni else [0, 2]
        H = selection(rows, self.n)
        hx = H @ self.x
        sw = math.exp(float(self.x[yaw_log_scale_index]))
        w = float(self.x[self.w_index])
        H[-1, self.w_index] = sw
        hx[-1] = sw * w
        # a yaw rate within its noise of zero says nothing of the scale: the filter's w, pulled by the
        # last twists, correlates with this one's noise (every change of sign would shrink the scale,
        # directly or through the scale's correlation with w that the update would leave); then the
        # scale is neither updated nor tied to w by it
        z_w = float(tw[comp[-1]])
        floor = max(scale_min_rate, SCALE_EVIDENCE_SIGMAS * math.sqrt(max(float(cov[2, 2]), 0.0)))
        frozen: tuple[int, ...] = (yaw_log_scale_index,)
        if z_w * w > 0.0 and min(abs(z_w), abs(sw * w)) > floor:
            H[-1, yaw_log_scale_index] = sw * w
            frozen = ()
        return self.update_h(tw[comp], hx, H, cov[_ix(tuple(comp))], self.config.gate_encoder, "encoder",
                             frozen=frozen)

    def update_gyro(self, t: float, rate: float, var: float, bias_index: int | None, gate: float | None) -> bool:
        """A gyro's yaw rate: ``z = w + b`` with ``b`` the bias state at ``bias_index`` (None: ``z = w``,
        the rate already corrected for its bias)."""
        assert self.t is not None, "EKF not initialized"
        self.predict(t)
        H = np.zeros((1, self.n))
        H[0, self.w_index] = 1.0
        if bias_index is not None:
            H[0, bias_index] = 1.0
        return self.update_h(np.array([rate]), H @ self.x, H, np.array([[var]]), gate, "gyro")

    def update_compass(self, t: float, theta_map: float | None, var_theta: float,
                       rate: float | None = None, var_rate: float = 0.0, gated: bool = True) -> bool:
        """Compass ``[theta, w]`` (heading already in the map frame); either part may be None.
        ``gated`` False: no gate (a reading re-applied as it was decided on arrival)."""
        w_idx = self.w_index
        z: list[float] = []
        rows: list[int] = []
        var: list[float] = []
        if theta_map is not None:
            z.append(theta_map)
            rows.append(TH)
            var.append(var_theta)
        if rate is not None:
            z.append(rate)
            rows.append(w_idx)
            var.append(var_rate)
        if not rows:
            return False
        gate = self.config.gate_compass if gated else None
        if gate is not None and len(rows) == 2:
            gate = CHI2_999[2]
        return self.update(t, np.array(z), rows, np.diag(var), gate, "compass")

    def pose(self) -> FloatArray:
        return self.x[:3].copy()

    def pose_cov(self) -> FloatArray:
        return self.P[:3, :3].copy()
