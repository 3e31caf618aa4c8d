"""Synthetic trajectories for the evaluation tests."""

from __future__ import annotations

import numpy as np

from fgloc.types import Trajectory


def straight(theta: float = np.radians(30.0), speed: float = 0.8, duration: float = 10.0,
             rate: float = 100.0, heading: float | None = None, t0: float = 100.0) -> Trajectory:
    """A straight run along direction ``theta`` (heading ``theta`` unless given: mecanum sideways)."""
    t = t0 + np.arange(int(duration * rate) + 1) / rate
    s = speed * (t - t0)
    yaw = np.full_like(t, theta if heading is None else heading)
    return Trajectory(t, np.column_stack([s * np.cos(theta), s * np.sin(theta), yaw]))


def rectangle(width: float = 25.0, height: float = 14.0, speed: float = 0.8, rate: float = 100.0) -> Trajectory:
    """The paper's kind of route: a rectangle, heading turning instantly at the corners."""
    corners = np.array([[0, 0], [width, 0], [width, height], [0, height], [0, 0]], float)
    pts, yaws = [], []
    for a, b in zip(corners[:-1], corners[1:], strict=True):
        n = int(np.linalg.norm(b - a) / (speed / rate))
        f = np.arange(n)[:, None] / n
        pts.append(a + f * (b - a))
        yaws.append(np.full(n, np.arctan2(b[1] - a[1], b[0] - a[0])))
    p = np.vstack(pts)
    return Trajectory(np.arange(len(p)) / rate, np.column_stack([p, np.concatenate(yaws)]))
