"""Scan-to-map tracking on a finished map (a check that a built map supports localization).

Each scan is predicted with the odometry increment, searched over a small
correlative window and refined by Gauss-Newton against the distance field of the
map's occupied cells.  No filtering and no relocalization: a baseline for the
real localizer (``fgloc run``), and a test of the map itself.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from fgloc.geometry import between, compose, transform_points
from fgloc.mapping.occupancy import scan_endpoints
from fgloc.mapping.scanmatch import build_distance_grid, correlative_search, refine, voxel_subsample
from fgloc.mapping.source import ScanRecord
from fgloc.maps import OccupancyMap
from fgloc.types import FloatArray, StaticTransform, Trajectory


def track_on_map(records: Sequence[ScanRecord], occ: OccupancyMap, mount: StaticTransform,
                 initial_pose: FloatArray, max_range_m: float = 25.0, window_m: float = 0.15,
                 window_deg: float = 5.0, min_inliers: float = 0.5) -> tuple[Trajectory, dict]:
    """Poses (map frame) of every scan; ``stats`` counts matched and odometry-only scans."""
    rows, cols = np.nonzero(occ.occupied)
    centers = np.column_stack([(cols + 0.5) * occ.resolution, (rows + 0.5) * occ.resolution])
    world = transform_points(occ.origin, centers)
    grid = build_distance_grid(world, min(occ.resolution, 0.05), 0.3, 0.5)
    mnt = np.asarray(mount.pose, dtype=float)
    pose = np.asarray(initial_pose, dtype=float).copy()
    odom_prev = None
    stamps, poses = [], []
    stats = {"scans": 0, "matched": 0, "odometry_only": 0}
    for rec in records:
        stats["scans"] += 1
        if odom_prev is not None:
            pose = compose(pose, between(odom_prev, rec.odom))
        odom_prev = rec.odom
        sc = rec.scan
        ends, hit = scan_endpoints(sc.ranges, sc.angles, sc.range_min, sc.range_max, max_range_m, 8.0)
        pts = voxel_subsample(transform_points(mnt, ends[hit]), 0.05)
        ok = False
        if len(pts) >= 20:
            sr = correlative_search(grid, pts, pose, window_m, np.radians(window_deg), 0.03, np.radians(1.0), 0.05)
            rr = refine(grid, pts, sr.pose)
            if rr.inlier_frac >= min_inliers:
                pose = rr.pose
                ok = True
        stats["matched" if ok else "odometry_only"] += 1
        stamps.append(rec.stamp)
        poses.append(pose.copy())
    return Trajectory.from_unsorted(np.array(stamps), np.array(poses)), stats
