"""``--static-transform`` / ``--static-transform-xyzw``: a laser mount the log lacks, given to ``fgloc map``
and ``fgloc run`` alike, an upside-down one included (its scans read mirrored), and one-line errors
for bad values.  The log is written here: the ring world seen by a laser 0.2 m ahead of the robot
centre, mounted upside down and facing backwards (pitched by pi), with no tf at all."""

from __future__ import annotations

import numpy as np
import pytest

from fgloc.cli import main
from fgloc.eval.metrics import evaluate
from fgloc.geometry import compose
from fgloc.io.mcap_writer import LogWriter
from fgloc.io.tum import read_tum
from fgloc.types import LaserScan, Odometry, Trajectory

from . import synth

MOUNT_UPRIGHT = np.array([0.2, 0.0, np.pi])   # the upright laser the upside-down one is equivalent to
RAW_ANGLES = np.radians(np.arange(-135.0, 135.5, 1.0))  # 271 beams, as the driver lists them


@pytest.fixture(scope="module")
def flipped_log(tmp_path_factory):
    d = tmp_path_factory.mktemp("flip")
    world = synth.world_grid()
    full = synth.ring_drive(laps=2)
    n = int(len(full) * 0.6)
    traj = Trajectory(full.stamps[:n], full.poses[:n])
    odom = synth.odometry_of(traj)
    rng = np.random.default_rng(3)
    log = d / "flipped.mcap"
    with LogWriter(log) as w:
        for k, (t, p) in enumerate(zip(traj.stamps, traj.poses, strict=True)):
            lp = compose(p, MOUNT_UPRIGHT)
            # upside down: the raw beam at angle a points at -a in the upright laser's frame
            r = world.raycast(lp[:2], -RAW_ANGLES + lp[2], 30.0) + rng.normal(0.0, 0.005, len(RAW_ANGLES))
            if k:
                dt = t - traj.stamps[k - 1]
                d_od = odom[k] - odom[k - 1]
                c, s = np.cos(odom[k - 1, 2]), np.sin(odom[k - 1, 2])
                tw = np.array([(c * d_od[0] + s * d_od[1]) / dt, (-s * d_od[0] + c * d_od[1]) / dt,
                               np.angle(np.exp(1j * d_od[2])) / dt])
            else:
                tw = np.zeros(3)
            w.write("/odom", Odometry(stamp=float(t) - 0.01, twist=tw, pose=odom[k].copy(),
                                      child_frame_id="base_link"))
            w.write("/scan", LaserScan(stamp=float(t), angle_min=float(RAW_ANGLES[0]),
                                       angle_increment=float(np.radians(1.0)), range_min=0.05, range_max=30.0,
                                       ranges=np.asarray(r, dtype=np.float32), frame_id="laser"))
    mp = d / "world.yaml"
    world.save(mp)
    return {"log": log, "map": mp, "gt": traj, "dir": d}


def _ate(path, gt):
    return evaluate(read_tum(path), gt, align=True).position_rmse_m


@pytest.mark.parametrize("option", [
    ["--static-transform", "base_link", "laser", "0.2", "0", "0.1", "0", "180", "0"],         # pitch pi
    ["--static-transform-xyzw", "base_link", "laser", "0.2", "0", "0.1", "0", "1", "0", "0"],  # the same
])
def test_map_and_run_take_an_upside_down_mount_the_log_lacks(flipped_log, capsys, option):
    d = flipped_log["dir"]
    tag = option[0].strip("-")
    out = d / f"map_{tag}"
    assert main(["map", str(flipped_log["log"]), "-o", str(out), "--no-progress", *option]) == 0
    ate = _ate(out / "trajectory.tum", flipped_log["gt"])
    assert ate < 0.15, ate            # measured: 0.092 m (the same log from an upright laser: 0.090 m)
    run_out = d / f"run_{tag}"
    p0 = flipped_log["gt"].poses[0]
    rc = main(["run", str(flipped_log["log"]), "--map", str(flipped_log["map"]), "-o", str(run_out), "-q",
               "--initial-pose", *(repr(float(v)) for v in p0), *option])
    so = capsys.readouterr().out
    assert rc == 0
    fixes = read_tum(run_out / "fixes.tum")
    assert len(fixes) >= 0.45 * len(flipped_log["gt"])       # a fix at every other scan
    err = evaluate(read_tum(run_out / "trajectory.tum"), flipped_log["gt"]).position_rmse_m
    assert err < 0.03, err                                     # measured: 0.004 m
    assert "speed scale" not in so                             # the odometry agrees with the scans


