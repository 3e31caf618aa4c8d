"""Scan matcher and ray-traced occupancy on synthetic geometry with known answers."""

from __future__ import annotations

import numpy as np

from fgloc.geometry import between, compose, inverse, transform_points
from fgloc.mapping.occupancy import LogOddsGrid, scan_beams, scan_endpoints
from fgloc.mapping.scanmatch import build_distance_grid, correlative_search, match_covariance, refine


def _room_points(step=0.02):
    """An L-shaped room outline with a pillar: walls as dense points (map frame)."""
    segs = [((-3, -2), (4, -2)), ((4, -2), (4, 1)), ((4, 1), (1, 1)), ((1, 1), (1, 3)), ((1, 3), (-3, 3)),
            ((-3, 3), (-3, -2)), ((0.0, 0.0), (0.4, 0.0)), ((0.4, 0.0), (0.4, 0.4))]
    pts = []
    for (x0, y0), (x1, y1) in segs:
        n = int(np.hypot(x1 - x0, y1 - y0) / step) + 1
        t = np.linspace(0, 1, n)
        pts.append(np.column_stack([x0 + t * (x1 - x0), y0 + t * (y1 - y0)]))
    return np.concatenate(pts)


def test_refine_recovers_known_offset():
    world = _room_points()
    grid = build_distance_grid(world, 0.04, 0.3)
    true = np.array([0.7, -0.4, 0.3])
    scan = transform_points(inverse(true), world[::3])  # the room seen from `true`
    guess = compose(true, np.array([0.08, -0.06, np.radians(3.0)]))
    rr = refine(grid, scan, guess)
    err = between(true, rr.pose)
    assert np.hypot(err[0], err[1]) < 0.005
    assert abs(err[2]) < np.radians(0.1)
    assert rr.inlier_frac > 0.99
    cov = match_covariance(rr.info, 0.05)
    assert np.all(np.linalg.eigvalsh(cov) > 0)


def test_correlative_search_finds_large_offset_and_reports_ambiguity():
    world = _room_points()
    grid = build_distance_grid(world, 0.04, 0.5)
    true = np.array([-1.0, 0.5, -0.8])
    scan = transform_points(inverse(true), world[::4])
    guess = compose(true, np.array([0.6, -0.5, np.radians(12.0)]))
    sr = correlative_search(grid, scan, guess, 1.0, np.radians(20), 0.1, np.radians(2.0), 0.15)
    err = between(true, sr.pose)
    assert np.hypot(err[0], err[1]) < 0.15 and abs(err[2]) < np.radians(3)
    assert sr.score > 0.8 and sr.ambiguity < 0.9
    # a featureless corridor (two parallel walls) is ambiguous along its axis
    xs = np.arange(-10, 10, 0.02)
    corridor = np.concatenate([np.column_stack([xs, np.full_like(xs, -1.0)]),
                               np.column_stack([xs, np.full_like(xs, 1.0)])])
    cg = build_distance_grid(corridor, 0.04, 0.5)
    local = corridor[np.abs(corridor[:, 0]) < 4][::3]
    sc = correlative_search(cg, local, np.zeros(3), 1.0, np.radians(5), 0.1, np.radians(1.0), 0.15)
    assert sc.ambiguity > 0.95


def test_raytraced_beam_free_then_hit_and_inf_carves_without_hit():
    g = LogOddsGrid(-1.0, -1.0, 6.0, 6.0, 0.1)
    ranges = np.array([3.0, np.inf, np.nan], dtype=np.float32)
    angles = np.array([0.0, np.pi / 2, np.pi])
    ends, hit = scan_endpoints(ranges, angles, 0.1, 30.0, 25.0, 4.0)
    assert ends.shape == (2, 2) and hit.tolist() == [True, False]
    for _ in range(3):
        g.add_beams(np.array([0.05, 0.05]), ends, hit)
    m = g.to_map()
    row0 = int((0.05 - g.y0) / 0.1)
    col_hit = int((3.05 - g.x0) / 0.1)
    assert m.data[row0, col_hit] == 100                      # the return
    assert np.all(m.data[row0, int((0.5 - g.x0) / 0.1):col_hit - 1] == 0)  # free along the beam
    col0 = int((0.05 - g.x0) / 0.1)
    up = m.data[int((0.5 - g.y0) / 0.1):int((3.9 - g.y0) / 0.1), col0]
    assert np.all(up == 0)                                   # +inf beam carved free ...
    assert not np.any(m.data[:, col0] == 100)                # ... with no hit anywhere
    assert m.data[int((5.0 - g.y0) / 0.1), col0] == -1       # beyond the carve cap: unknown


