"""Replay a run through the emulators into a live session (tests, benchmarks, demos).

``replay_live`` starts :class:`EmulatorPair` (STM32 on a pty or socket, SICK on TCP),
a :class:`LiveSession` reading them, runs until the replay is over and returns the
live trajectory mapped back to run time, so it can be compared with the run's ground
truth and with ``fgloc run`` on the same log.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fgloc.config import load_config
from fgloc.live.app import LiveSession, LiveSummary
from fgloc.live.serial_link import RobotParams
from fgloc.testing.emulators import EmulatorPair, ReplayClock
from fgloc.types import CompassHeading, Imu, LaserScan, Odometry, StaticTransform, Trajectory


@dataclass
class LiveReplay:
    session: LiveSession
    summary: LiveSummary
    clock: ReplayClock
    live_host: Trajectory  # fused poses, host time
    live_run: Trajectory  # the same, stamps mapped back to run time
    smoothed_run: Trajectory | None  # Localizer.finish() at shutdown, run time
    emulators: EmulatorPair


def live_config_overrides(messages: list[tuple[str, object]], rp: RobotParams,
                          laser_mount: StaticTransform) -> dict[str, Any]:
    """The live config a robot that recorded ``messages`` would have: its geometry, laser mount and range
    limits, and its sensors' noise as a spec sheet would give it (a config overlay for ``load_config``)."""
    over: dict[str, Any] = {
        "robot": {"drive": rp.drive, "wheel_radius_m": rp.wheel_radius_m, "track_width_m": rp.track_width_m,
                  "wheelbase_m": rp.wheelbase_m, "counts_per_rev": rp.counts_per_rev},
        "laser": {"mount": [float(v) for v in laser_mount.pose]},
    }
    # the robot's sensor noise, as its spec sheet would give it to the live config
    odom = next((m for t, m in messages if t == "/odom" and isinstance(m, Odometry)), None)
    if odom is not None and odom.twist_cov is not None:
        over["serial"] = {"twist_std": [float(v) for v in np.sqrt(np.diag(odom.twist_cov))]}
    imu = next((m if isinstance(m, CompassHeading) else m.heading() for t, m in messages
                if t == "/imu" and isinstance(m, CompassHeading | Imu)), None)
    if imu is not None:
        ser = over.setdefault("serial", {})
        if np.isfinite(imu.yaw_var):
            ser["compass_std_deg"] = float(np.degrees(np.sqrt(imu.yaw_var)))
        if np.isfinite(imu.yaw_rate_var):
            ser["gyro_std_dps"] = float(np.degrees(np.sqrt(imu.yaw_rate_var)))
    scan = next((m for t, m in messages if t == "/scan" and isinstance(m, LaserScan)), None)
    if scan is not None:
        over["laser"]["range_min_m"] = float(scan.range_min)
        over["laser"]["range_max_m"] = float(scan.range_max)
    return over


def replay_live(
    messages: list[tuple[str, object]],
    occ_map: Any,
    laser_mount: StaticTransform,
    robot: dict[str, Any] | RobotParams | None = None,
    backend: str = "smoother",
    frontend: str = "native",
    initial_pose: np.ndarray | None = None,
    t_start: float | None = None,
    duration: float | None = None,
    speed: float = 1.0,
    mode: str = "pty",
    record: str | Path | None = None,
    publish: list[str] | None = None,
    live_overrides: dict[str, Any] | None = None,
    lead_s: float = 1.0,
    status_sink: Any = None,
    warmup: bool = True,
    sick_kw: dict[str, Any] | None = None,
    stm32_kw: dict[str, Any] | None = None,
) -> LiveReplay:
    """``sick_kw``: :class:`SickEmulator` keywords (a real device's telegram shape, DeviceIdent, clock steps,
    ...); ``stm32_kw``: :class:`Stm32Emulator` keywords (clock steps, corruption, ...)."""
    from fgloc.localization import build_session

    rp = robot if isinstance(robot, RobotParams) else RobotParams.from_dict(robot)
    over = live_config_overrides(messages, rp, laser_mount)
    cfg = load_config(overrides=over)
    if live_overrides:
        from fgloc.config import parse_config

        cfg = parse_config(live_overrides, source="overrides", base=cfg)
    if warmup and occ_map is not None:
        _warm_up(messages, occ_map, laser_mount, backend, frontend, initial_pose, cfg, t_start)
    session = build_session(occ_map, laser_mount, backend=backend, frontend=frontend, initial_pose=initial_pose,
                            config=cfg)
    pair = EmulatorPair.create(messages, rp, mode=mode, speed=speed, t_start=t_start, duration=duration,
                               lead_s=lead_s, sick_kw=sick_kw, stm32_kw=stm32_kw)
    sess = LiveSession(session, pair.stm32.url, pair.sick.address, config=cfg, record=record, publish=publish,
                       status_sink=status_sink)
    sess.start()
    if mode == "tcp":
        time.sleep(0.2)
    pair.start()
    sess.runner.run(until=lambda: pair.stm32.done.is_set() and pair.sick.done.is_set())
    sess.runner.run(duration=0.3)
    summary = sess.close()
    pair.stop()
    host = sess.live_trajectory()
    run = Trajectory(np.asarray(pair.clock.to_run(host.stamps)), host.poses) if len(host) else host
    sm = sess.smoothed
    sm_run = Trajectory(np.asarray(pair.clock.to_run(sm.stamps)), sm.poses) if sm is not None and len(sm) else None
    return LiveReplay(sess, summary, pair.clock, host, run, sm_run, pair)


def _warm_up(messages: list[tuple[str, object]], occ_map: Any, laser_mount: StaticTransform, backend: str,
             frontend: str, initial_pose: np.ndarray | None, config: Any, t_start: float | None) -> None:
    """Run a throwaway localizer over the first scans so JIT compilation (numba) and caches are
    done before the replay clock starts, as they would be on a robot that has run once before."""
    from fgloc.localization import build_session

    first: list[tuple[str, object]] = []
    n_scans = 0
    for topic, m in messages:
        if t_start is not None and float(getattr(m, "stamp", t_start)) < t_start:
            continue
        first.append((topic, m))
        n_scans += topic == "/scan"
        if n_scans >= 5:
            break
    build_session(occ_map, laser_mount, backend=backend, frontend=frontend, initial_pose=initial_pose,
                  config=config).run(first)
