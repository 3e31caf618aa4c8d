"""The native matcher's own distance transform (``edt_squared``) against scipy's, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import distance_transform_edt

from fgloc.frontends.native import edt_squared, surface_distance_field
from fgloc.maps import OccupancyMap


def _scipy_field(occ_map: OccupancyMap, k: int, max_dist_m: float, depth_m: float) -> np.ndarray:
    """surface_distance_field as it was written with scipy.ndimage.distance_transform_edt."""
    occ = np.repeat(np.repeat(occ_map.occupied, k, axis=0), k, axis=1)
    fine = occ_map.resolution / k
    outside = distance_transform_edt(~occ) * fine - 0.5 * fine
    inside = distance_transform_edt(occ) * fine - 0.5 * fine
    return np.clip(np.where(occ, -inside, outside) + depth_m, -max_dist_m, max_dist_m)


@pytest.mark.parametrize("density", [0.0005, 0.02, 0.3, 0.9])
def test_edt_equals_scipy_on_random_grids(density: float) -> None:
    rng = np.random.default_rng(int(density * 1e4))
    for _ in range(40):
        h, w = (int(v) for v in rng.integers(1, 70, 2))
        feat = rng.random((h, w)) < density
        if not feat.any():
            feat[rng.integers(h), rng.integers(w)] = True
        got = edt_squared(feat)
        assert np.array_equal(np.sqrt(got), distance_transform_edt(~feat))
        assert np.array_equal(got, np.round(got))  # exact integers
        assert np.all(got[feat] == 0.0)


def test_edt_edge_shapes() -> None:
    for feat in (np.ones((1, 1), bool), np.eye(1, 50, 49, dtype=bool), np.eye(50, 1, 0, dtype=bool),
                 np.ones((7, 9), bool)):
        assert np.array_equal(np.sqrt(edt_squared(feat)), distance_transform_edt(~feat))
    one = np.zeros((5, 8), bool)
    one[4, 0] = True
    assert edt_squared(one)[0, 7] == 4.0**2 + 7.0**2


def test_surface_field_unchanged_on_a_room_with_a_pillar() -> None:
    data = np.zeros((60, 80), dtype=np.int16)
    data[0, :] = data[-1, :] = data[:, 0] = data[:, -1] = 100
    data[20:26, 30:41] = 100  # a thick block: inside distances
    data[40:, 55] = 100  # a thin wall
    data[5:12, 5:15] = -1  # unknown
    m = OccupancyMap(data, 0.05)
    for k, max_d, depth in ((2, 1.0, 0.0), (1, 0.4, 0.025), (3, 0.3, 0.01)):
        assert np.array_equal(surface_distance_field(m, k, max_d, depth), _scipy_field(m, k, max_d, depth))


def test_surface_field_equals_scipy_on_random_maps() -> None:
    """Walls of every thickness (sparse cells to nearly solid, whole rows and columns of wall, map edges):
    the inside distances found row by row are the exact transform's."""
    rng = np.random.default_rng(11)
    for density in (0.01, 0.2, 0.6, 0.97):
        for _ in range(6):
            h, w = (int(v) for v in rng.integers(1, 45, 2))
            w = max(w, 2)
            data = np.where(rng.random((h, w)) < density, 100, 0).astype(np.int16)
            if rng.random() < 0.5 and h > 2:
                data[rng.integers(h), :] = 100
            data.reshape(-1)[rng.permutation(h * w)[:2]] = (0, 100)  # a free and a wall cell
            m = OccupancyMap(data, 0.05)
            for k, max_d, depth in ((1, 0.4, 0.025), (2, 1.0, 0.0), (3, 0.2, -0.01)):
                got = surface_distance_field(m, k, max_d, depth)
                assert np.array_equal(got, _scipy_field(m, k, max_d, depth))
    solid = OccupancyMap(np.full((6, 7), 100, dtype=np.int16), 0.05)  # no free cell: as deep as the clip
    assert np.array_equal(surface_distance_field(solid, 2, 0.3, 0.01), np.full((12, 14), -0.3 + 0.01))