def test_growing_grid_with_a_pool_is_the_grid_without_one():
    """Submap fields from reused memory (BufferPool) equal fresh ones cell for cell, through growth
    in every direction, and equal a field built from all the points at once where both have cells."""
    from fgloc.mapping.scanmatch import BufferPool, GrowingDistanceGrid, build_distance_grid

    rng = np.random.default_rng(3)
    sets = [rng.uniform(-2, 2, (150, 2)) + off for off in ([0, 0], [9, 1], [-8, -7], [2, 12], [-3, 4])]
    pool = BufferPool(max_bytes=64e6)
    pool.give(np.full(3_000_000, 7.0, dtype=np.float32))  # stale contents must not leak through
    fresh = GrowingDistanceGrid(0.025, 0.3)
    pooled = GrowingDistanceGrid(0.025, 0.3, pool=pool)
    for pts in sets:
        fresh.add(pts)
        pooled.add(pts)
        assert pooled.dist.shape == fresh.dist.shape
        assert np.array_equal(pooled.dist, fresh.dist)
    whole = np.concatenate(sets)
    g = fresh.grid()
    d = dist_at(g, whole)
    assert np.all(d < 0.02)  # every stamped point sits in a near-zero cell
    ref = build_distance_grid(whole, 0.025, 0.3, 0.5)
    probe = rng.uniform(-10, 14, (2000, 2))
    a, b = dist_at(g, probe), dist_at(ref, probe)
    assert np.max(np.abs(a - b)) <= 0.025 * np.sqrt(2)  # the cell centres a probe falls in are this close
    pooled.release()
    assert pooled.dist is None and len(pool._free) >= 1


def dist_at(grid, xy):
    ix = np.floor((xy[:, 0] - grid.x0) / grid.resolution).astype(int)
    iy = np.floor((xy[:, 1] - grid.y0) / grid.resolution).astype(int)
    ok = (ix >= 0) & (iy >= 0) & (ix < grid.dist.shape[1]) & (iy < grid.dist.shape[0])
    out = np.full(len(xy), grid.dmax_m)
    out[ok] = grid.dist[iy[ok], ix[ok]]
    return out


def test_no_return_beams_do_not_erase_walls_the_returns_saw():
    """A driver reporting +inf for a dark wall: the no-return beams carve free space up to the
    wall the other scans' returns put in the map, never through it, whatever the scan order."""
    wall_x, res = 3.0, 0.05
    angles = np.radians(np.linspace(-40.0, 40.0, 161))
    seen = (wall_x / np.cos(angles)).astype(np.float32)       # the wall, seen from (0, 0)
    dark = np.full_like(seen, np.inf)                          # the same wall, no return

    def grid(order):
        g = LogOddsGrid(-1.0, -4.0, 10.0, 4.0, res)
        for origin, ranges in order:
            ends, hit, missing = scan_beams(ranges, angles, 0.1, 30.0, 25.0, 8.0)
            g.add_beams(np.asarray(origin), ends + np.asarray(origin), hit, missing)
        return g, g.to_map()

    g0, ref = grid([((0.0, 0.0), seen)])
    dark_scans = [((0.0, dy), dark) for dy in (-0.6, -0.3, 0.3, 0.6) for _ in range(3)]
    g1, after = grid([((0.0, 0.0), seen)] + dark_scans)
    g2, before = grid(dark_scans + [((0.0, 0.0), seen)])
    cols = int((wall_x - g0.x0) / res)
    wall = ref.data[:, cols - 1:cols + 2] == 100
    assert int(wall.sum()) == 80                                # the wall's cells from the returns
    for m in (after, before):                                  # ... all kept, in either order
        assert np.array_equal(m.data[:, cols - 1:cols + 2] == 100, wall)
        assert np.array_equal(m.data, after.data)
    rows = slice(int((-2.0 - g0.y0) / res), int((2.0 - g0.y0) / res))  # the wall's middle, |y| < 2 m
    beyond = after.data[rows, cols + 2:]                       # nothing carved behind it
    assert int((beyond == 0).sum()) == 0
    assert int((after.data == 0).sum()) > int((ref.data == 0).sum())  # the dark beams did clear free space
    # without the no-return flags (every non-hit carves through): the wall goes
    g3 = LogOddsGrid(-1.0, -4.0, 10.0, 4.0, res)
    for origin, ranges in [((0.0, 0.0), seen)] + dark_scans:
        ends, hit = scan_endpoints(ranges, angles, 0.1, 30.0, 25.0, 8.0)
        g3.add_beams(np.asarray(origin), ends + np.asarray(origin), hit)
    assert int((g3.to_map().data[:, cols - 1:cols + 2] == 100).sum()) == 0
