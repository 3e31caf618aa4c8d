"""STM32 serial link: open any pyserial URL, parse frames, turn them into messages.

:class:`FrameConverter` (pure) turns :class:`SensorFrame` s into ``Odometry`` (wheel
counts -> wheel speeds -> body twist through :mod:`fgloc.kinematics`, integrated to a
dead-reckoned ``odom`` pose) and ``CompassHeading`` messages stamped in host time
through :class:`ClockSync`.  :class:`SerialLink` is the reader thread: it opens the
port with ``serial.serial_for_url`` (``/dev/ttyUSB0``, ``socket://host:port``,
``loop://``, ``rfc2217://...``), reconnects with back-off when the port goes away,
and calls ``on_message(topic_kind, msg, arrival)`` for each message.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from fgloc.geometry import compose1, wrap_angle
from fgloc.geometry import exp as se2_exp
from fgloc.live.clock import ClockStep, ClockSync
from fgloc.live.config import RobotParams
from fgloc.live.serial_protocol import COUNT_MOD, SYNC, FrameParser, SensorFrame
from fgloc.live.worker import SensorThread
from fgloc.types import CompassHeading, Odometry

log = logging.getLogger(__name__)


def kinematics_of(p: RobotParams) -> Any:
    """The :mod:`fgloc.kinematics` model of these parameters."""
    from fgloc.kinematics import make_kinematics

    return make_kinematics({"drive": p.drive, "wheel_radius_m": p.wheel_radius_m,
                            "half_track_m": p.track_width_m / 2.0, "half_wheelbase_m": p.wheelbase_m / 2.0})


def wheel_speeds_to_twist(p: RobotParams, omega_radps: np.ndarray) -> np.ndarray:
    """Wheel angular speeds (rad/s) -> body twist ``[vx, vy, wz]`` by forward kinematics."""
    return np.asarray(kinematics_of(p).forward(np.asarray(omega_radps, dtype=float)), dtype=float)


def twist_to_wheel_speeds(p: RobotParams, twist: np.ndarray) -> np.ndarray:
    """Body twist -> wheel angular speeds (inverse kinematics; used by the emulator)."""
    return np.asarray(kinematics_of(p).inverse(np.asarray(twist, dtype=float)), dtype=float)


PLAUSIBILITY_MARGIN = 1.5  # x the robot's configured top speed / turn rate
REBASE_AFTER = 3  # consecutive implausible count steps before the counts are taken as the new baseline


class FrameConverter:
    """SensorFrame -> ``("odom", Odometry)`` / ``("imu", CompassHeading)``, host-time stamped.

    Plausibility: a twist faster than ``PLAUSIBILITY_MARGIN`` x the robot's ``max_speed_mps``
    (translation) or ``max_yaw_rate_dps`` (rotation) is rejected (``implausible_twist``): a
    CRC-valid frame whose counter jumped (a firmware or bus fault) would otherwise give a
    twist of millions of m/s.  The previous counts stay the baseline, so the next good frame
    covers the skipped interval (the counts are cumulative); after ``REBASE_AFTER`` rejections
    in a row the counts are taken as the new baseline (``counts_rebased``: the counter was
    reset without an MCU restart).  A gyro rate beyond the turn-rate limit is dropped
    (``implausible_rate``), the heading of that frame kept.
    """

    def __init__(
        self,
        robot: RobotParams,
        compass_clockwise: bool = False,
        twist_var: tuple[float, float, float] | None = None,
        yaw_var: float = float("nan"),
        yaw_rate_var: float = float("nan"),
        align_clock: bool = True,
    ) -> None:
        self.robot = robot
        self._kin = kinematics_of(robot)
        self.compass_sign = -1.0 if compass_clockwise else 1.0
        # None / NaN = unknown: the localizer's configured encoder / compass sigmas apply
        self.twist_cov = None if twist_var is None else np.diag(np.asarray(twist_var, dtype=float))
        self.yaw_var = yaw_var
        self.yaw_rate_var = yaw_rate_var
        self.align_clock = align_clock
        self.clock = ClockSync()
        self.clock_steps: list[ClockStep] = []  # found since the caller last took them (SerialLink reports them)
        self.wrong_wheel_count = 0
        self.bad_dt = 0
        self.implausible_twist = 0
        self.implausible_rate = 0
        self.counts_rebased = 0
        self._rejected_in_row = 0
        self.max_speed_mps = PLAUSIBILITY_MARGIN * float(robot.max_speed_mps)
        self.max_yaw_rate_radps = PLAUSIBILITY_MARGIN * math.radians(float(robot.max_yaw_rate_dps))
        self._prev: tuple[float, tuple[int, ...]] | None = None
        self._pose = np.zeros(3)
        self._last_stamp = -math.inf

    def counters(self) -> dict[str, Any]:
        return {"wrong_wheel_count": self.wrong_wheel_count, "bad_dt": self.bad_dt,
                "implausible_twist": self.implausible_twist, "implausible_rate": self.implausible_rate,
                "counts_rebased": self.counts_rebased, "clock_steps": self.clock.n_steps,
                "clock_outliers": self.clock.outliers,
                "clock_step_sizes_s": [round(st.step_s, 4) for st in self.clock.steps]}

    def plausible(self, twist: np.ndarray) -> bool:
        """Whether a body twist ``[vx, vy, wz]`` is within the robot's limits (with the margin)."""
        return bool(math.hypot(twist[0], twist[1]) <= self.max_speed_mps
                    and abs(twist[2]) <= self.max_yaw_rate_radps)

    def convert(self, f: SensorFrame, arrival: float) -> list[tuple[str, object]]:
        out: list[tuple[str, object]] = []
        if f.reset:
            self.clock.reset()
            self._prev = None
        t_raw = f.t_us_unwrapped * 1e-6
        # the clock is followed even when arrival times stamp the messages: its steps are taken out of
        # the device time the wheel counts are differentiated over
        step = self.clock.update(t_raw, arrival)
        if step is not None:
            self.clock_steps.append(step)
        t_dev = self.clock.continuous(t_raw)
        stamp = self.clock.to_host(t_raw, arrival) if self.align_clock else arrival
        if stamp <= self._last_stamp:
            stamp = self._last_stamp + 1e-6
        self._last_stamp = stamp
        if f.has_counts:
            if len(f.counts) != self.robot.n_wheels:
                self.wrong_wheel_count += 1
            else:
                odom = self._counts_to_odometry(f.counts, t_dev, stamp)
                if odom is not None:
                    out.append(("odom", odom))
        if f.has_heading and f.heading_ddeg is not None:
            yaw = float(wrap_angle(self.compass_sign * math.radians(f.heading_ddeg / 10.0)))
            rate = None if f.gyro_cdps is None else self.compass_sign * math.radians(f.gyro_cdps / 100.0)
            if rate is not None and abs(rate) > self.max_yaw_rate_radps:
                self.implausible_rate += 1
                rate = None
            out.append(
                ("imu", CompassHeading(stamp=stamp, yaw_rad=yaw, yaw_rate_radps=rate, yaw_var=self.yaw_var,
                                       yaw_rate_var=self.yaw_rate_var))
            )
        return out

    def _counts_to_odometry(self, counts: tuple[int, ...], t_dev: float, stamp: float) -> Odometry | None:
        """Twist from the counts since the baseline; the baseline moves on unless rejected."""
        if self._prev is None:
            self._prev = (t_dev, counts)
            return None
        t0, c0 = self._prev
        dt = t_dev - t0
        if dt <= 0 or dt > 1.0:
            self.bad_dt += 1
            self._prev = (t_dev, counts)
            return None
        dc = np.array([((c - p + (1 << 31)) % COUNT_MOD) - (1 << 31) for c, p in zip(counts, c0, strict=True)],
                      dtype=float)
        omega = dc * (2.0 * math.pi / self.robot.counts_per_rev) / dt
        twist = np.asarray(self._kin.forward(omega), dtype=float)
        if not self.plausible(twist):
            self.implausible_twist += 1
            self._rejected_in_row += 1
            if self._rejected_in_row >= REBASE_AFTER:
                self.counts_rebased += 1
                self._rejected_in_row = 0
                self._prev = (t_dev, counts)
            return None
        self._rejected_in_row = 0
        self._prev = (t_dev, counts)
        self._pose = compose1(self._pose, se2_exp(twist * dt))
        return Odometry(stamp=stamp, twist=twist, twist_cov=None if self.twist_cov is None else self.twist_cov.copy(),
                        pose=self._pose.copy())


