"""The interface every back-end implements, as :class:`fgloc.localization.Localizer` drives it.

Inputs arrive in (nearly) time order: wheel odometry twists, compass headings (in
the compass's own frame; the back-end owns the compass-to-map offset) and, at each
scan time, a keyframe with the front-end's map fix if there is one.  The back-end
answers with a pose guess for the front-end (:meth:`Backend.predict`), the online
estimate (:meth:`Backend.current`, :meth:`Backend.online_trajectory`) and the
final, smoothed trajectory (:meth:`Backend.finish`).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod

import numpy as np
from numpy.typing import NDArray

from fgloc.geometry import exp as se2_exp
from fgloc.geometry import log as se2_log
from fgloc.types import PoseFix, Trajectory

FloatArray = NDArray[np.float64]


_DEFAULT_COV: dict[tuple[float, float, float], list[float]] = {}


def twist_covariance(cov: FloatArray | None, default_sigmas: tuple[float, float, float]) -> FloatArray:
    """The message's 3x3 twist covariance, or a diagonal default when absent / all zero / bad (a new array)."""
    return np.array(twist_covariance_values(cov, default_sigmas)).reshape(3, 3)


def twist_covariance_values(cov: FloatArray | None, default_sigmas: tuple[float, float, float]) -> list[float]:
    """:func:`twist_covariance`'s 9 entries (row by row) as floats, without the array (every odometry
    message of the smoother: one ``tolist`` instead of four numpy calls).  The default's list is
    shared between calls: read it, do not change it."""
    if cov is not None:
        if isinstance(cov, np.ndarray) and cov.dtype == np.float64 and cov.size == 9:
            v = cov.ravel().tolist()
        else:
            v = np.asarray(cov, dtype=float).reshape(3, 3).ravel().tolist()
        if v[0] > 0 and v[4] > 0 and v[8] > 0 and math.isfinite(sum(v)):
            return v
    d = _DEFAULT_COV.get(default_sigmas)
    if d is None:
        d = _DEFAULT_COV[default_sigmas] = np.diag(np.square(default_sigmas)).ravel().tolist()
    return d


class Backend(ABC):
    """A state estimator fed by :class:`fgloc.localization.Localizer`."""

    name: str = "backend"

    def __init__(self) -> None:
        self.stats: dict = {"keyframes": 0, "fixes_used": 0, "fixes_rejected": 0, "late": 0}
        self._online_t: list[float] = []
        self._online_p: list[FloatArray] = []
        self._online_c: list[FloatArray] = []

    @property
    @abstractmethod
    def initialized(self) -> bool: ...

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
        """Re-initialize after a relocalization (kidnapping); default: initialize again."""
        self.initialize(t, pose, cov)

    # ------------------------------------------------------------------ helpers
    def _record_online(self, t: float, pose: FloatArray, cov: FloatArray) -> None:
        if self._online_t and t <= self._online_t[-1]:
            return
        self._online_t.append(float(t))
        self._online_p.append(np.asarray(pose, dtype=float).copy())
        self._online_c.append(np.asarray(cov, dtype=float).copy())

    def online_trajectory(self) -> Trajectory:
        """The online estimate at each keyframe (scan) time, as it was known then."""
        if not self._online_t:
            return Trajectory(np.zeros(0), np.zeros((0, 3)))
        return Trajectory(np.asarray(self._online_t), np.asarray(self._online_p),
                          covs=np.asarray(self._online_c))


def with_rotation(delta: FloatArray, rotation: float, speed_gain: float = 1.0) -> FloatArray:
    """An SE(2) increment of a constant twist, its rotation replaced by ``rotation`` (rad) and its
    translation speed times ``speed_gain`` (the arc keeps its shape as a constant twist)."""
    u = se2_log(np.asarray(delta, dtype=float))
    u[:2] *= speed_gain
    u[2] = rotation
    return se2_exp(u)
