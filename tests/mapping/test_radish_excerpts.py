"""Mapping quality on real data: excerpts of the Radish intel and fr079 logs (data/radish).

The reference is the GMapping-corrected trajectory of the same scans (a reference, not
ground truth); the bounds are about 1.5x what the mapper reaches, and well below what raw
odometry scores, so a regression in scan matching or the graph shows up.
"""

from __future__ import annotations

import numpy as np
import pytest

from fgloc.eval.relations import evaluate_relations, relations_from_reference
from fgloc.io.tum import read_tum
from fgloc.mapping.build import load_records
from fgloc.mapping.slam import MapperConfig, run_slam
from fgloc.maps import OccupancyMap
from fgloc.types import Trajectory

CASES = {  # name: (relation dt window, trans bound m, rot bound deg)
    "intel": ((1.0, 6.0), 0.055, 0.6),
    "fr079": ((1.0, 2.0), 0.045, 0.5),
}


@pytest.fixture(scope="module")
def slam_runs(repo_data):
    out = {}
    for name in CASES:
        recs, mount = load_records(repo_data / "radish" / f"{name}-head.clf.bz2")
        ref = read_tum(repo_data / "radish" / f"{name}-head-reference.tum")
        out[name] = (recs, mount, ref, run_slam(recs, mount, MapperConfig()))
    return out


@pytest.mark.parametrize("name", list(CASES))
def test_relation_error_vs_gmapping_reference(slam_runs, name):
    recs, _, ref, res = slam_runs[name]
    (lo, hi), tb, rb = CASES[name]
    rels = relations_from_reference(ref, lo, hi)
    ev = evaluate_relations(res.scan_trajectory, rels)
    assert ev["unmatched"] == 0
    assert ev["n"] >= 50
    assert ev["trans_mean"] < tb
    assert ev["rot_mean_deg"] < rb
    # and far better than the raw odometry on the same relations
    odom = Trajectory.from_unsorted(np.array([r.stamp for r in recs]), np.array([r.odom for r in recs]))
    ev_odom = evaluate_relations(odom, rels)
    assert ev["rot_mean_deg"] < 0.5 * ev_odom["rot_mean_deg"]


def test_every_scan_has_a_pose(slam_runs):
    recs, _, _, res = slam_runs["fr079"]
    assert len(res.scan_trajectory) == len({r.stamp for r in recs})
    assert len(res.keyframes) >= 100
    assert res.stats["loops"] >= 3  # fr079's first minutes revisit the start corridor


def test_map_is_crisp(slam_runs, tmp_path):
    """Walls are thin: few occupied cells per metre of path, and the map explains its own scans."""
    recs, mount, _, res = slam_runs["fr079"]
    from fgloc.mapping.slam import build_occupancy

    occ = build_occupancy(res, recs, mount)
    n_occ = int(occ.occupied.sum())
    assert 1500 < n_occ < 6000
    # endpoints of every 10th scan lie on (or next to) occupied cells
    from fgloc.geometry import compose, transform_points

    d_all = []
    for rec in recs[::10]:
        i = int(np.argmin(np.abs(res.scan_trajectory.stamps - rec.stamp)))
        pts = rec.scan.points()
        r = np.hypot(pts[:, 0], pts[:, 1])
        pts = pts[r < 10]
        wp = transform_points(compose(res.scan_trajectory.poses[i], mount.pose), pts)
        d_all.append(occ.distance_at(wp, outside=1.0))
    d = np.concatenate(d_all)
    assert np.median(d) <= 0.05
    assert np.mean(d < 0.1) > 0.85


def test_fgloc_map_cli_writes_outputs(repo_data, tmp_path):
    from fgloc.cli import main

    out = tmp_path / "m"
    rc = main(["map", str(repo_data / "radish" / "fr079-head.clf.bz2"), "-o", str(out), "--no-progress",
               "--end", "0.5", "--resolution", "0.1"])
    assert rc == 0
    for f in ("map.yaml", "map.pgm", "map.png", "trajectory.tum", "trajectory_keyframes.tum", "check.yaml",
              "check.png"):
        assert (out / f).is_file()
    m = OccupancyMap.load(out / "map.yaml")
    assert m.resolution == pytest.approx(0.1)
    assert m.occupied.sum() > 100 and m.free.sum() > 10 * m.occupied.sum()
    kf = read_tum(out / "trajectory_keyframes.tum")
    scans = read_tum(out / "trajectory.tum")  # every scan has a pose
    assert 30 < len(kf) < len(scans) <= 300
    assert len(scans) == 300


def test_fgloc_map_missing_log_is_one_line_error(tmp_path, capsys):
    from fgloc.cli import main

    rc = main(["map", str(tmp_path / "nope.clf"), "-o", str(tmp_path / "o"), "--no-progress"])
    assert rc == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "nope.clf" in err[0]


def test_scans_localize_on_the_built_map(slam_runs):
    """The fr079 excerpt's map supports scan-to-map tracking: re-localizing its own scans from
    odometry stays within a few cm of the SLAM trajectory, and matches almost every scan."""
    from fgloc.mapping.localize import track_on_map
    from fgloc.mapping.slam import build_occupancy

    recs, mount, _, res = slam_runs["fr079"]
    occ = build_occupancy(res, recs, mount)
    seg = recs[300:600]
    p0 = res.scan_trajectory.interpolate(seg[0].stamp)[0]
    traj, stats = track_on_map(seg, occ, mount, p0)
    assert stats["matched"] >= 0.95 * stats["scans"]
    slam = res.scan_trajectory.interpolate(traj.stamps)
    d = np.hypot(traj.poses[:, 0] - slam[:, 0], traj.poses[:, 1] - slam[:, 1])
    dyaw = np.abs(np.angle(np.exp(1j * (traj.poses[:, 2] - slam[:, 2]))))
    assert np.sqrt(np.mean(d**2)) < 0.05
    assert np.degrees(np.sqrt(np.mean(dyaw**2))) < 1.0