def test_matcher_gives_the_map_its_distance_field() -> None:
    """The matcher's coarse field comes from the map's distance field, which it computes (exactly
    scipy's) when the map has none yet, and reuses when it has: the scan agreement and the global
    search then read it without a second transform."""
    from fgloc.frontends.native import NativeMatcher, map_distance_field

    data = np.zeros((60, 80), dtype=np.int16)
    data[0, :] = data[-1, :] = data[:, 0] = data[:, -1] = 100
    data[20:26, 30:41] = 100
    m = OccupancyMap(data, 0.05)
    assert "distance_field" not in vars(m)
    matcher = NativeMatcher(m)
    assert "distance_field" in vars(m)
    expected = distance_transform_edt(~m.occupied) * 0.05
    assert np.array_equal(m.distance_field, expected)
    assert map_distance_field(m) is m.distance_field
    # a map whose field was already made (by its own property) keeps it, and the matcher's coarse
    # field is the same either way
    m2 = OccupancyMap(data, 0.05)
    own = m2.distance_field
    matcher2 = NativeMatcher(m2)
    assert m2.distance_field is own
    assert np.array_equal(matcher2.lik, matcher.lik) and np.array_equal(matcher2.field, matcher.field)
    empty = OccupancyMap(np.zeros((10, 10), dtype=np.int16), 0.1)
    assert np.all(np.isinf(map_distance_field(empty)))


def test_amcl_wall_field_equals_its_scipy_form() -> None:
    """AMCL's likelihood field from the exact transform (and from the map's distance field when the walls
    are the occupied cells) is the field scipy's transform gave, bit for bit."""
    from fgloc.frontends.amcl import wall_surface_field

    def scipy_form(w: np.ndarray, res: float, max_d: float, depth: float) -> np.ndarray:
        half = 0.5 * res
        outside = distance_transform_edt(~w) * res - half
        inside = distance_transform_edt(w) * res - half if not w.all() else np.full(w.shape, float(max_d))
        return np.clip(np.where(w, -inside, outside) + depth, -max_d, max_d)

    rng = np.random.default_rng(7)
    for density in (0.002, 0.05, 0.4, 0.95, 1.0):
        for _ in range(6):
            h, w = (int(v) for v in rng.integers(2, 60, 2))
            walls = rng.random((h, w)) < density
            walls[rng.integers(h), rng.integers(w)] = True
            for res, max_d, depth in ((0.05, 2.0, 0.0), (0.1, 0.3, 0.025)):
                got = wall_surface_field(walls, res, max_d, depth)
                assert np.array_equal(got, scipy_form(walls, res, max_d, depth))
    data = np.zeros((40, 50), dtype=np.int16)
    data[0, :] = data[-1, :] = data[:, 0] = data[:, -1] = 100
    data[10:20, 20:31] = 100
    m = OccupancyMap(data, 0.05)
    from fgloc.frontends.native import map_distance_field

    got = wall_surface_field(m.occupied, 0.05, 1.0, distance=map_distance_field(m))
    assert np.array_equal(got, scipy_form(m.occupied, 0.05, 1.0, 0.0))


def test_edt_below_a_bound_is_exact_below_it_and_at_least_it_beyond() -> None:
    from fgloc.frontends.native import edt_squared_below

    rng = np.random.default_rng(5)
    for density in (0.0003, 0.003, 0.05):
        for _ in range(8):
            h, w = (int(v) for v in rng.integers(20, 160, 2))
            feat = rng.random((h, w)) < density
            feat[rng.integers(h), rng.integers(w)] = True
            exact = np.round(distance_transform_edt(~feat) ** 2)  # exact integers
            for bound in (1.0, 4.0, 9.0, 30.0, 400.0, np.inf):
                got = edt_squared_below(feat, bound)
                below = exact < bound
                assert np.array_equal(got[below], exact[below])
                assert np.all(got[~below] >= bound)


def test_fine_field_on_open_maps_equals_scipy() -> None:
    """Rooms wider than the clip distance: the fine field's transform skips what lies beyond it."""
    rng = np.random.default_rng(8)
    for _ in range(4):
        h, w = (int(v) for v in rng.integers(40, 120, 2))
        data = np.zeros((h, w), dtype=np.int16)
        data[0, :] = data[-1, :] = data[:, 0] = data[:, -1] = 100
        data[rng.integers(1, h - 1, 6), rng.integers(1, w - 1, 6)] = 100  # pillars
        data[rng.integers(1, h - 1), 1:w // 2] = 100
        m = OccupancyMap(data, 0.05)
        for k, max_d, depth in ((2, 1.0, 0.0), (2, 0.5, 0.025), (3, 0.3, -0.02), (2, 0.04, 0.0)):
            assert np.array_equal(surface_distance_field(m, k, max_d, depth), _scipy_field(m, k, max_d, depth))