class SerialLink(SensorThread):
    """Reader thread on a pyserial URL (or an already open port object)."""

    role = "reader"
    thread_name = "serial-link"

    def __init__(
        self,
        url: str | None,
        converter: FrameConverter,
        on_message: Callable[[str, object, float], None],
        baudrate: int = 115200,
        port: Any = None,
        backoff_min_s: float = 0.1,
        backoff_max_s: float = 2.0,
        on_event: Callable[[str], None] | None = None,
    ) -> None:
        super().__init__(on_event, backoff_min_s, backoff_max_s)
        self.url = url
        self.converter = converter
        self.parser = FrameParser()
        self.on_message = on_message
        self.baudrate = baudrate
        self._port = port
        self.opens = 0
        self.open_failures = 0
        self.disconnects = 0
        self.internal_errors = 0

    @property
    def label(self) -> str:
        return f"serial {self.url}"

    def feed(self, data: bytes, arrival: float) -> int:
        """Parse bytes and dispatch messages; returns the number of frames decoded.

        Never raises: an unexpected exception while parsing a chunk or converting a frame
        (a bug, not bad input: bad input is counted by the parser and the converter) is
        counted in ``internal_errors``, reported the first few times, and the stream goes on.
        """
        try:
            frames = self.parser.feed(data)
        except Exception as e:  # noqa: BLE001 - a parser bug must not stop the serial link
            self.parser.reset_buffer()
            self._internal_error("chunk", e)
            return 0
        for f in frames:
            try:
                msgs = self.converter.convert(f, arrival)
            except Exception as e:  # noqa: BLE001
                self._internal_error(f"frame seq {f.seq}", e)
                continue
            for kind, msg in msgs:
                self.on_message(kind, msg, arrival)
            if self.converter.clock_steps:
                for step in self.converter.clock_steps:
                    self.on_event(f"{self.label}: MCU {step.describe()}")
                self.converter.clock_steps.clear()
        return len(frames)

    def _internal_error(self, what: str, e: Exception) -> None:
        self.internal_errors += 1
        if self.internal_errors <= 3:
            self.on_event(f"{self.label}: {what} skipped ({type(e).__name__}: {e})")
        log.debug("serial %s", what, exc_info=True)

    def counters(self) -> dict[str, Any]:
        """Every serial counter (parser, converter, link), for the status line and the summary."""
        return {**self.parser.stats.as_dict(), **self.converter.counters(), "disconnects": self.disconnects,
                "internal_errors": self.internal_errors, "thread_failure": self.failure}

    def _open(self) -> Any:
        if self._port is not None:
            return self._port
        import serial

        return serial.serial_for_url(self.url, baudrate=self.baudrate, timeout=0.05)

    def serve(self) -> None:
        """The reader loop (open, read, reopen) until :meth:`stop`; runs in the thread."""
        import serial

        backoff = self.backoff_min_s
        while not self.stop_event.is_set():
            try:
                port = self._open()
            except (serial.SerialException, OSError, ValueError) as e:
                self.open_failures += 1
                backoff = self.retry_later(self.open_failures, f"open failed ({e})", backoff)
                continue
            backoff = self.backoff_min_s
            self.opens += 1
            if self.parser.pending >= len(SYNC):
                # a frame cut by the disconnect (unplugged, port closed): its rest is never coming, and
                # joined to the new port's first bytes it would fail its CRC and count as line corruption
                self.parser.stats.truncated += 1
                self.parser.reset_buffer()
            self.connected = True
            self.on_event(f"serial {self.url or port}: open")
            try:
                while not self.stop_event.is_set():
                    n = getattr(port, "in_waiting", 0) or 1
                    data = port.read(min(max(n, 1), 4096))
                    if data:
                        self.feed(data, time.time())
            except (serial.SerialException, OSError) as e:
                self.disconnects += 1
                self.on_event(f"{self.label}: lost ({e}); reopening")
                self._port = None if self.url else self._port
            finally:
                self.connected = False
                if self.url:
                    try:
                        port.close()
                    except Exception:  # noqa: BLE001 - a dying port may raise anything
                        pass
            if self._port is not None and not self.url:
                # an externally supplied port that failed: nothing to reopen
                if self.stop_event.is_set():
                    break
                self.stop_event.wait(backoff)
