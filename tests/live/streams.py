"""Synthetic sensor streams for the live tests (no simulator needed)."""

from __future__ import annotations

import math

import numpy as np

from fgloc.types import CompassHeading, LaserScan, Odometry


def synthetic_messages(duration: float = 4.0, t0: float = 100.0) -> list[tuple[str, object]]:
    """A robot on a curved path: /odom 50 Hz, /imu 20 Hz, /scan 25 Hz (541 beams), time-ordered."""
    out: list[tuple[str, object]] = []
    for k in range(int(duration * 50)):
        t = t0 + k / 50
        tw = np.array([0.6 + 0.2 * math.sin(t), 0.1 * math.cos(0.5 * t), 0.3 * math.sin(0.7 * t)])
        out.append(("/odom", Odometry(t, tw)))
    for k in range(int(duration * 20)):
        t = t0 + k / 20 + 0.003
        out.append(("/imu", CompassHeading(t, math.remainder(0.4 * t, 2 * math.pi), 0.05, 1e-4, 1e-5)))
    rng = np.random.default_rng(0)
    for k in range(int(duration * 25)):
        t = t0 + k / 25 + 0.001
        r = rng.uniform(0.6, 20.0, 541).astype(np.float32)
        r[::23] = np.inf
        out.append(("/scan", LaserScan(t, math.radians(-135), math.radians(0.5), 0.5, 50.0, r, scan_time=0.04)))
    out.sort(key=lambda tm: tm[1].stamp)  # type: ignore[attr-defined]
    return out


def world(duration: float = 12.0, seed: int = 0, t0: float = 1000.0, laser: dict | None = None):
    """A small room map and a drive through it: ``(map, mount, ground_truth, messages)``.

    /odom 50 Hz (noisy twist), /imu 20 Hz (compass with a 0.3 rad offset), /scan 25 Hz
    ray-cast on the map (541 beams, 270 deg, 8 mm noise, beam timing 1/18 kHz).  ``laser``
    overrides the scan geometry: ``start_deg``, ``step_deg``, ``n``, ``hz``, ``beam_dt_s``,
    ``range_max_m``, ``noise_m`` (e.g. a TiM571's -135 / 0.3333 / 811 / 15 / 1/16200 / 25).
    """
    from fgloc.geometry import compose
    from fgloc.testing.soak import room_map
    from fgloc.types import StaticTransform, Trajectory

    occ = room_map()
    mount = StaticTransform("base_link", "laser", np.array([0.15, 0.0, 0.0]))
    rng = np.random.default_rng(seed)
    dt = 0.01
    ts = np.arange(0.0, duration, dt)
    poses = np.zeros((len(ts), 3))
    twists = np.zeros((len(ts), 3))
    p = np.array([2.0, 2.0, 0.0])
    for i, t in enumerate(ts):
        tw = np.array([0.5, 0.05 * math.sin(t), 0.25 * math.sin(0.3 * t)])
        poses[i], twists[i] = p, tw
        p = compose(p, tw * dt)
    msgs: list[tuple[str, object]] = []
    lz = {"start_deg": -135.0, "step_deg": 0.5, "n": 541, "hz": 25.0, "beam_dt_s": 1 / 18000, "range_max_m": 20.0,
          "noise_m": 0.008, **(laser or {})}
    ang = math.radians(lz["start_deg"]) + math.radians(lz["step_deg"]) * np.arange(int(lz["n"]))
    n_scans = 0
    for i, t in enumerate(ts):
        if i % 2 == 0:
            msgs.append(("/odom", Odometry(t0 + t, twists[i] + rng.normal(0, 0.005, 3))))
        if i % 5 == 0:
            yaw = math.remainder(poses[i, 2] + 0.3 + rng.normal(0, 0.005), 2 * math.pi)
            msgs.append(("/imu", CompassHeading(t0 + t, yaw, float(twists[i, 2]))))
        while n_scans / lz["hz"] < t + dt - 1e-9:  # the scans due in this tick, at their exact times
            ts_scan = n_scans / lz["hz"]
            lp = compose(compose(poses[i], twists[i] * (ts_scan - t)), mount.pose)
            r = occ.raycast(lp[:2], lp[2] + ang, lz["range_max_m"])
            r = (r + rng.normal(0, lz["noise_m"], len(r)) * np.isfinite(r)).astype(np.float32)
            msgs.append(("/scan", LaserScan(t0 + ts_scan, math.radians(lz["start_deg"]), math.radians(lz["step_deg"]),
                                            0.05, lz["range_max_m"], r, time_increment=lz["beam_dt_s"],
                                            scan_time=1.0 / lz["hz"])))
            n_scans += 1
    msgs.sort(key=lambda tm: tm[1].stamp)  # type: ignore[attr-defined]
    return occ, mount, Trajectory(ts + t0, poses), msgs
