"""The scan's agreement with the map (fgloc.localization.agreement.beam_agreements) is the map's own distance
field lookup (OccupancyMap.distance_at) at the beams' endpoints, bit for bit: on and off the grid, with a
turned and shifted map origin, a laser mounted off the robot's centre, and a map with no wall at all."""

from __future__ import annotations

import numpy as np
import pytest

from fgloc.localization.agreement import OFF_GRID_M, agreements, beam_agreements, scan_agreement
from fgloc.maps import OccupancyMap
from fgloc.types import LaserScan, StaticTransform


def reference(occ: OccupancyMap, mount: StaticTransform, poses: np.ndarray, sigma_m: float,
              pts: np.ndarray) -> np.ndarray:
    """The endpoints in the map frame by numpy, the field by OccupancyMap.distance_at."""
    m = np.asarray(mount.pose, dtype=float)
    cb, sb = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    ox = poses[:, 0] + cb * m[0] - sb * m[1]
    oy = poses[:, 1] + sb * m[0] + cb * m[1]
    yaw = poses[:, 2] + m[2]
    c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    qx = ox[:, None] + c * pts[None, :, 0] - s * pts[None, :, 1]
    qy = oy[:, None] + s * pts[None, :, 0] + c * pts[None, :, 1]
    d = occ.distance_at(np.column_stack([qx.ravel(), qy.ravel()]), outside=OFF_GRID_M)
    d = np.where(np.isfinite(d), d, OFF_GRID_M).reshape(len(poses), len(pts))
    return np.exp(-0.5 * (d / sigma_m) ** 2)


def grid(rng: np.random.Generator, walls: bool = True) -> np.ndarray:
    data = np.zeros((90, 130), dtype=np.int16)
    if walls:
        data[rng.random(data.shape) < 0.03] = 100
        data[:, 0] = data[0, :] = 100
    return data


@pytest.mark.parametrize("origin", [[0.0, 0.0, 0.0], [-1.7, 2.3, 0.0], [0.4, -3.1, 0.7], [2.0, 1.0, -2.9]])
@pytest.mark.parametrize("walls", [True, False])
def test_the_agreement_is_the_maps_distance_field_bit_for_bit(origin, walls):
    rng = np.random.default_rng(7)
    occ = OccupancyMap(grid(rng, walls), 0.05, origin=np.array(origin))
    mount = StaticTransform("base_link", "laser", np.array([0.21, -0.07, 0.3]))
    lo = np.asarray(origin[:2]) - 1.0
    hi = np.asarray(origin[:2]) + [130 * 0.05 + 1.0, 90 * 0.05 + 1.0]
    poses = np.column_stack([rng.uniform(lo[0], hi[0], 40), rng.uniform(lo[1], hi[1], 40),
                             rng.uniform(-np.pi, np.pi, 40)])
    r, a = rng.uniform(0.02, 9.0, 300), rng.uniform(-np.pi, np.pi, 300)
    pts = np.column_stack([r * np.cos(a), r * np.sin(a)])
    want = reference(occ, mount, poses, 0.1, pts)
    got = beam_agreements(occ, mount, poses, 0.1, pts)
    assert got.shape == (40, 300)
    assert np.array_equal(got.view(np.int64), want.view(np.int64))
    assert ((got == np.exp(-0.5 * (OFF_GRID_M / 0.1) ** 2)).any())  # some endpoints off the grid
    if walls:
        assert got.max() > 0.5
    # the mean per pose, as any number of poses at once
    one = np.array([agreements(occ, mount, None, p[None], 0.1, pts)[0] for p in poses[:5]])
    assert np.array_equal(one, agreements(occ, mount, None, poses, 0.1, pts)[:5])


def nearest_reference(occ: OccupancyMap, mount: StaticTransform, scan: LaserScan, pose: np.ndarray, sigma_m: float,
                      max_beams: int) -> float:
    """The monitor's cheaper agreement by numpy: every ceil(n / max_beams)-th beam, the field at each valid
    endpoint's cell (OccupancyMap.world_to_grid), off the grid OFF_GRID_M."""
    n = len(scan.ranges)
    idx = np.arange(0, n, -(-n // max_beams))
    r = np.asarray(scan.ranges, dtype=float)[idx]
    ok = (r >= scan.range_min) & (r <= scan.range_max)
    a = scan.angle_min + scan.angle_increment * idx[ok]
    m = np.asarray(mount.pose, dtype=float)
    x, y, yaw = pose
    lx, ly = x + np.cos(yaw) * m[0] - np.sin(yaw) * m[1], y + np.sin(yaw) * m[0] + np.cos(yaw) * m[1]
    th = yaw + m[2] + a
    rc = occ.world_to_grid(np.column_stack([lx + r[ok] * np.cos(th), ly + r[ok] * np.sin(th)]))
    inside = (rc[:, 0] >= 0) & (rc[:, 0] < occ.height) & (rc[:, 1] >= 0) & (rc[:, 1] < occ.width)
    d = np.full(len(rc), OFF_GRID_M)
    d[inside] = occ.distance_field[rc[inside, 0], rc[inside, 1]]
    return float(np.mean(np.exp(-0.5 * (d / sigma_m) ** 2)))


@pytest.mark.parametrize("origin", [[0.0, 0.0, 0.0], [0.4, -3.1, 0.7]])
def test_the_monitors_agreement_reads_the_field_at_each_endpoints_cell(origin):
    rng = np.random.default_rng(11)
    occ = OccupancyMap(grid(rng), 0.05, origin=np.array(origin))
    mount = StaticTransform("base_link", "laser", np.array([0.21, -0.07, 0.3]))
    ranges = rng.uniform(0.1, 6.0, 721).astype(np.float32)
    ranges[rng.random(721) < 0.1] = np.nan
    scan = LaserScan(0.0, -2.3, 4.6 / 721, 0.05, 5.0, ranges)
    values = []
    for _ in range(30):
        pose = np.array([origin[0] + rng.uniform(0.0, 6.5), origin[1] + rng.uniform(0.0, 4.5), rng.uniform(-3, 3)])
        got = scan_agreement(occ, mount, scan, pose, 0.1, max_beams=64)
        assert got == pytest.approx(nearest_reference(occ, mount, scan, pose, 0.1, 64), abs=1e-12)
        values.append(got)
    assert min(values) < 0.3 < max(values)
    nowhere = np.array([origin[0] - 50.0, origin[1] - 50.0, 0.0])  # every endpoint off the grid
    assert scan_agreement(occ, mount, scan, nowhere, 0.1, max_beams=64) == pytest.approx(0.0, abs=1e-12)
    # a pose not a number: no endpoint on the grid either
    assert scan_agreement(occ, mount, scan, np.array([np.nan, 1.0, 0.0]), 0.1, max_beams=64) == pytest.approx(0.0)
