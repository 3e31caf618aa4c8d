"""Assemble a live session: config -> serial link + laser client + localizer + outputs.

:class:`LiveSession` is what ``fgloc live`` runs and what the end-to-end tests drive
(``start()``, ``runner.run(...)``, ``close()``).  ``close()`` stops the sensor
threads, fuses what is still queued, closes the recording (a valid MCAP) and
returns the summary.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fgloc.errors import ConfigError
from fgloc.live.config import HealthConfig, LaserConfig, SerialConfig  # noqa: F401 - their home before
from fgloc.live.serial_link import FrameConverter, SerialLink
from fgloc.types import StaticTransform, Trajectory

if TYPE_CHECKING:
    from fgloc.config import FglocConfig
    from fgloc.live.sick import SickClient

def load_config(path: str | Path | None = None, overrides: dict[str, Any] | None = None) -> FglocConfig:
    """The one fgloc config (:func:`fgloc.config.load_config`); kept here for old callers."""
    from fgloc.config import load_config as load

    return load(path, overrides)


def parse_host_port(s: str) -> tuple[str, int]:
    host, sep, port = s.rpartition(":")
    if not sep or not host or not port.isdigit():
        raise ConfigError(f"--laser {s}: expected HOST:PORT (e.g. 192.168.0.1:2111)")
    return host, int(port)


@dataclass
class LiveSummary:
    duration_s: float
    counters: dict[str, Any]
    health: dict[str, str]
    latency_p50_ms: float
    latency_p99_ms: float
    n_poses: int
    events: list[str]


class LiveSession:
    """Serial + laser + localizer + recorder + publisher, wired through a :class:`LiveRunner`."""

    def __init__(
        self,
        localizer: Any,
        serial_url: str | None,
        laser: str | None,
        config: FglocConfig | None = None,
        record: str | Path | None = None,
        publish: list[str] | None = None,
        status_sink: Any = None,
        event_sink: Any = None,
        serial_port: Any = None,
    ) -> None:
        # here, not at the top: every command's config (fgloc.config's live sections) imports this module
        from fgloc.config import parse_config
        from fgloc.live.publish import UdpPublisher
        from fgloc.live.runner import LiveRunner
        from fgloc.live.sick import SickClient

        cfg = parse_config(config)
        self.cfg = cfg
        robot = cfg.robot
        sc, lc = cfg.serial, cfg.laser
        mount = np.asarray(lc.mount, dtype=float)
        self.laser_mount = StaticTransform("base_link", "laser", mount)
        self.recorder: Any = None
        self.record_path = Path(record) if record else None
        if record:
            from fgloc.io.mcap_writer import LogWriter

            self.recorder = LogWriter(str(record))
            if hasattr(self.recorder, "__enter__"):
                self.recorder.__enter__()
        self.publisher = UdpPublisher(publish) if publish else None
        self.events: list[str] = []

        def ev(msg: str) -> None:
            self.events.append(f"{time.strftime('%H:%M:%S')} {msg}")
            if event_sink is not None:
                event_sink(msg)

        self.runner = LiveRunner(
            localizer, recorder=self.recorder, publisher=self.publisher, status_sink=status_sink,
            event_sink=ev, laser_mount=self.laser_mount,
            silence_s=cfg.health.silence_s,
        )
        ts, cs, gs = sc.twist_std, sc.compass_std_deg, sc.gyro_std_dps
        conv = FrameConverter(
            robot,
            compass_clockwise=sc.compass_clockwise,
            twist_var=None if ts is None else (ts[0] ** 2, ts[1] ** 2, ts[2] ** 2),
            yaw_var=float("nan") if cs is None else math.radians(cs) ** 2,
            yaw_rate_var=float("nan") if gs is None else math.radians(gs) ** 2,
            align_clock=sc.align_clock,
        )
        self.serial: SerialLink | None = None
        if serial_url or serial_port is not None:
            self.serial = SerialLink(serial_url, conv, self.runner.push, baudrate=sc.baudrate,
                                     port=serial_port, on_event=ev)
            self.runner.sources["serial"] = self.serial.counters
        self.laser: SickClient | None = None
        if laser:
            host, port = parse_host_port(laser)
            self.laser = SickClient(
                host, port, on_scan=lambda scan, arrival: self.runner.push("scan", scan, arrival),
                range_min=lc.range_min_m, range_max=lc.range_max_m, angle_offset_deg=lc.angle_offset_deg,
                time_increment_from=lc.time_increment_from, align_clock=lc.align_clock,
                stall_timeout_s=lc.stall_timeout_s, on_event=ev, layer_field=lc.layer_field,
                start_measurement=lc.start_measurement,
            )
            self.runner.sources["laser"] = self.laser.counters
        self._t0 = time.monotonic()
        self.closed = False
        self.smoothed: Trajectory | None = None  # Localizer.finish() at close (fixed-lag / batch result)

    def start(self) -> None:
        self._t0 = time.monotonic()
        if self.serial is not None:
            self.serial.start()
        if self.laser is not None:
            self.laser.start()

    def live_trajectory(self) -> Trajectory:
        return self.runner.live_trajectory()

    def close(self) -> LiveSummary:
        """Stop sensors, fuse the backlog, close the recording; idempotent."""
        if not self.closed:
            self.closed = True
            if self.laser is not None:
                self.laser.stop()
            if self.serial is not None:
                self.serial.stop()
            self.runner.drain()
            try:
                self.smoothed = self.runner.loc.finish()
            except Exception as e:  # noqa: BLE001 - the live trajectory is already safe
                self.events.append(f"smoothing at shutdown failed: {type(e).__name__}: {e}")
            if self.recorder is not None:
                if hasattr(self.recorder, "__exit__"):
                    self.recorder.__exit__(None, None, None)
                elif hasattr(self.recorder, "close"):
                    self.recorder.close()
            if self.publisher is not None:
                self.publisher.close()
        p50, p99 = self.runner.latency_percentiles()
        return LiveSummary(
            duration_s=time.monotonic() - self._t0,
            counters=self.runner.all_counters(),
            health=self.runner.health_states(),
            latency_p50_ms=p50,
            latency_p99_ms=p99,
            n_poses=len(self.runner.live_stamps),
            events=list(self.events),
        )
