"""The relocalizer gives the map its distance field from the native matcher's exact transform:
the same field as the map's own (scipy's), bit for bit."""

from __future__ import annotations

import numpy as np

import fgloc.frontends.native  # noqa: F401 - loaded, as when the native matcher runs
from fgloc.localization.relocalization import prime_distance_field
from fgloc.maps import OccupancyMap


def _map(rng: np.random.Generator, h: int, w: int, walls: float) -> OccupancyMap:
    data = np.where(rng.random((h, w)) < walls, 100, 0).astype(np.int16)
    data[rng.random((h, w)) < 0.1] = -1
    return OccupancyMap(data, 0.05, np.array([-3.0, 2.0, 0.0]))


def test_primed_field_is_the_maps_own_bit_for_bit():
    rng = np.random.default_rng(11)
    for h, w, walls in ((61, 47, 0.02), (120, 200, 0.002), (33, 9, 0.3), (1, 50, 0.05)):
        occ = _map(rng, h, w, walls)
        if not occ.occupied.any():
            occ.data[0, 0] = 100
        primed = OccupancyMap(occ.data.copy(), occ.resolution, occ.origin.copy())
        prime_distance_field(primed)
        assert "distance_field" in vars(primed)
        want = occ.distance_field  # scipy's distance_transform_edt
        assert primed.distance_field.dtype == want.dtype and primed.distance_field.tobytes() == want.tobytes()


def test_a_map_without_obstacles_keeps_its_own_answer():
    occ = OccupancyMap(np.zeros((10, 12), dtype=np.int16), 0.1)
    prime_distance_field(occ)
    assert "distance_field" not in vars(occ)
    assert np.all(np.isinf(occ.distance_field))
