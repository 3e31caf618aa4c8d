"""Honest fixes on real SLAM maps (issue 13 item 4): the native matcher's fix NEES against SLAM on
the Radish excerpts (data/radish), and on the simulated paper run against the truth.

Each excerpt is mapped by fgloc.mapping; a 150-scan segment is matched (every 2nd scan, guesses
5 cm / 2 deg off the SLAM pose) against the map of the keyframes *outside* the segment's time
window +-20 s, in the same frame: another pass through the same rooms.  The SLAM map's passes
disagree by centimetres, which no scan can see: without the map-registration floor the fixes
claim a few millimetres and NEES is far above its dimension, 3; with the map's accuracy declared as
half a cell (what a SLAM map is good to), it comes down.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from fgloc.frontends.native import NativeMatcher
from fgloc.geometry import between, wrap_angle

HALF_CELL = 0.025  # the SLAM maps' 5 cm cells: the accuracy such a map declares


def _segment_nees(log, accuracies):
    from scipy.spatial import cKDTree

    from fgloc.mapping.build import load_records
    from fgloc.mapping.slam import MapperConfig, build_occupancy, run_slam

    recs, mount = load_records(log)
    slam = run_slam(recs, mount, MapperConfig())
    st = np.array([r.stamp for r in recs])
    P = slam.scan_trajectory.interpolate(st)
    kt = np.array([k.stamp for k in slam.keyframes])
    best = None
    for s0 in range(0, len(recs) - 150, 25):  # the segment best covered by the other passes
        out = (kt < st[s0] - 20) | (kt > st[s0 + 149] + 20)
        if out.sum() < 10:
            continue
        cov = float((cKDTree(slam.keyframe_poses[out, :2]).query(P[s0:s0 + 150, :2])[0] < 2.0).mean())
        if best is None or cov >= best[1]:
            best = (s0, cov)
    s0 = best[0]
    out = (kt < st[s0] - 20) | (kt > st[s0 + 149] + 20)
    occ = build_occupancy(replace(slam, keyframes=[k for k, o in zip(slam.keyframes, out, strict=True) if o],
                                  keyframe_poses=slam.keyframe_poses[out]), recs, mount)
    res = {}
    for acc in accuracies:
        fe = NativeMatcher(occ, mount, map_accuracy_m=acc)
        rng = np.random.default_rng(0)
        nees = []
        for i in range(s0 + 2, s0 + 149, 2):
            fe.reset()
            fe.pre(recs[i - 1].scan, between(recs[i - 2].odom, recs[i - 1].odom))
            g = P[i] + np.r_[rng.normal(0, 0.05, 2), rng.normal(0, np.radians(2), 1)]
            r = fe.match(recs[i].scan, g, between(recs[i - 1].odom, recs[i].odom))
            if r.ok:
                e = r.pose - P[i]
                e[2] = wrap_angle(e[2])
                nees.append(float(e @ np.linalg.solve(r.cov, e)))
        res[acc] = np.array(nees)
    return res


@pytest.fixture(scope="module")
def radish_nees(repo_data):
    return {name: _segment_nees(repo_data / "radish" / f"{name}-head.clf.bz2", (0.0, HALF_CELL))
            for name in ("intel", "fr079")}


def test_fix_nees_on_real_maps_is_near_its_dimension(radish_nees):
    """NEES pooled over both excerpts (3 dof: mean 3, median 2.37).  Measured without the floor
    (mean / median): intel 20.7 / 7.0, fr079 3.6 / 2.6; with half a cell declared (a floor of its part
    beyond the raster's, 2.04 cm on these 5 cm cells): intel 15.8 / 5.2, fr079 1.5 / 1.0, pooled
    12.5 / 4.2 -> 8.9 / 1.8 (the mean is a few intel fixes').  The full logs' fr079 and aces segments
    (tools/eval_frontends_real.py) go from 34-51 to 1.8-2.6 with the accuracy fgloc map measures."""
    before = np.concatenate([radish_nees[n][0.0] for n in radish_nees])
    after = np.concatenate([radish_nees[n][HALF_CELL] for n in radish_nees])
    assert len(after) >= 100
    assert np.mean(before) > 10.0
    assert np.mean(after) < 0.75 * np.mean(before)
    assert np.median(after) < 0.6 * np.median(before)
    assert 1.0 < np.median(after) < 3.5


def test_fix_nees_on_the_simulator_is_unchanged(paper_sim):
    """The simulator's map is its world rasterized (accuracy_m = 0): no floor, NEES as before (~2.4-2.9)."""
    from fgloc.geometry import interpolate_poses
    from fgloc.types import LaserScan, Odometry

    assert paper_sim.map.accuracy_m == 0.0
    scans = [m for _, m in paper_sim.messages if isinstance(m, LaserScan)]
    odoms = [m for t, m in paper_sim.messages if isinstance(m, Odometry) and t != "/ground_truth"]
    st = np.array([s.stamp for s in scans])
    gt = paper_sim.ground_truth.interpolate(st)
    od = interpolate_poses(np.array([o.stamp for o in odoms]), np.array([o.pose for o in odoms]), st)
    fe = NativeMatcher(paper_sim.map, paper_sim.laser_mount)
    rng = np.random.default_rng(0)
    nees = []
    for i in range(2, len(scans), 8):
        fe.reset()
        fe.pre(scans[i - 1], between(od[i - 2], od[i - 1]))
        g = gt[i] + np.r_[rng.normal(0, 0.05, 2), rng.normal(0, np.radians(2), 1)]
        r = fe.match(scans[i], g, between(od[i - 1], od[i]))
        if r.ok:
            e = r.pose - gt[i]
            e[2] = wrap_angle(e[2])
            nees.append(float(e @ np.linalg.solve(r.cov, e)))
    assert len(nees) > 300
    assert 1.5 < float(np.mean(nees)) < 4.5
