"""The back-end contract: everything the localizer, the sources router and the view call on a back-end.

Inputs arrive in (nearly) time order: wheel odometry twists, compass headings (in the compass's
own frame; the back-end owns the compass-to-map offset) and, at each scan time, a keyframe with
the front-end's map fix if there is one.  The back-end answers with a pose guess for the
front-end (:meth:`Backend.predict`), the online estimate (:meth:`Backend.current`,
:meth:`Backend.online_trajectory`) and the final, smoothed trajectory (:meth:`Backend.finish`).

Every back-end takes odometry, compass readings and keyframes.  What only some back-ends do is a
declared :class:`Capability` (``Backend.capabilities``): a further input (a gyro's yaw rate, a
second odometry's twists, a differential orientation), a way of using the odometry, or an
estimate it keeps (odometry scales, gyro biases, scan latency).  A caller asks
``Capability.X in backend.capabilities``; a back-end without it raises ``NotImplementedError``
for the input, and reports the neutral value (scale 1, bias 0, latency 0) for the estimate.

Adding a back-end: subclass :class:`Backend`, implement the abstract methods and
:meth:`Backend.from_config`, declare the capabilities it has and implement their methods, and add it
to :data:`fgloc.backends.REGISTRY` (its config section to :class:`fgloc.config.FglocConfig`).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from bisect import bisect_left
from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import Enum
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from fgloc.backends.health import SourceHealth
from fgloc.types import PoseFix, Trajectory

FloatArray = NDArray[np.float64]

#: s, no odometry this long after the start: a log of scans alone (on a map; an IMU at most), the
#: back-end carries its own velocity between the fixes and waits for no odometry
SCANS_ALONE_AFTER_S = 1.0


class Capability(Enum):
    """What a back-end does beyond the inputs every back-end takes."""

    #: the odometry twist measures a velocity state (a filter): after a burst of pose stamps the
    #: localizer hands a velocity estimated over the last poses, not the burst's increment
    #: (:meth:`fgloc.localization.odometry.OdometryTracker.velocity_measurement`), and does not carry
    #: the odometry to each scan stamp
    MEASURES_VELOCITY = "measures_velocity"
    #: integrates the odometry's increments between keyframes: a slow odometry's stamps are placed
    #: on the scans' clock by the localizer (:class:`fgloc.localization.clock.OdometryClock`), which
    #: says when it cannot (:meth:`Backend.set_odometry_timing_unknown`)
    ODOMETRY_CLOCK = "odometry_clock"
    #: :meth:`Backend.add_gyro`: a gyro's yaw rate with an estimated bias
    GYRO = "gyro"
    #: :meth:`Backend.add_velocity`: a further odometry source's body twist
    VELOCITY = "velocity"
    #: :meth:`Backend.add_relative_yaw`: an orientation whose increments are used, not its frame
    RELATIVE_YAW = "relative_yaw"
    #: :meth:`Backend.odom_scales`: the odometry's speed and yaw-rate scales are estimated
    ODOM_SCALES = "odom_scales"
    #: :meth:`Backend.gyro_bias`: each gyro's bias is estimated
    GYRO_BIAS = "gyro_bias"
    #: :meth:`Backend.latency_estimate`, :meth:`Backend.latency_fit`: the scans' latency is estimated
    LATENCY = "latency"
    #: the covariance is the state's own (a filter): :meth:`Backend.current` with ``covariance=True``
    #: computes nothing new, so a prediction made before it stands (a smoother's marginal is computed
    #: there, on demand, and starts its predictions' covariance)
    STATE_COVARIANCE = "state_covariance"
    #: memory and time per input stay bounded however long it runs: ``fgloc live`` takes it (a batch
    #: optimization over the whole run does not)
    LIVE = "live"


@dataclass(frozen=True)
class SourceNoise:
    """The noise one input stream showed against the other sources of the same quantity
    (:class:`fgloc.backends.health.Arbiter`): its claimed variance times ``k_claimed^2`` plus
    ``(per_turn * increment)^2``."""

    k_claimed: float
    per_turn: float
    shown_sigma: float | None     # per comparison block; None before there is evidence
    claimed_sigma: float | None


@dataclass(frozen=True)
class Estimates:
    """What a back-end has estimated about its inputs so far (None / empty: not estimated)."""

    compass_offset_rad: float | None = None     # compass_yaw = map_yaw + offset
    odom_speed_scale: float | None = None       # reported / true
    odom_yaw_rate_scale: float | None = None    # reported / true
    gyro_bias_radps: Mapping[str, float] = field(default_factory=dict)   # per IMU source
    latency_s: float | None = None              # the scans' latency in use
    latency_estimate_s: float | None = None     # the estimator's fit, once it has a finite sigma
    latency_sigma_s: float | None = None

    def as_dict(self) -> dict[str, Any]:
        """The estimates that are known, by name (JSON-ready: floats and a dict of floats)."""
        out: dict[str, Any] = {}
        for k in ("compass_offset_rad", "odom_speed_scale", "odom_yaw_rate_scale", "latency_s",
                  "latency_estimate_s", "latency_sigma_s"):
            v = getattr(self, k)
            if v is not None:
                out[k] = float(v)
        if self.gyro_bias_radps:
            out["gyro_bias_radps"] = {k: float(v) for k, v in self.gyro_bias_radps.items()}
        return out


class Backend(ABC):
    """A state estimator fed by :class:`fgloc.localization.Localizer` (and the sources router)."""

    name: str = "backend"
    #: what this back-end does beyond the common inputs (see :class:`Capability`)
    capabilities: ClassVar[frozenset[Capability]] = frozenset()
    #: the section of :class:`fgloc.config.FglocConfig` holding its settings (the latency's among
    #: them); empty: none
    config_section: ClassVar[str] = ""
    #: counters of the run (keyframes, fixes used / rejected, late inputs, ...), for the run summary
    stats: dict[str, Any]

    def __init__(self) -> None:
        self.stats = {"keyframes": 0, "fixes_used": 0, "fixes_rejected": 0, "late": 0}
        self._online_t: list[float] = []
        self._online_p: list[FloatArray] = []
        self._online_c: list[FloatArray] = []
        #: the run-long records (the online trajectory, a smoother's smoothed keyframes) kept this many
        #: seconds back; None: the whole run (the outputs of a run)
        self.history_s: float | None = None

    # ------------------------------------------------------------------ every back-end
    @classmethod
    def from_config(cls, config: Any = None) -> Backend:
        """The back-end with its sections of ``config`` (a :class:`fgloc.config.FglocConfig`; None:
        the defaults).  Default: no section."""
        return cls()

    @property
    @abstractmethod
    def initialized(self) -> bool: ...

    @property
    @abstractmethod
    def encoder_sigmas(self) -> tuple[float, float, float]:
        """``[vx m/s, vy m/s, w rad/s]`` twist noise used when an odometry message carries no covariance."""

    @abstractmethod
    def initialize(self, t: float, pose: FloatArray, cov: FloatArray | None = None) -> None:
        """Start at map pose ``pose`` at time ``t``."""

    @abstractmethod
    def set_compass_offset(self, offset: float) -> None:
        """Declare the compass-to-map offset known (``compass_yaw = map_yaw + offset``)."""

    @abstractmethod
    def add_odometry(self, t: float, twist: FloatArray, twist_cov: FloatArray | None) -> None:
        """Body twist ``[vx, vy, wz]`` measured at ``t``."""

    @abstractmethod
    def add_compass(self, t: float, yaw: float | None, yaw_var: float,
                    rate: float | None, rate_var: float) -> None:
        """Compass yaw (compass frame) and yaw rate at ``t``; either may be None."""

    @abstractmethod
    def add_keyframe(self, t: float, fix: PoseFix | None) -> bool:
        """A keyframe at scan time ``t`` with the front-end's fix, if any; True if the fix was used."""

    @abstractmethod
    def predict(self, t: float) -> tuple[FloatArray, FloatArray]:
        """Pose guess and 3x3 covariance at ``t`` (for the front-end)."""

    @abstractmethod
    def current(self, covariance: bool = True) -> tuple[float, FloatArray, FloatArray] | None:
        """Latest (time, pose, cov) estimate, or None before initialization.  ``covariance=False``:
        the last computed covariance may be returned (a smoother's marginal is not free)."""

    @abstractmethod
    def finish(self) -> Trajectory:
        """The final trajectory at keyframe times (smoothed for the smoothers)."""

    def output_covariance(self, t: float, pose: FloatArray, cov: FloatArray) -> FloatArray:
        """The covariance to report with ``pose`` at ``t`` (the fused pose, the online trajectory), given
        the estimator's own ``cov``: a back-end whose internal covariance is knowingly too small says so
        here (the smoother: never below the last fix it took).  Default: ``cov``."""
        return cov

    def record_prediction(self, t: float) -> None:
        """Add the odometry prediction at ``t`` to the online trajectory (a scan without keyframe)."""
        if self.initialized:
            pose, cov = self.predict(t)
            self._record_online(t, pose, cov)

    def compass_offset(self) -> float | None:
        """The compass-to-map offset (rad) once known, else None."""
        return None

    def motion_correction(self, t0: float, t1: float, delta: FloatArray) -> FloatArray:
        """The odometry's motion ``delta`` (``odom`` increment over ``(t0, t1]``) as the back-end
        believes it happened: with the odometry's estimated scales and a gyro's rotation where it
        covers the interval (a skid steer's wheels report twice the turn: a scan de-skewed with
        that is bent).  For the front-ends' de-skew and motion model; default: as it is."""
        return delta

    def reset(self, t: float, pose: FloatArray, cov: FloatArray) -> None:
        """Re-initialize after a relocalization (kidnapping); default: initialize again.  The online pose
        already recorded at ``t`` (the keyframe of the scan that relocalized) is the one before: replaced."""
        if self._online_t and self._online_t[-1] >= t:
            k = bisect_left(self._online_t, t)
            del self._online_t[k:], self._online_p[k:], self._online_c[k:]
        self.initialize(t, pose, cov)

    def online_trajectory(self) -> Trajectory:
        """The online estimate at each keyframe (scan) time, as it was known then."""
        if not self._online_t:
            return Trajectory(np.zeros(0), np.zeros((0, 3)))
        return Trajectory(np.asarray(self._online_t), np.asarray(self._online_p),
                          covs=np.asarray(self._online_c))

    def online_after(self, t: float) -> list[tuple[float, FloatArray, FloatArray]]:
        """The entries of :meth:`online_trajectory` stamped after ``t``, oldest first, ``(t, pose, cov)``,
        without building the whole trajectory (a live node publishing each pose as it is known)."""
        ts = self._online_t
        k = len(ts)
        while k > 0 and ts[k - 1] > t:
            k -= 1
        return [(ts[i], self._online_p[i], self._online_c[i]) for i in range(k, len(ts))]

    def source_health(self) -> Mapping[str, SourceHealth]:
        """Per input stream the back-end saw (``odom``, ``imu.yaw``, ``imu.gyro``, ``scan``, a further
        source's name): what it accepted, gated and skipped."""
        return {}

    def source_noise(self, name: str) -> SourceNoise | None:
        """The noise stream ``name`` showed against the others, or None when it was not compared."""
        return None

    def motion_summary(self, vy_max_mps: float | None = None) -> str:
        """Which body twist the back-end integrates, and why (the run summary's line);
        ``vy_max_mps``: the largest lateral velocity the odometry's messages reported (None: unknown).
        Default: the odometry's whole twist, as a smoother integrates it."""
        if vy_max_mps == 0.0:
            return "differential: the odometry's lateral velocity is 0 throughout (its whole twist is integrated)"
        if vy_max_mps is not None:
            return ("omni: the odometry's whole twist (vx, vy, w) is integrated (lateral velocity up to "
                    f"{vy_max_mps:.3f} m/s)")
        return "omni: the odometry's whole twist (vx, vy, w) is integrated"

    def estimates(self) -> Estimates:
        """What the back-end has estimated so far (the view's health panel, the run summary)."""
        caps = self.capabilities
        scales = self.odom_scales() if Capability.ODOM_SCALES in caps else None
        biases: dict[str, float] = {}
        if Capability.GYRO_BIAS in caps:
            for name, h in self.source_health().items():
                if h.kind == "gyro" and name.endswith(".gyro"):
                    src = name[: -len(".gyro")]
                    biases[src] = float(self.gyro_bias(src))
        lat = fit = None
        if Capability.LATENCY in caps:
            lat = float(self.latency_estimate())
            fit = self.latency_fit()
        off = self.compass_offset()
        return Estimates(
            compass_offset_rad=None if off is None else float(off),
            odom_speed_scale=None if scales is None else float(scales[0]),
            odom_yaw_rate_scale=None if scales is None else float(scales[1]),
            gyro_bias_radps=biases, latency_s=lat,
            latency_estimate_s=None if fit is None else fit[0],
            latency_sigma_s=None if fit is None else fit[1])

    # ------------------------------------------------------------------ capabilities
    def add_gyro(self, t: float, rate: float, rate_var: float, source: str = "imu") -> None:
        """(:attr:`Capability.GYRO`) A yaw rate (rad/s, base_link z) measuring ``w + bias``."""
        raise NotImplementedError(f"the {self.name} back-end takes no gyro input")

    def add_velocity(self, t: float, twist: FloatArray, twist_cov: FloatArray, used: tuple[bool, bool, bool],
                     source: str) -> None:
        """(:attr:`Capability.VELOCITY`) Another odometry source's body twist ``[vx, vy, wz]``; its
        ``used`` components are measurements."""
        raise NotImplementedError(f"the {self.name} back-end takes no further odometry source")

    def add_relative_yaw(self, t: float, yaw: float, var: float, source: str = "imu") -> None:
        """(:attr:`Capability.RELATIVE_YAW`) An orientation whose increments are used, not its frame
        (robot_localization's ``imuN_differential``)."""
        raise NotImplementedError(f"the {self.name} back-end takes no differential orientation")

    def set_odometry_timing_unknown(self, unknown: bool) -> None:
        """(:attr:`Capability.ODOMETRY_CLOCK`) The odometry's stamps cannot be placed against the
        scans' (a slow odometry written in bursts): the back-end carries their timing uncertainty."""
        raise NotImplementedError(f"the {self.name} back-end keeps no odometry clock")

    def odom_scales(self) -> FloatArray:
        """(:attr:`Capability.ODOM_SCALES`) The odometry's ``[speed, yaw-rate]`` scales (reported / true)."""
        return np.ones(2)

    def gyro_bias(self, source: str = "imu") -> float:
        """(:attr:`Capability.GYRO_BIAS`) The estimated bias (rad/s) of ``source``'s gyro (0 before it is
        estimated)."""
        return 0.0

    def latency_estimate(self) -> float:
        """(:attr:`Capability.LATENCY`) The scans' latency (s) in use: configured, estimated once
        significant, or 0."""
        return 0.0

    def latency_fit(self) -> tuple[float, float] | None:
        """(:attr:`Capability.LATENCY`) The latency estimator's fit ``(estimate s, sigma s)`` once its
        sigma is finite, else None."""
        return None

    # ------------------------------------------------------------------ helpers
    def _record_online(self, t: float, pose: FloatArray, cov: FloatArray) -> None:
        if self._online_t and t <= self._online_t[-1]:
            return
        self._online_t.append(float(t))
        self._online_p.append(np.asarray(pose, dtype=float).copy())
        self._online_c.append(np.asarray(cov, dtype=float).copy())
        h = self.history_s
        if h is not None and t - self._online_t[0] > 2.0 * h:  # amortized: cut once twice the history is held
            k = bisect_left(self._online_t, t - h)
            del self._online_t[:k], self._online_p[:k], self._online_c[:k]

