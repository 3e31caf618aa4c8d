"""Wheel kinematics and quadrature encoders for mecanum and differential-drive robots.

Body twist ``[vx_mps, vy_mps, wz_radps]`` is in ``base_link`` (REP 103: x forward,
y left, z up).  Wheel speeds are rad/s, positive when the wheel drives the robot
forward.

Mecanum wheel order (index constants): ``FL, FR, RL, RR`` (front-left,
front-right, rear-left, rear-right), rollers in the usual "X" arrangement seen
from above, ``lx`` half the wheelbase (front-rear), ``ly`` half the track
(left-right)::

    w_FL = (vx - vy - (lx + ly) wz) / r        vx = r/4 ( w_FL + w_FR + w_RL + w_RR)
    w_FR = (vx + vy + (lx + ly) wz) / r        vy = r/4 (-w_FL + w_FR + w_RL - w_RR)
    w_RL = (vx + vy - (lx + ly) wz) / r        wz = r/(4 (lx + ly)) (-w_FL + w_FR - w_RL + w_RR)
    w_RR = (vx - vy + (lx + ly) wz) / r

Differential drive order: ``LEFT, RIGHT``; ``ly`` is half the track width.

Skid steer (Husky, Jackal, most outdoor bases): four wheels in ``FL, FR, RL, RR`` order, the
two of a side driven together, differential-drive kinematics on the wheels' mean; the
wheels scrub sideways when the base turns, so the yaw rate their speeds imply (with the
geometric track) is larger than the true one (the simulator's ``scrub`` factor).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fgloc.errors import ConfigError

FloatArray = NDArray[np.float64]

FL, FR, RL, RR = 0, 1, 2, 3
LEFT, RIGHT = 0, 1
VX, VY, WZ = 0, 1, 2


@dataclass(frozen=True)
class MecanumKinematics:
    """Four-wheel mecanum platform."""

    wheel_radius_m: float
    half_wheelbase_m: float
    half_track_m: float
    n_wheels: int = 4

    def inverse(self, twist: ArrayLike) -> FloatArray:
        """Body twist ``(..., 3)`` -> wheel speeds ``(..., 4)`` rad/s in FL, FR, RL, RR order."""
        t = np.asarray(twist, dtype=float)
        vx, vy, wz = t[..., VX], t[..., VY], t[..., WZ]
        k = self.half_wheelbase_m + self.half_track_m
        r = self.wheel_radius_m
        return np.stack([vx - vy - k * wz, vx + vy + k * wz, vx + vy - k * wz, vx - vy + k * wz], axis=-1) / r

    def forward(self, wheel_speeds: ArrayLike) -> FloatArray:
        """Wheel speeds ``(..., 4)`` rad/s -> body twist ``(..., 3)`` (least squares, exact for 4 wheels)."""
        w = np.asarray(wheel_speeds, dtype=float)
        r = self.wheel_radius_m
        k = self.half_wheelbase_m + self.half_track_m
        vx = r / 4 * (w[..., FL] + w[..., FR] + w[..., RL] + w[..., RR])
        vy = r / 4 * (-w[..., FL] + w[..., FR] + w[..., RL] - w[..., RR])
        wz = r / (4 * k) * (-w[..., FL] + w[..., FR] - w[..., RL] + w[..., RR])
        return np.stack([vx, vy, wz], axis=-1)


@dataclass(frozen=True)
class DiffDriveKinematics:
    """Two driven wheels on a common axle (casters ignored); ``vy`` is always 0."""

    wheel_radius_m: float
    half_track_m: float
    n_wheels: int = 2

    def inverse(self, twist: ArrayLike) -> FloatArray:
        """Body twist ``(..., 3)`` -> wheel speeds ``(..., 2)`` rad/s (LEFT, RIGHT); vy is ignored."""
        t = np.asarray(twist, dtype=float)
        vx, wz = t[..., VX], t[..., WZ]
        return np.stack([vx - self.half_track_m * wz, vx + self.half_track_m * wz], axis=-1) / self.wheel_radius_m

    def forward(self, wheel_speeds: ArrayLike) -> FloatArray:
        """Wheel speeds ``(..., 2)`` rad/s -> body twist ``(..., 3)``."""
        w = np.asarray(wheel_speeds, dtype=float)
        r = self.wheel_radius_m
        vx = r / 2 * (w[..., LEFT] + w[..., RIGHT])
        wz = r / (2 * self.half_track_m) * (w[..., RIGHT] - w[..., LEFT])
        return np.stack([vx, np.zeros_like(vx), wz], axis=-1)


@dataclass(frozen=True)
class SkidSteerKinematics:
    """Four wheels, two per side turning together; ``vy`` is always 0 (FL, FR, RL, RR order)."""

    wheel_radius_m: float
    half_track_m: float
    half_wheelbase_m: float = 0.0
    n_wheels: int = 4

    def inverse(self, twist: ArrayLike) -> FloatArray:
        """Body twist ``(..., 3)`` -> wheel speeds ``(..., 4)`` rad/s (no scrub); vy is ignored."""
        t = np.asarray(twist, dtype=float)
        vx, wz = t[..., VX], t[..., WZ]
        left = (vx - self.half_track_m * wz) / self.wheel_radius_m
        right = (vx + self.half_track_m * wz) / self.wheel_radius_m
        return np.stack([left, right, left, right], axis=-1)

    def forward(self, wheel_speeds: ArrayLike) -> FloatArray:
        """Wheel speeds ``(..., 4)`` rad/s -> body twist ``(..., 3)`` (each side's mean)."""
        w = np.asarray(wheel_speeds, dtype=float)
        r = self.wheel_radius_m
        left = 0.5 * (w[..., FL] + w[..., RL])
        right = 0.5 * (w[..., FR] + w[..., RR])
        vx = r / 2 * (left + right)
        wz = r / (2 * self.half_track_m) * (right - left)
        return np.stack([vx, np.zeros_like(vx), wz], axis=-1)


Kinematics = MecanumKinematics | DiffDriveKinematics | SkidSteerKinematics

#: drive names that have a lateral velocity (the omni state of the back-ends)
HOLONOMIC_DRIVES = ("mecanum", "omni", "omnidirectional", "holonomic")



@dataclass(frozen=True)
class QuadratureEncoder:
    """Incremental encoder read in quadrature: ``4 * pulses_per_rev`` counts per wheel revolution.

    The paper's Omron E6B2-CWZ6C gives 500 pulses/rev, i.e. 2000 counts/rev.
    """

    pulses_per_rev: int = 500
    quadrature: int = 4

    @property
    def counts_per_rev(self) -> int:
        return self.pulses_per_rev * self.quadrature

    def angle_to_counts(self, angle_rad: ArrayLike) -> NDArray[np.int64]:
        """Cumulative wheel angle (rad) -> cumulative integer count (floor, as a counter latches edges)."""
        return np.floor(np.asarray(angle_rad, dtype=float) / (2 * np.pi) * self.counts_per_rev).astype(np.int64)

    def counts_to_angle(self, counts: ArrayLike) -> FloatArray:
        return np.asarray(counts, dtype=float) * (2 * np.pi / self.counts_per_rev)


def counts_to_twist(kin: Kinematics, enc: QuadratureEncoder, delta_counts: ArrayLike, dt_s: float) -> FloatArray:
    """Count differences over ``dt_s`` seconds (one per wheel) -> body twist ``[vx, vy, wz]``."""
    if not dt_s > 0:
        raise ValueError(f"dt must be positive, got {dt_s}")
    w = enc.counts_to_angle(delta_counts) / dt_s
    return kin.forward(w)


def make_kinematics(cfg: dict) -> Kinematics:
    """Kinematics from ``{drive: mecanum|diff|skid, wheel_radius_m, half_wheelbase_m, half_track_m}``."""
    drive = str(cfg.get("drive", "mecanum")).lower()
    try:
        r = float(cfg["wheel_radius_m"])
        ly = float(cfg["half_track_m"])
        if drive == "mecanum":
            return MecanumKinematics(r, float(cfg["half_wheelbase_m"]), ly)
        if drive in ("diff", "differential", "diff_drive"):
            return DiffDriveKinematics(r, ly)
        if drive in ("skid", "skid_steer", "skid-steer"):
            return SkidSteerKinematics(r, ly, float(cfg.get("half_wheelbase_m", 0.0)))
    except KeyError as e:
        raise ConfigError(f"kinematics config lacks {e.args[0]}") from None
    raise ConfigError(f"unknown drive '{drive}' (mecanum, diff or skid)")
