"""A global search that found nothing is not repeated on the next scan from the same place: it waits until the
odometry moved ``pipeline.global_retry_move_m``, turned ``global_retry_turn_deg`` or ``global_retry_s`` passed.
A log on the wrong map (another building) searched the whole map on every scan: the paper log on the Willow
Garage map took 565 s for 113 s of log; now 73 s, with the same verdict."""

from __future__ import annotations

import math

import pytest

from fgloc.config import load_config
from fgloc.localization import Localizer, Session
from fgloc.maps import OccupancyMap

LEG = [[2.5, 3.0], [14.5, 3.0]]  # the paper's first leg, 15 s at 0.8 m/s


@pytest.fixture(scope="module")
def leg():
    from fgloc.sim import simulate_paper

    return simulate_paper(seed=0, route=LEG)


def _localize(sim, occ_map, **pipeline) -> Localizer:
    msgs = [(t, m) for t, m in sim.messages if t != "/ground_truth"]
    loc = Localizer(occ_map, sim.laser_mount, "ekf", "native", initial_pose=None,
                    config=load_config(overrides={"pipeline": pipeline} if pipeline else None))
    Session(loc).run(msgs)
    return loc


def test_a_wrong_map_is_searched_again_only_after_motion(leg):
    loc = _localize(leg, _willow())
    scans, searches = loc.stats["scans"], loc.stats["global_searches"]
    assert loc.stats["fixes"] == 0 and scans > 300
    travelled_m = float(sum(math.dist(a, b) for a, b in zip(LEG, LEG[1:], strict=False)))
    # one search per 0.25 m of travel (and per second standing), not one per scan
    assert searches <= travelled_m / 0.25 + 16 + 2
    assert searches >= travelled_m / 0.25 * 0.8
    assert loc.no_fix_reasons["global localization: the last search found nothing, waiting for motion"] == \
        scans - searches
    assert any(v.kind == "no_fix" and v.unusable for v in loc.monitor.verdicts)


def test_the_right_map_is_found_as_fast_as_before(leg):
    loc = _localize(leg, leg.map)
    assert loc.stats["global_searches"] == 1 and loc.stats["fixes"] > 100  # the first scan's search found it


def _willow() -> OccupancyMap:
    from importlib.resources import files

    return OccupancyMap.load(files("fgloc.config") / "maps" / "willow-2010-02-18-0.10.yaml")
