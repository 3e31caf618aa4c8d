"""The laser's ranges against the map's, ray-cast from the poses the localizer called ok
(fgloc.localization.coverage.range_fit, MapAgreement.range_misfit): a map.yaml with a wrong ``resolution``
fits a particle filter's scans somewhere, but few of the ranges ray-cast there are the laser's; the right map
with people and moved furniture keeps most of them."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from fgloc.config import load_config
from fgloc.localization.coverage import beyond_walls, range_fit, range_residuals
from fgloc.localization.monitor import MapAgreement
from fgloc.maps import OccupancyMap
from fgloc.types import LaserScan, StaticTransform

MOUNT = StaticTransform("base_link", "laser", np.array([0.1, 0.0, 0.0]))


def _room() -> OccupancyMap:
    """A 12 m x 8 m room (0.05 m cells) around the map frame's origin, with a 2 m x 1 m block in it."""
    g = np.zeros((160, 240), dtype=np.int16)
    g[:2, :] = g[-2:, :] = g[:, :2] = g[:, -2:] = 100
    g[100:120, 150:190] = 100
    return OccupancyMap(g, 0.05, origin=np.array([-6.0, -4.0, 0.0]))


def _twice(occ: OccupancyMap) -> OccupancyMap:
    """``occ`` with its cells read at twice their size, still around the origin: every wall twice as far."""
    return replace(occ, resolution=2 * occ.resolution, origin=2 * occ.origin)


def _scan(occ: OccupancyMap, pose, people: bool = False) -> LaserScan:
    """The scan the room gives at ``pose`` (360 beams, 20 m range); ``people``: every fourth beam blocked
    0.8 m from the laser."""
    p = np.asarray(pose, float)
    origin = p[:2] + np.array([math.cos(p[2]), math.sin(p[2])]) * MOUNT.pose[0]
    ang = -math.pi + 2 * math.pi / 360 * np.arange(360)
    r = occ.raycast(origin, p[2] + ang, 20.0)
    if people:
        r[::4] = 0.8
    return LaserScan(0.0, -math.pi, 2 * math.pi / 360, 0.05, 20.0, r.astype(np.float32))


def test_the_right_map_fits_and_one_at_twice_its_cell_size_does_not():
    occ = _room()
    pose = (-3.0, -1.5, 0.3)
    lr, share = range_fit(occ, MOUNT, _scan(occ, pose), np.array(pose))
    assert abs(lr) < 0.01 and share > 0.95
    lr, share = range_fit(occ, MOUNT, _scan(occ, pose, people=True), np.array(pose))
    assert abs(lr) < 0.01 and 0.7 < share < 0.8  # a quarter of the beams on people
    wrong = _twice(occ)
    lr, share = range_fit(wrong, MOUNT, _scan(occ, pose), np.array(pose))
    assert share < 0.2 and lr > math.log(1.5)


def _agreement(occ: OccupancyMap, scan_map: OccupancyMap) -> MapAgreement:
    """A MapAgreement on ``occ`` fed a minute of good measurements (4 per second) of ``scan_map``'s scans
    along the room."""
    cfg = load_config().integrity
    ag = MapAgreement(cfg, occ, MOUNT, 0.1)
    for k in range(240):
        pose = np.array([-4.0 + 0.03 * k, -1.5, 0.1])
        ag.check(0.25 * k, _scan(scan_map, pose, people=k % 2 == 0), pose, True)
    return ag


def test_a_minute_at_the_wrong_resolution_is_a_misfit_and_the_right_map_is_not():
    occ = _room()
    right = _agreement(occ, occ)
    assert len(right.range_samples) == 60 and right.range_misfit() is None  # sampled once a second
    wrong = _agreement(_twice(occ), occ)
    assert len(wrong.range_samples) >= MapAgreement.RANGE_MIN_SAMPLES
    m = wrong.range_misfit()
    assert m is not None and m[0] < MapAgreement.RANGE_FIT_LOW and m[1] > 1.5


def test_people_shorten_beams_and_a_wall_that_is_not_there_lengthens_them():
    """coverage.beyond_walls: a quarter of the beams on people end short of the map's walls, none beyond; a map
    with a partition the room does not have (across it, 2.5 m beside the robot) sends the beams that cross it
    beyond it: 30 % of one scan's, 22 % at the median over a minute, while 35 % and more of the ranges still fit
    (no misfit by the share that fits)."""
    occ = _room()
    pose = np.array([-3.0, -1.5, 0.3])
    lr = range_residuals(occ, MOUNT, _scan(occ, pose, people=True), pose)
    assert lr is not None and beyond_walls(lr) == 0.0
    g = occ.data.copy()
    g[100:102, 2:-2] = 100
    walled = replace(occ, data=g)
    lr = range_residuals(walled, MOUNT, _scan(occ, pose), pose)
    assert lr is not None and 0.25 < beyond_walls(lr) < 0.35
    ag = _agreement(walled, occ)
    bw = ag.beyond_walls()
    assert bw is not None and 0.2 < bw[0] < 0.25 and bw[1] == 60 and ag.range_misfit() is None
    assert _agreement(occ, occ).beyond_walls() is None
