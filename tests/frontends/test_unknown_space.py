"""Points the map cannot speak for (issue 13 item 5): a scan that looks into a room the map's passes
never saw (unknown cells) is still a fix when the rest of it fits; beams that cross a mapped wall
still count against a wrong pose."""

from __future__ import annotations

import numpy as np

from fgloc.frontends.native import NativeMatcher
from fgloc.maps import UNKNOWN, OccupancyMap

from .synth import MOUNT, make_map, make_scan


def _partial_map():
    full = make_map()
    data = full.data.copy()
    # the map never saw the right part of the room (x > 6.6 m in the map frame: its walls, pillar,
    # shelf and cabinet are unknown), as a SLAM map built from other passes
    j0 = int(round((6.6 - full.origin[0]) / full.resolution))
    data[:, j0:] = UNKNOWN
    return full, OccupancyMap(data, full.resolution, full.origin, accuracy_m=0.0)


def test_scan_into_an_unmapped_room_is_a_fix():
    full, part = _partial_map()
    pose = np.array([6.0, 3.0, 0.0])  # 0.6 m from the unknown part, looking into it
    scan = make_scan(full, pose, np.random.default_rng(2))
    fe = NativeMatcher(part, MOUNT, surface_depth_cells=0.0)
    r = fe.match(scan, pose + np.array([0.04, -0.03, 0.02]))
    assert r.ok, r.reason
    assert r.info["n_unknown"] > 0.5 * r.info["n_points"]   # measured 334 of 541
    assert r.quality < 0.4                                  # measured 0.38: counting every point, no fix
    assert np.hypot(*(r.pose[:2] - pose[:2])) < 0.01 and abs(r.pose[2] - pose[2]) < np.radians(0.3)


def test_beams_through_mapped_walls_still_count():
    full, part = _partial_map()
    # the robot is in the right room (unknown to the map) but guessed in the left one: its beams
    # cross the mapped inner wall into what the map says is wall or unknown: no fix
    truth = np.array([11.0, 2.0, 2.5])
    scan = make_scan(full, truth, np.random.default_rng(4))
    fe = NativeMatcher(part, MOUNT, surface_depth_cells=0.0)
    r = fe.match(scan, np.array([3.0, 2.0, 2.5]))
    assert not r.ok


def test_a_laser_off_the_mapped_free_space_gets_no_exemption():
    """The scan of the first test, with the map's cells under the laser (0.15 m ahead of the base,
    which stays on free space) unknown, as where a prediction gone metres off puts it: the beams
    ending in unknown space count again, and with them the fit is too poor for a fix."""
    full, part = _partial_map()
    pose = np.array([6.0, 3.0, 0.0])
    scan = make_scan(full, pose, np.random.default_rng(2))
    data = part.data.copy()
    r0 = int(round((pose[1] - part.origin[1]) / part.resolution))
    cl = int(round((pose[0] + MOUNT.pose[0] - part.origin[0]) / part.resolution))
    data[r0 - 3:r0 + 3, cl - 1:cl + 3] = UNKNOWN  # 0.3 m x 0.2 m under the laser
    off = OccupancyMap(data, part.resolution, part.origin, accuracy_m=0.0)
    r = NativeMatcher(off, MOUNT, surface_depth_cells=0.0).match(scan, pose + np.array([0.04, -0.03, 0.02]))
    assert not r.ok and "inlier" in r.reason, r.reason
