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
