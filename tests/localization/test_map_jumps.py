"""The map's placements against the odometry (fgloc.localization.divergence.MapJumps): a jump the wheels
did not drive is counted; the placements of a right map follow the odometry, a skid steer's scrubbed turn
included."""

from __future__ import annotations

import math

import numpy as np

from fgloc.geometry import compose
from fgloc.localization.divergence import MapJumps


def _drive(mj: MapJumps, placed, odom, dt_s: float = 0.1) -> int:
    """Place at each of ``placed`` (every ``dt_s``) with the odometry's pose ``odom`` then; the jumps counted."""
    n = 0
    for k, (p, o) in enumerate(zip(placed, odom, strict=True)):
        n += mj.place(dt_s * k, np.asarray(p, float), np.asarray(o, float))
    return n


def _path(steps, turn_scale: float = 1.0, start=(0.0, 0.0, 0.0)):
    """Poses along ``steps`` (forward m, turn rad) from ``start``; the turns ``turn_scale`` times as large."""
    p = np.asarray(start, float)
    out = [p]
    for fwd, turn in steps:
        p = compose(p, np.array([fwd, 0.0, turn_scale * turn]))
        out.append(p)
    return np.array(out)


# a 10 m leg, a 90 deg left turn over 1 m, another 10 m leg: 0.1 m steps
STEPS = [(0.1, 0.0)] * 100 + [(0.1, math.pi / 20)] * 10 + [(0.1, 0.0)] * 100


def test_placements_that_follow_the_odometry_are_no_jumps():
    truth = _path(STEPS, start=(2.5, 3.0, 0.0))
    odom = _path(STEPS)  # its own frame
    assert _drive(MapJumps(0.5), truth, odom) == 0
    # a skid steer's wheels report 2.5 times the turn: still no jump
    assert _drive(MapJumps(0.5), truth, _path(STEPS, turn_scale=2.5)) == 0
    # placements once a second (every 10th): the same
    assert _drive(MapJumps(0.5), truth[::10], odom[::10]) == 0


def test_a_kidnapping_is_one_jump():
    truth = _path(STEPS, start=(2.5, 3.0, 0.0))
    odom = _path(STEPS)
    placed = truth.copy()
    placed[150:] += np.array([6.0, -4.0, 0.0])  # carried after the turn: the odometry saw nothing
    mj = MapJumps(0.5)
    assert _drive(mj, placed, odom) == 1
    assert mj.worst is not None and abs(mj.worst[1] - math.hypot(6.0, 4.0)) < 1e-6
    assert not mj.repeated


def test_two_kidnappings_minutes_apart_are_not_a_map_that_does_not_fit():
    """Two jumps 0.5 s apart: repeated; the same two placed every 1.2 s (100 s apart): not."""
    truth = _path(STEPS, start=(2.5, 3.0, 0.0))
    odom = _path(STEPS)
    placed = truth.copy()
    placed[50:] += np.array([6.0, -4.0, 0.0])
    placed[55:] += np.array([-3.0, 5.0, 0.0])
    mj = MapJumps(0.5)
    assert _drive(mj, placed, odom) == 2 and mj.repeated and mj.closest_s is not None
    assert abs(mj.closest_s - 0.5) < 1e-9
    placed = truth.copy()
    placed[50:] += np.array([6.0, -4.0, 0.0])
    placed[135:] += np.array([-3.0, 5.0, 0.0])
    mj = MapJumps(0.5)
    assert _drive(mj, placed, odom, dt_s=1.2) == 2 and not mj.repeated


def test_a_turn_the_wheels_did_not_make_is_a_jump():
    """A placement turned 180 deg from the odometry's heading (a mirrored map's other end of the corridor), and
    back: two jumps, whatever the distance."""
    truth = _path(STEPS, start=(2.5, 3.0, 0.0))
    odom = _path(STEPS)
    placed = truth.copy()
    placed[60:90, 2] += math.pi
    mj = MapJumps(0.5)
    # after the first flipped placement the following ones move backwards against its heading: each is a jump
    assert _drive(mj, placed, odom) >= 2
    assert mj.worst is not None and math.degrees(mj.worst[2]) > 170.0
    assert mj.repeated
