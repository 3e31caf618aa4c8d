"""A small synthetic world for front-end tests (independent of the simulator)."""

from __future__ import annotations

import numpy as np

from fgloc.geometry import compose
from fgloc.maps import OccupancyMap
from fgloc.types import LaserScan, StaticTransform

MOUNT = StaticTransform("base_link", "laser", np.array([0.15, 0.0, 0.0]))


def make_map(resolution: float = 0.05) -> OccupancyMap:
    """A 16 m x 10 m room with an inner wall, pillars and boxes; unknown outside the walls."""
    w, h = int(round(17.0 / resolution)), int(round(11.0 / resolution))
    data = np.full((h, w), -1, dtype=np.int16)

    def cells(x0: float, y0: float, x1: float, y1: float) -> tuple[slice, slice]:
        return slice(int(round(y0 / resolution)), int(round(y1 / resolution))), slice(
            int(round(x0 / resolution)), int(round(x1 / resolution))
        )

    data[cells(0.5, 0.5, 16.5, 10.5)] = 100
    data[cells(0.6, 0.6, 16.4, 10.4)] = 0
    data[cells(6.0, 0.6, 6.1, 6.0)] = 100       # inner wall with a door gap above y=6
    data[cells(10.0, 4.0, 10.6, 4.6)] = 100     # pillar
    data[cells(3.0, 7.5, 4.2, 8.1)] = 100       # box
    data[cells(12.0, 8.0, 14.5, 8.3)] = 100     # shelf
    data[cells(13.0, 1.5, 13.4, 3.5)] = 100     # cabinet
    # the scans are ray cast on this very grid: the map has no registration error
    return OccupancyMap(data, resolution, origin=np.array([-1.0, -2.0, 0.0]), accuracy_m=0.0)


def make_scan(
    m: OccupancyMap,
    pose: np.ndarray,
    rng: np.random.Generator | None = None,
    n_beams: int = 541,
    fov_deg: float = 270.0,
    range_max: float = 20.0,
    range_sigma: float = 0.008,
    mount: StaticTransform = MOUNT,
    stamp: float = 0.0,
) -> LaserScan:
    """A static scan by exact ray casting from ``pose`` (base_link in map), Gaussian range noise."""
    rng = rng or np.random.default_rng(0)
    fov = np.radians(fov_deg)
    inc = fov / (n_beams - 1)
    angles = -fov / 2 + inc * np.arange(n_beams)
    lp = compose(pose, mount.pose)
    r = m.raycast(lp[:2], lp[2] + angles, range_max)
    r = r + rng.normal(0.0, range_sigma, n_beams) * np.isfinite(r)
    return LaserScan(stamp, -fov / 2, inc, 0.05, range_max, r.astype(np.float32), time_increment=0.0, scan_time=0.04)


def free_poses(m: OccupancyMap, n: int, rng: np.random.Generator, clearance: float = 0.5) -> np.ndarray:
    """``n`` random poses in free space at least ``clearance`` from obstacles."""
    out = []
    x0, x1, y0, y1 = m.extent
    while len(out) < n:
        p = np.array([rng.uniform(x0, x1), rng.uniform(y0, y1), rng.uniform(-np.pi, np.pi)])
        if m.is_free(p[None, :2])[0] and m.distance_at(p[None, :2])[0] > clearance:
            out.append(p)
    return np.array(out)


def make_moving_scan(
    m: OccupancyMap,
    pose0: np.ndarray,
    twist: np.ndarray,
    rng: np.random.Generator | None = None,
    n_beams: int = 541,
    fov_deg: float = 270.0,
    scan_period: float = 0.04,
    range_max: float = 20.0,
    range_sigma: float = 0.008,
    mount: StaticTransform = MOUNT,
    stamp: float = 0.0,
) -> LaserScan:
    """A motion-distorted scan: beam ``i`` cast from the pose at ``stamp + i * time_increment``
    while the robot moves at the constant body ``twist`` [vx, vy, wz] from ``pose0`` (first beam)."""
    from fgloc.geometry import exp_along

    rng = rng or np.random.default_rng(0)
    fov = np.radians(fov_deg)
    inc = fov / (n_beams - 1)
    t_inc = scan_period * (fov_deg / 360.0) / (n_beams - 1)
    angles = -fov / 2 + inc * np.arange(n_beams)
    offs = exp_along(np.asarray(twist, dtype=float), t_inc * np.arange(n_beams))
    poses = compose(pose0[None, :], offs)
    lp = compose(poses, mount.pose[None, :])
    r = m.raycast(lp[:, :2], lp[:, 2] + angles, range_max)
    r = r + rng.normal(0.0, range_sigma, n_beams) * np.isfinite(r)
    return LaserScan(stamp, -fov / 2, inc, 0.05, range_max, r.astype(np.float32), time_increment=t_inc,
                     scan_time=scan_period)
