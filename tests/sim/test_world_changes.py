"""A world that changed since its map: furniture moved, turned, removed and added, a map_server
world with solids added and a box cleared; the shipped changed_world scenario."""

from importlib import resources
from pathlib import Path

import numpy as np
import pytest

from fgloc.errors import ConfigError
from fgloc.maps import FREE, OCCUPIED, OccupancyMap
from fgloc.sim import load_scenario
from fgloc.sim.simulate import GridWorld, apply_changes, build_world, true_motion
from fgloc.sim.world import World, paper_hall

SCEN = Path(str(resources.files("fgloc.config") / "scenarios"))


def _square(x0, y0, s=1.0):
    return np.array([[x0, y0], [x0 + s, y0], [x0 + s, y0 + s], [x0, y0 + s]], dtype=float)


def test_moved_turned_removed_and_added_pieces():
    w = World([_square(0, 0), _square(5, 5)], np.array([[10.0, 10.0, 0.5], [20.0, 0.0, 0.3]]))
    polys, circles = apply_changes(w, [
        {"polygon": 0, "shift": [1.0, 2.0]},
        {"polygon": 1, "rotate_deg": 90.0},
        {"circle": 0, "remove": True},
        {"circle": 1, "shift": [0.0, 1.0]},
        {"add": [[3, 3], [4, 3], [3.5, 4]]},
        {"add_circle": [7.0, 7.0, 0.2]},
    ])
    assert len(polys) == 3 and circles.shape == (2, 3)
    np.testing.assert_allclose(polys[0], _square(1, 2))
    # a square turned 90 deg about its centre covers the same square, its vertices cycled
    np.testing.assert_allclose(sorted(map(tuple, polys[1].round(9))), sorted(map(tuple, _square(5, 5))))
    np.testing.assert_allclose(polys[2], [[3, 3], [4, 3], [3.5, 4]])
    np.testing.assert_allclose(circles, [[20.0, 1.0, 0.3], [7.0, 7.0, 0.2]])
    # the world itself is unchanged (the map is made from it)
    np.testing.assert_allclose(w.polygons[0], _square(0, 0))
    assert len(w.circles) == 2


def test_a_piece_turned_by_30_deg_keeps_its_centre_and_shape():
    w = World([np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0]])])
    (p,), _ = apply_changes(w, [{"polygon": 0, "rotate_deg": 30.0}])
    np.testing.assert_allclose(p.mean(axis=0), [1.0, 0.5])
    np.testing.assert_allclose(np.hypot(*(p[1] - p[0])), 2.0)
    assert np.degrees(np.arctan2(*(p[1] - p[0])[::-1])) == pytest.approx(30.0)


@pytest.mark.parametrize("change, words", [
    ({"polygon": 99, "shift": [1, 0]}, "no polygon 99"),
    ({"circle": 6, "remove": True}, "no circle 6"),
    ({"polygon": 1, "add": [[0, 0], [1, 0], [1, 1]]}, "one kind per entry"),
    ({"add": [[0, 0], [1, 0]]}, "at least 3"),
    ({"add_circle": [1, 2, -1]}, "radius > 0"),
    ({"clear": [0, 0, 1, 1]}, "only in a map_server world"),
    ({"shift": [1, 0]}, "one kind per entry"),
])
def test_bad_changes_are_one_line_errors(change, words):
    with pytest.raises(ConfigError) as e:
        apply_changes(paper_hall(), [change])
    assert words in str(e.value) and "\n" not in str(e.value)


def test_a_removed_piece_cannot_be_changed_again():
    with pytest.raises(ConfigError, match="no polygon 4"):
        apply_changes(paper_hall(), [{"polygon": 4, "remove": True}, {"polygon": 4, "shift": [1, 0]}])


def _corridor() -> OccupancyMap:
    """A 10 m x 3 m corridor of 0.1 m cells: free inside, solid walls around."""
    data = np.full((30, 100), OCCUPIED, dtype=np.int16)
    data[3:27, 3:97] = FREE
    return OccupancyMap(data, 0.1, np.zeros(3))


def test_grid_world_sees_added_solids_and_cleared_cells():
    occ = _corridor()
    east = np.array([0.0])
    before = GridWorld(occ).raycast(np.array([[2.0, 1.5]]), east, 20.0)[0]
    assert before == pytest.approx(7.7, abs=0.11)  # to the east wall's face at x = 9.7
    added = GridWorld(occ, [{"add": [[5.0, 1.0], [5.5, 1.0], [5.5, 2.0], [5.0, 2.0]]}])
    assert added.raycast(np.array([[2.0, 1.5]]), east, 20.0)[0] == pytest.approx(3.0, abs=1e-6)
    pallet = GridWorld(occ, [{"add_circle": [4.0, 1.5, 0.5]}])
    assert pallet.raycast(np.array([[2.0, 1.5]]), east, 20.0)[0] == pytest.approx(1.5, abs=1e-6)
    # an opening cut into the east wall (a door opened since mapping): the beam passes it
    opened = GridWorld(occ, [{"clear": [9.6, 1.2, 10.05, 1.8]}])
    assert not np.isfinite(opened.raycast(np.array([[2.0, 1.5]]), east, 20.0)[0])
    # a beam beside the opening still ends on the wall
    assert opened.raycast(np.array([[2.0, 0.8]]), east, 20.0)[0] == pytest.approx(7.7, abs=0.11)


@pytest.mark.parametrize("change, words", [
    ({"polygon": 3, "shift": [1, 0]}, "no numbered pieces"),
    ({"clear": [0, 0, 1]}, "[x0, y0, x1, y1]"),
])
def test_grid_world_bad_changes(change, words):
    with pytest.raises(ConfigError) as e:
        GridWorld(_corridor(), [change])
    assert words in str(e.value)


def test_shipped_changed_world_has_every_kind_of_change_and_a_clear_route():
    sc = load_scenario(SCEN / "changed_world.yaml")
    kinds = {k for ch in sc["map_changes"] for k in ch if k in ("polygon", "circle", "add", "add_circle")}
    assert kinds == {"polygon", "circle", "add", "add_circle"}
    assert any(ch.get("remove") for ch in sc["map_changes"]) and any("rotate_deg" in ch for ch in sc["map_changes"])
    assert len(sc["faults"]["moving_obstacles"]) >= 3  # people
    world, occ = build_world(sc)
    hall, _ = build_world(load_scenario({}))
    assert len(world.polygons) == len(hall.polygons) - 2 + 7  # two removed, seven added
    gone = hall.circles[3]
    assert not np.any(np.hypot(*(world.circles[:, :2] - gone[:2]).T) < 1e-9)  # the pillar removed
    plan = true_motion(sc)
    assert world.is_free(plan.poses[::25, :2], clearance=0.3).all()
    # the map is the unchanged hall's: the shelves along the north wall are not in it
    (r, c), = occ.world_to_grid([[14.0, 19.8]])
    assert not occ.occupied[r, c] and occ.free[r, c]
