"""The live localizer's config sections (``serial:``, ``laser:``, ``health:``, ``robot:``).

Apart from the modules that use them (:mod:`fgloc.live.app`, :mod:`fgloc.live.serial_link`, which
import them from here) so that composing the one config (:mod:`fgloc.config.loader`, every
command's start) does not import the live localizer's threads, serial link and protocol: 0.012 s
of CPU at every ``fgloc run``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from fgloc.config.schema import setting
from fgloc.errors import ConfigError


@dataclass(frozen=True)
class SerialConfig:
    """``serial:`` the STM32 serial link (``fgloc live --serial``)."""

    baudrate: int = setting(115200, "serial baud rate", min=1)
    align_clock: bool = setting(True, "MCU timestamps -> host time (min-delay filter); false = arrival time")
    compass_clockwise: bool = setting(False, "true if the firmware sends a clockwise (north-east) heading")
    twist_std: tuple[float, float, float] | None = setting(
        None, "[vx m/s, vy m/s, wz rad/s] noise put into /odom; null = unknown (the back-end's sigmas apply)", gt=0)
    compass_std_deg: float | None = setting(None, "compass heading noise put into /imu; null = unknown", gt=0)
    gyro_std_dps: float | None = setting(None, "yaw-rate noise (deg/s) put into /imu; null = unknown", gt=0)


@dataclass(frozen=True)
class LaserConfig:
    """``laser:`` the SICK scanner over TCP, CoLa-A or CoLa-B (``fgloc live --laser``)."""

    range_min_m: float = setting(0.5, "shorter ranges are invalid (paper Table 2: 0.5-50 m)", min=0)
    range_max_m: float = setting(50.0, "longer ranges are invalid", gt=0)
    angle_offset_deg: float | None = setting(
        None, "REP 103 angle = device angle + this; null = by the device family (sRN DeviceIdent): -90 for "
        "LMS1xx, LMS5xx, TiM5xx/7xx, MRS1000 (device 0 deg is the scanner's right side), 0 for TiM240, "
        "LRS4xxx, NAV2xx")
    align_clock: bool = setting(True, "device 'time since startup' -> host time")
    time_increment_from: str = setting(
        "measurement_frequency", "beam timing for de-skew: 1 / measurement frequency, or rotation: scan_time * "
        "angular step / 360 deg", choices=("measurement_frequency", "rotation"))
    stall_timeout_s: float = setting(1.0, "reconnect when connected but silent this long", gt=0)
    start_measurement: bool = setting(
        False, "on connecting, log in as authorized client (SICK's default password) and send sMN "
        "LMCstartmeas and sMN Run before streaming: for a scanner left in standby (it changes the device's "
        "state)")
    layer_field: int = setting(0, "multi-layer scanners (MRS1000: one telegram per layer): the layer-angle "
                               "field (signed, 1/100 deg) of the planar layer to localize with; the other "
                               "layers are counted (other_layer) and skipped", min=-32768, max=32767)
    mount: tuple[float, float, float] = setting((0.0, 0.0, 0.0), "base_link -> laser [x_m, y_m, yaw_rad]")


@dataclass(frozen=True)
class HealthConfig:
    """``health:`` sensor monitoring in ``fgloc live``."""

    silence_s: float = setting(0.4, "a sensor with no message this long is reported silent (checked every "
                               "~20 ms)", gt=0)
    queue_max_msgs: int = setting(
        4000, "messages from the sensors waiting for the fusion loop at most (~40 s of a robot's 95 a second); "
        "when it is full the oldest is dropped, counted (queue_dropped) and reported: a host too slow for its "
        "input keeps bounded memory and fuses what is recent", min=1)


@dataclass
class RobotParams:
    """Drive geometry.  ``drive`` is ``"diff"`` (2 wheels: left, right) or ``"mecanum"``
    (4 wheels: front-left, front-right, rear-left, rear-right).  ``track_width_m`` is the
    left-right wheel distance, ``wheelbase_m`` front-rear (mecanum only)."""

    drive: str = setting("mecanum", "mecanum (4 wheels: FL, FR, RL, RR) or diff (2 wheels: left, right)",
                         choices=("mecanum", "diff"))
    wheel_radius_m: float = setting(0.076, "wheel radius", gt=0)
    track_width_m: float = setting(0.56, "left-right wheel distance", gt=0)
    wheelbase_m: float = setting(0.50, "front-rear axle distance (mecanum only)", gt=0)
    counts_per_rev: float = setting(2000.0, "encoder counts per wheel revolution (500 PPR x4 quadrature)", gt=0)
    max_speed_mps: float = setting(2.0, "the robot's top speed; odometry faster than 1.5x this is rejected "
                                   "(counted implausible_twist)", gt=0)
    max_yaw_rate_dps: float = setting(180.0, "the robot's top turn rate; odometry or gyro faster than 1.5x this is "
                                      "rejected (implausible_twist / implausible_rate)", gt=0)

    @property
    def n_wheels(self) -> int:
        return 4 if self.drive == "mecanum" else 2

    @staticmethod
    def from_dict(d: dict[str, Any] | None) -> RobotParams:
        d = dict(d or {})
        aliases = {
            "type": "drive", "kind": "drive", "wheel_radius": "wheel_radius_m",
            "track_width": "track_width_m", "wheel_separation": "track_width_m",
            "wheelbase": "wheelbase_m", "counts_per_rev": "counts_per_rev", "cpr": "counts_per_rev",
        }
        out: dict[str, Any] = {}
        for k, v in d.items():
            k2 = aliases.get(k, k)
            if k2 in RobotParams.__dataclass_fields__:
                out[k2] = v
        # the names fgloc.kinematics / SimResult.robot use: half distances, pulses per revolution
        if "half_track_m" in d:
            out["track_width_m"] = 2.0 * float(d["half_track_m"])
        if "half_wheelbase_m" in d:
            out["wheelbase_m"] = 2.0 * float(d["half_wheelbase_m"])
        for key in ("pulses_per_rev", "encoder_ppr"):
            if "counts_per_rev" not in out and key in d:
                out["counts_per_rev"] = 4.0 * float(d[key])  # quadrature decoding
        p = RobotParams(**out)
        p.drive = {"differential": "diff", "diff_drive": "diff", "omni": "mecanum"}.get(p.drive, p.drive)
        if p.drive not in ("diff", "mecanum"):
            raise ConfigError(f"robot drive must be 'diff' or 'mecanum', got {p.drive!r}")
        if p.wheel_radius_m <= 0 or p.track_width_m <= 0 or p.counts_per_rev <= 0:
            raise ConfigError("robot wheel_radius_m, track_width_m and counts_per_rev must be positive")
        return p
