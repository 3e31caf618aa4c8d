"""Assemble a live session: config -> serial link + laser client + localizer + outputs.

:class:`LiveSession` is what ``fgloc live`` runs and what the end-to-end tests drive
(``start()``, ``runner.run(...)``, ``close()``).  ``close()`` stops the sensor
threads, fuses what is still queued, closes the recording (a valid MCAP) and
returns the summary.
"""

from __future__ import annotations

import copy
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from fgloc.errors import ConfigError
from fgloc.live.publish import UdpPublisher
from fgloc.live.runner import LiveRunner
from fgloc.live.serial_link import FrameConverter, RobotParams, SerialLink
from fgloc.live.sick import SickClient
from fgloc.types import StaticTransform, Trajectory

DEFAULT_CONFIG = Path(__file__).resolve().parents[2] / "config" / "live.yaml"

_BUILTIN: dict[str, Any] = {
    "robot": {"drive": "mecanum", "wheel_radius_m": 0.076, "track_width_m": 0.56, "wheelbase_m": 0.50,
              "counts_per_rev": 2000},
    "serial": {"baudrate": 115200, "align_clock": True, "compass_clockwise": False,
               "twist_std": None, "compass_std_deg": None, "gyro_std_dps": None},
    "laser": {"range_min_m": 0.5, "range_max_m": 50.0, "angle_offset_deg": -90.0, "align_clock": True,
              "stall_timeout_s": 1.0, "mount": [0.0, 0.0, 0.0],
              "time_increment_from": "measurement_frequency"},
    "health": {"silence_s": 0.4},
    "localizer": {},
}


def _merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    out = copy.deepcopy(base)
    for k, v in (over or {}).items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = _merge(out[k], v)
        else:
            out[k] = v
    return out


def load_config(path: str | Path | None = None, overrides: dict[str, Any] | None = None) -> dict[str, Any]:
    """Built-in defaults, then ``config/live.yaml`` (if present), then ``path``, then overrides."""
    cfg = copy.deepcopy(_BUILTIN)
    for p in ([DEFAULT_CONFIG] if DEFAULT_CONFIG.is_file() else []) + ([Path(path)] if path else []):
        try:
            data = yaml.safe_load(Path(p).read_text()) or {}
        except FileNotFoundError:
            raise ConfigError(f"{p}: config file not found") from None
        except yaml.YAMLError as e:
            raise ConfigError(f"{p}: invalid YAML ({str(e).splitlines()[0]})") from None
        if not isinstance(data, dict):
            raise ConfigError(f"{p}: expected a mapping at the top level")
        cfg = _merge(cfg, data)
    return _merge(cfg, overrides or {})


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
        config: dict[str, Any] | None = None,
        record: str | Path | None = None,
        publish: list[str] | None = None,
        status_sink: Any = None,
        event_sink: Any = None,
        serial_port: Any = None,
    ) -> None:
        cfg = config if config is not None else load_config()
        self.cfg = cfg
        robot = RobotParams.from_dict(cfg.get("robot"))
        sc, lc = cfg.get("serial", {}), cfg.get("laser", {})
        mount = np.asarray(lc.get("mount", [0, 0, 0]), dtype=float)
        self.laser_mount = StaticTransform("base_link", "laser", mount)
        self.recorder: Any = None
        self.record_path = Path(record) if record else None
        if record:
            from fgloc.io.log import LogWriter

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
            silence_s=float(cfg.get("health", {}).get("silence_s", 0.4)),
        )
        ts, cs, gs = sc.get("twist_std"), sc.get("compass_std_deg"), sc.get("gyro_std_dps")
        conv = FrameConverter(
            robot,
            compass_clockwise=bool(sc.get("compass_clockwise", False)),
            twist_var=None if ts is None else tuple(float(v) ** 2 for v in ts),  # type: ignore[arg-type]
            yaw_var=float("nan") if cs is None else math.radians(float(cs)) ** 2,
            yaw_rate_var=float("nan") if gs is None else math.radians(float(gs)) ** 2,
            align_clock=bool(sc.get("align_clock", True)),
        )
        self.serial: SerialLink | None = None
        if serial_url or serial_port is not None:
            self.serial = SerialLink(serial_url, conv, self.runner.push, baudrate=int(sc.get("baudrate", 115200)),
                                     port=serial_port, on_event=ev)
            self.runner.sources["serial"] = self.serial.counters
        self.laser: SickClient | None = None
        if laser:
            host, port = parse_host_port(laser)
            self.laser = SickClient(
                host, port, on_scan=lambda scan, arrival: self.runner.push("scan", scan, arrival),
                range_min=float(lc.get("range_min_m", 0.5)), range_max=float(lc.get("range_max_m", 50.0)),
                angle_offset_deg=float(lc.get("angle_offset_deg", -90.0)),
                time_increment_from=str(lc.get("time_increment_from", "measurement_frequency")),
                align_clock=bool(lc.get("align_clock", True)),
                stall_timeout_s=float(lc.get("stall_timeout_s", 1.0)), on_event=ev,
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
