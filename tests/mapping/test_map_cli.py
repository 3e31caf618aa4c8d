"""``fgloc map`` / ``fgloc map-check`` on generated CARMEN logs, including bad input: a log that never
comes back, 10 scans, an odometry jump of 10 m, every beam at max range.  Each gives a map (with a
warning) or a one-line error, never a traceback."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from fgloc.cli import main
from fgloc.io.tum import read_tum, write_tum
from fgloc.maps import OccupancyMap
from fgloc.types import Trajectory

from . import synth


def _log(tmp_path, name, traj, world=None, odom=None, ranges=None):
    world = world or synth.world_grid()
    rng = np.random.default_rng(0)
    if ranges is None:
        ranges = [synth.scan_at(world, p, t, rng=rng).ranges for t, p in zip(traj.stamps, traj.poses, strict=True)]
    odom = synth.odometry_of(traj) if odom is None else odom
    return synth.write_carmen(tmp_path / f"{name}.clf.bz2", ranges, odom, traj.stamps)


def _map(tmp_path, log, capsys, *extra):
    out = tmp_path / (log.name.split(".")[0] + "_map")
    rc = main(["map", str(log), "-o", str(out), "--no-progress", *extra])
    cap = capsys.readouterr()
    return rc, out, cap.out, cap.err


def test_map_then_map_check_and_a_moved_pass(tmp_path, capsys):
    full = synth.ring_drive(laps=2)
    n = int(len(full) * 0.65)  # a lap and a third: the start is passed twice
    traj = Trajectory(full.stamps[:n], full.poses[:n])
    log = _log(tmp_path, "ring", traj)
    rc, out, so, se = _map(tmp_path, log, capsys)
    assert rc == 0, se
    for f in ("map.yaml", "map.png", "trajectory.tum", "trajectory_keyframes.tum", "check.yaml", "check.png",
              "mapping.yaml"):
        assert (out / f).is_file()
    assert "map-check: CONSISTENT" in so
    assert len(read_tum(out / "trajectory.tum")) == n  # one pose per scan
    doc = yaml.safe_load((out / "check.yaml").read_text())
    assert doc["passed"] is True and doc["stats"]["regions_checked"] >= 2
    # the map declares what the check measured: the passes' registration and the raster (>= cell / sqrt(12))
    reg = doc["registration"]
    assert reg["scans"] >= 10 and 0.0 <= reg["rms_per_axis_m"] < 0.03
    acc = OccupancyMap.load(out / "map.yaml").accuracy_m
    assert acc == pytest.approx(np.hypot(reg["rms_per_axis_m"], 0.05 / np.sqrt(12)), abs=2e-4)
    # the same check on its own, then on the trajectory with one pass moved by 0.5 m / 2 deg
    assert main(["map-check", str(out / "map.yaml"), str(log), "--no-progress", "-o", str(tmp_path / "c0")]) == 0
    est = read_tum(out / "trajectory.tum")
    p = est.poses.copy()
    late = est.stamps > est.stamps[0] + 0.9 * (est.stamps[-1] - est.stamps[0])  # the second pass at the start
    c = p[late, :2].mean(axis=0)
    from fgloc.geometry import compose

    tf = compose(compose(np.array([c[0], c[1], 0.0]), np.array([0.35, 0.35, np.radians(2.0)])),
                 np.array([-c[0], -c[1], 0.0]))
    p[late] = compose(tf, p[late])
    moved = write_tum(tmp_path / "moved.tum", Trajectory(est.stamps, p))
    capsys.readouterr()
    rc = main(["map-check", str(out / "map.yaml"), str(log), "--trajectory", str(moved), "--mode", "consistency",
               "--no-progress", "-o", str(tmp_path / "c1")])
    so = capsys.readouterr().out
    assert rc == 1 and "map-check: INCONSISTENT" in so
    assert (tmp_path / "c1" / "check.png").is_file()
    doc = yaml.safe_load((tmp_path / "c1" / "check.yaml").read_text())
    flagged = [r for r in doc["regions"] if r["flagged"]]
    assert flagged and min(np.hypot(r["center_m"][0] - c[0], r["center_m"][1] - c[1]) for r in flagged) < 4.0


def test_log_that_never_comes_back(tmp_path, capsys):
    full = synth.ring_drive(laps=1)
    traj = Trajectory(full.stamps[:70], full.poses[:70])  # along one corridor, once
    rc, out, so, se = _map(tmp_path, _log(tmp_path, "oneway", traj), capsys)
    assert rc == 0
    assert "no loop closure" in se and "NOT CHECKED" in so
    m = OccupancyMap.load(out / "map.yaml")
    assert m.occupied.sum() > 200


def test_log_with_ten_scans(tmp_path, capsys):
    full = synth.ring_drive(laps=1)
    traj = Trajectory(full.stamps[:10], full.poses[:10])
    rc, out, so, se = _map(tmp_path, _log(tmp_path, "ten", traj), capsys)
    assert rc == 0
    assert "only 10 scans" in se
    assert len(read_tum(out / "trajectory.tum")) == 10


def test_odometry_jump_is_bridged(tmp_path, capsys):
    full = synth.ring_drive(laps=1)
    traj = Trajectory(full.stamps[:120], full.poses[:120])
    odom = synth.odometry_of(traj)
    odom[60:, 0] += 10.0  # the odometry jumps 10 m once
    rc, out, so, se = _map(tmp_path, _log(tmp_path, "jump", traj, odom=odom), capsys)
    assert rc == 0
    assert "odometry jumped 1 time" in se
    est = read_tum(out / "trajectory.tum")
    steps = np.hypot(*np.diff(est.poses[:, :2], axis=0).T)
    assert steps.max() < 0.6  # no 10 m jump in the trajectory
    # and the trajectory still follows the drive (same shape as the truth)
    span_est = np.hypot(*(est.poses[-1, :2] - est.poses[0, :2]))
    span_true = np.hypot(*(traj.poses[-1, :2] - traj.poses[0, :2]))
    assert abs(span_est - span_true) < 0.5


def test_all_ranges_at_max_is_a_one_line_error_not_a_map(tmp_path, capsys):
    """Every beam at max range: no wall anywhere, nothing to map (before: a map of carved free space
    only, exit 0, its self-check 'passed')."""
    full = synth.ring_drive(laps=1)
    traj = Trajectory(full.stamps[:40], full.poses[:40])
    ranges = [np.full(180, 81.91) for _ in range(40)]
    rc, out, so, se = _map(tmp_path, _log(tmp_path, "blind", traj, ranges=ranges), capsys)
    lines = se.strip().splitlines()
    assert rc == 2 and len(lines) == 1 and "no scan has a return within range (40 scans" in lines[0]
    assert not out.exists()


@pytest.mark.parametrize("content", ["", "ODOM 0 0 0 0 0 0 1.0 h 1.0\n", "FLASER 3 1 2\n"])
def test_unusable_logs_are_one_line_errors(tmp_path, capsys, content):
    log = tmp_path / "bad.clf"
    log.write_text(content)
    rc = main(["map", str(log), "-o", str(tmp_path / "o"), "--no-progress"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and err[0].startswith("fgloc: error:")


def test_map_check_without_trajectory_is_one_line_error(tmp_path, capsys):
    world = synth.world_grid()
    world.save(tmp_path / "w.yaml")
    full = synth.ring_drive(laps=1)
    traj = Trajectory(full.stamps[:20], full.poses[:20])
    log = _log(tmp_path, "short", traj)
    rc = main(["map-check", str(tmp_path / "w.yaml"), str(log), "--no-progress"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "trajectory" in err[0]
