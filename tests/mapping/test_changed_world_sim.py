"""The self-check on a localization log against its map, in the simulator's hall after the world
changed (issue 13): furniture moved and removed, pallets standing by the route.  Every edit is
reported where it was made, an unchanged world is not, and scans taken while the robot turns on
the spot (beams measured along the turn) report nothing."""

from __future__ import annotations

import numpy as np
import pytest

from fgloc.mapping.selfcheck import check_against_map
from fgloc.mapping.source import pair_scans
from fgloc.sim import run_scenario
from fgloc.types import Trajectory

# two sides of the paper hall's loop, with a stop-and-turn at the corner (27.5, 3)
ROUTE = [[2.5, 3.0], [27.5, 3.0], [27.5, 17.0]]


def _pallet(x: float, y: float, r: float) -> dict:
    return {"path": [[x, y], [x + 1e-6, y]], "speed_mps": 0.0, "radius_m": r}  # standing still


EDITS = {
    # hall polygon 6, a cabinet on the south wall at x 17.5-19.5, moved 4 m west; polygon 21, a
    # 2 x 0.8 m table at (20, 6.9), taken away
    "map_changes": [{"polygon": 6, "shift": [-4.0, 0.0]}, {"polygon": 21, "shift": [100.0, 100.0]}],
    "faults": {"moving_obstacles": [_pallet(9.0, 1.6, 0.4), _pallet(28.7, 12.8, 0.35)]},
}
EXPECTED = {  # kind -> centres (m) of what changed
    "added": [(9.0, 1.6), (14.5, 0.45), (28.7, 12.8)],
    "removed": [(18.5, 0.45), (20.0, 6.9)],
}


def _localized(gt: Trajectory, seed: int) -> Trajectory:
    """The ground truth with a localization's error (2 cm, 0.2 deg)."""
    rng = np.random.default_rng(seed)
    noise = np.column_stack([rng.normal(0, 0.02, (len(gt), 2)), rng.normal(0, np.radians(0.2), len(gt))])
    return Trajectory(gt.stamps, gt.poses + noise)


def _check(overrides: dict, rate_hz: float):
    res = run_scenario(dict(overrides, route=ROUTE, laser={"rate_hz": rate_hz}), seed=1)
    recs, mount = pair_scans(iter(res.messages))
    return check_against_map(recs, np.asarray(mount.pose), _localized(res.ground_truth, 2), res.map)


@pytest.mark.parametrize("rate_hz", [10.0, 25.0])
def test_unchanged_world_matches(rate_hz):
    res = _check({"map_changes": []}, rate_hz)
    assert res.passed and "MATCHES" in res.verdict, res.verdict
    assert not res.changes
    assert res.stats["checked"] >= 100 and res.stats["inconsistent"] == 0


@pytest.mark.parametrize("rate_hz", [10.0, 25.0])
def test_changed_world_reports_every_edit_in_place(rate_hz):
    res = _check(EDITS, rate_hz)
    assert not res.passed and "CHANGED" in res.verdict
    assert res.stats["inconsistent"] == 0  # the poses still agree with the map: the world changed
    for kind, centres in EXPECTED.items():
        found = [c for c in res.changes if c.kind == kind]
        assert len(found) == len(centres), (kind, [(c.kind, c.center) for c in res.changes])
        for cx, cy in centres:  # each edit is one region, within 0.4 m of where it was made ...
            d = [float(np.hypot(c.center[0] - cx, c.center[1] - cy)) for c in found]
            assert min(d) < 0.4, (kind, (cx, cy), d)
        for c in found:  # ... seen by many returns (the smallest edit, a 0.35 m pallet: ~1000)
            assert c.observations >= 300
    assert len(res.suspects) == len(res.changes)
