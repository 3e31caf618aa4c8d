"""Small generated worlds, drives and logs for the mapping tests (seconds, not minutes).

A ring corridor (24 m x 16 m outside, 3 m wide) with pillars and wall niches at irregular places,
so that a position along a corridor is observable; a robot drives laps around it and a 180-beam
laser (CARMEN FLASER layout, 1 deg steps from -90 deg) is ray-cast in the rasterized world.
"""

from __future__ import annotations

import bz2
from pathlib import Path

import numpy as np

from fgloc.mapping.source import ScanRecord
from fgloc.maps import OccupancyMap
from fgloc.types import LaserScan, Trajectory

RES = 0.05
EXTENT = (-2.0, -2.0, 26.0, 18.0)  # xmin, ymin, xmax, ymax
PILLARS = [(5.2, 0.55), (9.7, 2.4), (14.1, 0.5), (18.9, 2.45), (23.4, 5.3), (21.6, 9.1), (23.5, 12.6),
           (17.3, 15.5), (11.8, 13.6), (6.4, 15.45), (0.6, 11.2), (2.4, 6.9), (0.55, 3.7)]
NICHES = [(7.0, -0.6, 8.2, 0.0), (16.0, 16.0, 17.0, 16.7), (24.0, 8.0, 24.6, 9.3), (-0.6, 8.5, 0.0, 9.2),
          (12.0, 2.9, 13.5, 3.0)]


def world_grid(pillars=PILLARS, extra_boxes=(), removed=()) -> OccupancyMap:
    """The ring world as a trinary map (occupied walls/pillars, free elsewhere)."""
    x0, y0, x1, y1 = EXTENT
    w, h = int(round((x1 - x0) / RES)), int(round((y1 - y0) / RES))
    xs = x0 + (np.arange(w) + 0.5) * RES
    ys = y0 + (np.arange(h) + 0.5) * RES
    X, Y = np.meshgrid(xs, ys)
    inside_outer = (X > 0) & (X < 24) & (Y > 0) & (Y < 16)
    inside_inner = (X > 3) & (X < 21) & (Y > 3) & (Y < 13)
    free = inside_outer & ~inside_inner
    for a, b, c, d in NICHES:
        free |= (X > a) & (X < c) & (Y > b) & (Y < d)
    occ = ~free
    for i, (px, py) in enumerate(pillars):
        if i in removed:
            continue
        occ |= (np.abs(X - px) < 0.2) & (np.abs(Y - py) < 0.2)
    for bx0, by0, bx1, by1 in extra_boxes:
        occ |= (X > bx0) & (X < bx1) & (Y > by0) & (Y < by1)
    data = np.where(occ, 100, 0).astype(np.int16)
    return OccupancyMap(data=data, resolution=RES, origin=np.array([x0, y0, 0.0]))


def ring_drive(laps: int = 3, speed: float = 0.6, dt: float = 0.5, lane_shift: float = 0.35) -> Trajectory:
    """Poses every ``dt`` s driving ``laps`` laps around the ring (each lap in its own lane),
    turning in place at the corners."""
    stamps, poses = [], []
    t = 1000.0
    for lap in range(laps):
        o = 1.5 + (lap - (laps - 1) / 2) * lane_shift
        corners = [(o, o), (24 - o, o), (24 - o, 16 - o), (o, 16 - o), (o, o)]
        for (ax, ay), (bx, by) in zip(corners[:-1], corners[1:], strict=True):
            yaw = float(np.arctan2(by - ay, bx - ax))
            if poses:  # turn in place to the new heading
                y0 = poses[-1][2]
                dy = (yaw - y0 + np.pi) % (2 * np.pi) - np.pi
                for f in np.linspace(0, 1, 5)[1:]:
                    t += dt
                    stamps.append(t)
                    poses.append([ax, ay, y0 + f * dy])
            n = max(int(np.hypot(bx - ax, by - ay) / (speed * dt)), 1)
            for f in np.arange(n) / n:
                t += dt
                stamps.append(t)
                poses.append([ax + f * (bx - ax), ay + f * (by - ay), yaw])
    return Trajectory(np.array(stamps), np.array(poses))


def scan_at(world: OccupancyMap, pose, stamp: float, noise_m: float = 0.005, rng=None) -> LaserScan:
    ang = -np.pi / 2 + np.arange(180) * np.pi / 180.0
    r = world.raycast(np.asarray(pose[:2]), ang + pose[2], 30.0)
    if rng is not None and noise_m > 0:
        r = r + rng.normal(0.0, noise_m, r.shape)
    return LaserScan(stamp=float(stamp), angle_min=-np.pi / 2, angle_increment=np.pi / 180.0, range_min=0.02,
                     range_max=30.0, ranges=np.asarray(r, dtype=np.float32))


def records(world: OccupancyMap, traj: Trajectory, seed: int = 0) -> list[ScanRecord]:
    rng = np.random.default_rng(seed)
    return [ScanRecord(float(t), p.copy(), scan_at(world, p, t, rng=rng), i)
            for i, (t, p) in enumerate(zip(traj.stamps, traj.poses, strict=True))]


def write_carmen(path: Path, ranges: list[np.ndarray], odom: np.ndarray, stamps: np.ndarray,
                 no_return_m: float = 81.91) -> Path:
    """A CARMEN log: ODOM and FLASER lines (ranges >= no_return_m or inf written as no return)."""
    lines = ["PARAM robot_frontlaser_offset 0.0 nohost 0\n"]
    for r, p, t in zip(ranges, odom, stamps, strict=True):
        rr = np.where(np.isfinite(r) & (np.asarray(r) < no_return_m), r, no_return_m)
        x, y, th = (float(v) for v in p)
        lines.append(f"ODOM {x:.4f} {y:.4f} {th:.5f} 0 0 0 {t - 0.01:.4f} synth {t - 0.01:.4f}\n")
        lines.append(f"FLASER {len(rr)} " + " ".join(f"{v:.3f}" for v in rr)
                     + f" {x:.4f} {y:.4f} {th:.5f} {x:.4f} {y:.4f} {th:.5f} {t:.4f} synth {t:.4f}\n")
    with bz2.open(path, "wt") as f:
        f.writelines(lines)
    return path


def odometry_of(traj: Trajectory, seed: int = 0, drift_yaw_per_m: float = 0.002) -> np.ndarray:
    """Wheel odometry along ``traj``: the true increments with a small heading drift and noise."""
    from fgloc.geometry import between, compose

    rng = np.random.default_rng(seed)
    out = [np.zeros(3)]
    for a, b in zip(traj.poses[:-1], traj.poses[1:], strict=True):
        d = between(a, b)
        dist = float(np.hypot(d[0], d[1]))
        d = d + np.array([rng.normal(0, 0.005 * dist), rng.normal(0, 0.005 * dist),
                          drift_yaw_per_m * dist + rng.normal(0, 0.002)])
        out.append(compose(out[-1], d))
    return np.array(out)
