"""The map self-check on generated worlds: consistent maps pass, a pass shifted by 0.5 m / 2 deg is
flagged where it is, and a changed world is reported where it changed (seconds, no SLAM)."""

from __future__ import annotations

import numpy as np
import pytest

from fgloc.geometry import compose
from fgloc.mapping.selfcheck import check_against_map, check_consistency
from fgloc.types import Trajectory

from . import synth


@pytest.fixture(scope="module")
def ring():
    world = synth.world_grid()
    traj = synth.ring_drive(laps=3)
    return world, traj, synth.records(world, traj)


def _inject(traj: Trajectory, t_from: float, t_to: float, shift_m: float = 0.5, deg: float = 2.0):
    """The poses of [t_from, t_to] s (after the start) moved rigidly by shift_m and turned by deg
    about their centroid: one pass mapped in the wrong place."""
    p = traj.poses.copy()
    t0 = traj.stamps[0]
    m = (traj.stamps >= t0 + t_from) & (traj.stamps <= t0 + t_to)
    c = p[m, :2].mean(axis=0)
    d = shift_m / np.sqrt(2.0)
    tf = compose(compose(np.array([c[0], c[1], 0.0]), np.array([d, d, np.radians(deg)])), np.array([-c[0], -c[1], 0.0]))
    p[m] = compose(tf, p[m])
    return Trajectory(traj.stamps, p), c, (traj.stamps[m][0], traj.stamps[m][-1])


def test_consistent_map_is_not_flagged(ring):
    _, traj, recs = ring
    res = check_consistency(recs, np.zeros(3), traj)
    assert res.passed and "CONSISTENT" in res.verdict
    assert res.stats["regions_checked"] >= 10  # every region is seen by three laps
    assert res.stats["checked"] >= 200
    assert res.stats["inconsistent"] <= 2
    assert not res.flagged and not res.culprits
    # the passes register to the world's raster (measured 0.011 m / 0.02 deg)
    assert res.registration_n >= 200 and res.registration_m < 0.02 and res.registration_deg < 0.1


def test_small_pose_noise_is_not_flagged(ring):
    """A good SLAM trajectory is a few cm / tenths of a degree off: still consistent."""
    _, traj, recs = ring
    rng = np.random.default_rng(3)
    noise = np.column_stack([rng.normal(0, 0.02, (len(traj), 2)), rng.normal(0, np.radians(0.2), len(traj))])
    noisy = traj.poses + noise
    res = check_consistency(recs, np.zeros(3), Trajectory(traj.stamps, noisy))
    assert res.passed, res.verdict
    # and the registration measures that noise (2 cm per axis, 0.2 deg: measured 0.022 m / 0.22 deg)
    assert 0.015 < res.registration_m < 0.03 and 0.15 < res.registration_deg < 0.3


@pytest.mark.parametrize("window", [(150.0, 175.0), (260.0, 285.0)])
def test_injected_pass_error_is_flagged_in_place(ring, window):
    _, traj, recs = ring
    bad, center, (ta, tb) = _inject(traj, *window)
    res = check_consistency(recs, np.zeros(3), bad)
    assert not res.passed and "INCONSISTENT" in res.verdict
    flagged = res.flagged
    assert flagged
    dist = [float(np.hypot(*(r.center - center))) for r in flagged]
    assert min(dist) < 4.0  # flagged where the pass was moved ...
    assert max(dist) < 9.0  # ... and nowhere else
    worst = max(flagged, key=lambda r: r.n_bad)
    assert 0.3 < worst.offset_m < 0.8 and 1.0 < worst.offset_deg < 3.0
    # the moved pass is named: the other laps agree with each other
    assert len(res.culprits) >= 1
    assert any(a <= tb and b >= ta for a, b in res.culprits)
    assert res.suspects and all("disagree" in s for s in res.suspects)


def test_localization_log_reports_changed_world():
    """A log driven after furniture changed: a box added in a corridor, two pillars gone."""
    world = synth.world_grid()
    box = (10.0, 0.6, 11.0, 1.4)
    changed = synth.world_grid(extra_boxes=[box], removed=[4, 9])
    traj = synth.ring_drive(laps=1)
    same = check_against_map(synth.records(world, traj), np.zeros(3), traj, world)
    assert same.passed and "MATCHES" in same.verdict and not same.changes
    res = check_against_map(synth.records(changed, traj, seed=1), np.zeros(3), traj, world)
    assert not res.passed and "CHANGED" in res.verdict
    added = [c for c in res.changes if c.kind == "added"]
    removed = [c for c in res.changes if c.kind == "removed"]
    assert len(added) == 1 and len(removed) == 2
    bc = np.array([(box[0] + box[2]) / 2, (box[1] + box[3]) / 2])
    assert np.hypot(*(added[0].center - bc)) < 0.6
    gone = [np.array(synth.PILLARS[i]) for i in (4, 9)]
    for c in removed:
        assert min(np.hypot(*(c.center - g)) for g in gone) < 0.4
    assert res.stats["inconsistent"] == 0  # the poses still agree with the map


def test_no_second_pass_is_not_checked():
    world = synth.world_grid()
    full = synth.ring_drive(laps=1)
    half = Trajectory(full.stamps[:100], full.poses[:100])  # one way along two sides
    res = check_consistency(synth.records(world, half), np.zeros(3), half)
    assert res.passed and "NOT CHECKED" in res.verdict


@pytest.mark.parametrize("shift_m", [1.5, 2.5])
def test_gross_pass_error_is_flagged_in_place(ring, shift_m):
    """A pass put metres off (a wrong loop closure) overlaps little where it was put: the check
    searches wider than its local window there (it passed such a map as CONSISTENT before)."""
    _, traj, recs = ring
    bad, center, (ta, tb) = _inject(traj, 150.0, 175.0, shift_m=shift_m, deg=0.0)
    res = check_consistency(recs, np.zeros(3), bad)
    assert not res.passed and "INCONSISTENT" in res.verdict
    dist = [float(np.hypot(*(r.center - center))) for r in res.flagged]
    assert min(dist) < 4.0 and max(dist) < 9.0
    worst = max(res.flagged, key=lambda r: r.n_bad)
    assert abs(worst.offset_m - shift_m) < 0.3
    assert any(a <= tb and b >= ta for a, b in res.culprits)