def test_without_the_mount_the_map_is_wrong(flipped_log, capsys):
    out = flipped_log["dir"] / "map_none"
    rc = main(["map", str(flipped_log["log"]), "-o", str(out), "--no-progress"])
    assert rc in (0, 1)                                            # 1: the self-check flagged the map
    assert _ate(out / "trajectory.tum", flipped_log["gt"]) > 1.0   # measured 1.68 m: mirrored scans
    if rc == 1:
        assert "INCONSISTENT" in (out / "check.yaml").read_text()


@pytest.mark.parametrize("args, message", [
    (["--static-transform", "base_link", "laser", "0.2", "0", "x", "180", "0", "0"],
     "--static-transform needs eight values PARENT CHILD X Y Z ROLL PITCH YAW (m, deg)"),
    (["--static-transform-xyzw", "base_link", "laser", "0.2", "0", "0", "1", "0", "0", "0.5"],
     "--static-transform-xyzw base_link laser: QX QY QZ QW is not a unit quaternion (norm 1.1180)"),
    (["--static-transform", "base_link", "laser", "0.2", "0", "0", "40", "0", "0"],
     "base_link laser: the laser is tilted 40.0 deg from level (roll / pitch); fgloc maps and localizes with a "
     "level laser or one upside down (ROLL 180 or PITCH 180): check the ROLL and PITCH given"),
    (["--static-transform-xyzw", "base_link", "laser", "0.2", "0", "0", "0.3420", "0", "0", "0.9397"],
     "base_link laser: the laser is tilted 40.0 deg from level"),
    (["--static-transform", "odom", "laser", "0.2", "0", "0", "180", "0", "0"],
     "--static-transform: parent frame 'odom': fgloc takes mounts on the robot"),
    (["--static-transform", "base_link", "laser", "nan", "0", "0", "180", "0", "0"],
     "--static-transform base_link laser: every value must be a finite number"),
])
@pytest.mark.parametrize("command", ["map", "run"])
def test_bad_mounts_are_one_line_errors(flipped_log, capsys, command, args, message):
    out = flipped_log["dir"] / f"bad_{command}"
    extra = ["--no-progress"] if command == "map" else ["-q"]
    capsys.readouterr()
    rc = main([command, str(flipped_log["log"]), "-o", str(out), *extra, *args])
    err = capsys.readouterr().err
    assert rc == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("fgloc: error: ") and message in lines[0], err


def test_map_check_takes_the_mount_too(flipped_log, capsys):
    """``fgloc map-check`` reads the log's scans as ``fgloc map`` did: with the mount given to map, the
    map's own scans at the map's own poses match it; without, the scans read at the robot centre
    and unmirrored flag the whole room as changed (what it printed before it took the option)."""
    d = flipped_log["dir"]
    mount = ["--static-transform", "base_link", "laser", "0.2", "0", "0.1", "0", "180", "0"]
    out = d / "map_for_check"
    assert main(["map", str(flipped_log["log"]), "-o", str(out), "--no-progress", "--no-check", *mount]) == 0
    check = ["map-check", str(out / "map.yaml"), str(flipped_log["log"]), "--trajectory",
             str(out / "trajectory.tum"), "--no-progress"]
    capsys.readouterr()
    assert main([*check, "-o", str(d / "check_mount"), *mount]) == 0
    assert "MATCHES" in capsys.readouterr().out
    assert main([*check, "-o", str(d / "check_none")]) == 1
    assert "CHANGED" in capsys.readouterr().out
