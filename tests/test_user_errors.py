"""Every command tried as a new user would: mistakes and damaged inputs give one line and the
documented exit code (docs/user-errors.md lists each case with the test here or elsewhere that
holds it)."""

from __future__ import annotations

from pathlib import Path

import pytest

from fgloc.testing.cli import last_error_line as one_error_line
from fgloc.testing.cli import run_cli as fgloc


@pytest.fixture(scope="module")
def short_log(tmp_path_factory) -> dict:
    """A 10 s simulated run (scans in frame 'laser', /odom, /imu, /tf_static) and its map."""
    from fgloc.sim import simulate_paper, write_sim

    d = tmp_path_factory.mktemp("short")
    sim = simulate_paper(seed=0, route=[[2.5, 3.0], [6.5, 3.0]])
    write_sim(sim, d)
    return {"dir": d, "log": d / "log.mcap", "map": d / "map.yaml", "start": ("2.5", "3.0", "0.0")}


# ------------------------------------------------------------------ frames and topics
def test_run_mount_of_a_frame_the_log_does_not_have(short_log, tmp_path):
    rc, _, err = fgloc("run", short_log["log"], "-o", tmp_path / "o", "-q",
                       "--static-transform", "base_link", "rplidar_link", "0.1", "0", "0.2", "0", "0", "0")
    assert rc == 2
    line = one_error_line(err)
    assert line.startswith(f"{short_log['log']}: --static-transform base_link rplidar_link: the log has no sensor "
                           "frame 'rplidar_link' (its scans are in 'laser'")
    assert "e.g. --static-transform base_link laser" in line
    assert not (tmp_path / "o" / "run.mcap").exists()


def test_map_mount_of_a_frame_the_log_does_not_have(short_log, tmp_path):
    rc, _, err = fgloc("map", short_log["log"], "-o", tmp_path / "m", "--no-progress",
                       "--static-transform", "base_link", "rplidar_link", "0.1", "0", "0.2", "0", "0", "0")
    assert rc == 2
    assert one_error_line(err) == (
        f"{short_log['log']}: --static-transform base_link rplidar_link: the log's scans are in 'laser', not "
        "'rplidar_link' (mapping uses the laser's mount only): give the scans' frame as CHILD, e.g. "
        "--static-transform base_link laser ...")


def test_relative_topic_names_resolve_as_ros_does_and_empty_is_none(short_log, tmp_path):
    """--scan-topic scan is /scan (ROS name resolution); --imu-topic "" uses no IMU."""
    a, b, c = tmp_path / "a", tmp_path / "b", tmp_path / "c"
    common = ("--map", short_log["map"], "--initial-pose", *short_log["start"], "-q")
    assert fgloc("run", short_log["log"], "-o", a, *common)[0] == 0
    assert fgloc("run", short_log["log"], "-o", b, *common, "--scan-topic", "scan", "--odom-topic", "odom/")[0] == 0
    assert (a / "trajectory.tum").read_bytes() == (b / "trajectory.tum").read_bytes()
    rc, out, err = fgloc("run", short_log["log"], "-o", c, *common, "--imu-topic", "")
    assert rc == 0, err
    assert "imu 0," in out and "imu 0," not in fgloc("run", short_log["log"], "-o", a, *common)[1]
    rc, _, err = fgloc("run", short_log["log"], "-o", c, *common, "--scan-topic", "laser_scan")
    assert rc == 2 and one_error_line(err).startswith(f"{short_log['log']}: --scan-topic /laser_scan: no such topic")


# ------------------------------------------------------------------ one spelling for each option
def test_version_flag():
    from fgloc import __version__

    for flag in ("--version", "-V"):
        rc, out, _ = fgloc(flag)
        assert rc == 0 and out.strip() == f"fgloc {__version__}"


def test_yaw_with_its_unit_is_the_same_pose(short_log, tmp_path):
    """--initial-pose takes the yaw in radians or with its unit (90deg); a yaw that is surely degrees
    given bare is a one-line error saying so; a word is one line too."""
    common = ("--map", short_log["map"], "-q")
    a, b = tmp_path / "a", tmp_path / "b"
    assert fgloc("run", short_log["log"], "-o", a, *common, "--initial-pose", "2.5", "3", "0")[0] == 0
    assert fgloc("run", short_log["log"], "-o", b, *common, "--initial-pose", "2.5", "3", "0deg")[0] == 0
    assert (a / "trajectory.tum").read_bytes() == (b / "trajectory.tum").read_bytes()
    from fgloc.app.units import pose_arg, pose_value

    assert pose_arg((1.0, 2.0, pose_value("90deg"))) == pytest.approx((1.0, 2.0, 1.5707963267948966))
    assert pose_arg((1.0, 2.0, pose_value("-1.2rad"))) == (1.0, 2.0, -1.2)
    rc, _, err = fgloc("run", short_log["log"], "-o", b, *common, "--initial-pose", "2.5", "3", "90")
    assert rc == 2 and "yaw 90 is in radians (did you mean 1.5708 for 90 deg?)" in one_error_line(err)
    rc, _, err = fgloc("run", short_log["log"], "-o", b, *common, "--initial-pose", "2.5", "3", "east")
    assert rc == 2 and one_error_line(err).startswith("--initial-pose needs three values X Y YAW (m, m, rad or with "
                                                      "its unit: 90deg")
    rc, _, err = fgloc("run", short_log["log"], "-o", b, *common, "--initial-pose", "2.5deg", "3", "0")
    assert rc == 2 and one_error_line(err) == ("--initial-pose: X and Y are metres; only YAW takes a unit (e.g. "
                                               "--initial-pose 2.5 3.0 90deg)")


def test_output_and_quiet_spellings(short_log, tmp_path, capsys):
    """-o/--output everywhere (simulate's old --out kept hidden); -q/--quiet everywhere (map's old
    --no-progress kept hidden); no carriage-return bars into a pipe."""
    rc, _, err = fgloc("simulate", "paper", "--output", tmp_path / "s1", "--seed", "3")
    assert rc == 0, err
    rc, _, err = fgloc("simulate", "paper", "--out", tmp_path / "s2", "--seed", "3")
    assert rc == 0, err
    assert (tmp_path / "s1" / "log.mcap").stat().st_size == (tmp_path / "s2" / "log.mcap").stat().st_size
    rc, _, err = fgloc("simulate", "paper")
    assert rc == 2 and one_error_line(err) == "fgloc simulate paper: give the output folder with -o / --output"
    for flag in ("-q", "--quiet", "--no-progress"):
        rc, out, err = fgloc("map", short_log["log"], "-o", tmp_path / f"m{flag}", "--no-check", flag)
        assert rc == 0, err
        assert "\r" not in err
    rc, _, err = fgloc("map", short_log["log"], "-o", tmp_path / "m4", "--no-check")
    assert rc == 0 and "\r" not in err  # not a terminal: no bar
    import subprocess
    import sys

    helps = subprocess.run([sys.executable, "-m", "fgloc.cli", "map", "--help"], capture_output=True, text=True,
                           timeout=120).stdout
    assert "--quiet" in helps and "--no-progress" not in helps


# ------------------------------------------------------------------ AMCL on a robot that stands still
def test_amcl_on_a_standing_robot_gives_a_pose_and_says_why_it_waits(short_log):
    """nav2's parameters, global localization, the robot standing: AMCL updates once and then waits
    for update_min_d / update_min_a motion.  A pose anyway (the cloud's, as nav2 publishes it), every
    scan counted as no fix with the reason, and no literal 'N' in a grouped reason."""
    import dataclasses

    import numpy as np
    import yaml

    from fgloc.config import parse_config
    from fgloc.io import open_log
    from fgloc.localization import build_session
    from fgloc.localization.localizer import reason_kind
    from fgloc.maps import OccupancyMap
    from fgloc.porting import from_nav2
    from fgloc.types import Odometry

    nav2 = Path(__file__).parent / "backends" / "data" / "porting" / "nav2_params_amcl.yaml"
    cfg = parse_config(from_nav2(yaml.safe_load(nav2.read_text()))[0])
    src = open_log(short_log["log"])
    scan = next(m for t, m in src.messages(["/scan"]))
    session = build_session(OccupancyMap.load(short_log["map"]), src.laser_mount(), frontend="amcl", config=cfg)
    for k in range(12):
        t = float(scan.stamp) + 0.1 * k
        session.feed("/odom", Odometry(t - 0.01, np.zeros(3), np.eye(3) * 1e-4, np.zeros(3), np.eye(3) * 1e-4))
        session.feed("/scan", dataclasses.replace(scan, stamp=t))
    final = session.finish()
    st = session.loc.stats
    assert len(final) > 0  # a pose anyway
    assert st["fixes"] == 0 and st["no_fix"] == 12
    reasons = st["no_fix_reasons"]
    assert reasons.get("global localization: waiting for motion", 0) >= 10, reasons
    assert not any(" N " in k or "N%" in k for k in reasons)
    assert reason_kind("outside the map: the beams end in unmapped space (62 %), dead reckoning (x)") == \
        "outside the map: the beams end in unmapped space, dead reckoning"


def test_latency_line_is_not_contradictory():
    from fgloc.localization.sources.report import SourceReport, summary_lines
    from fgloc.localization.stats import RunStats

    rep = SourceReport("pose", accepted=10, latency_s=0.0, latency_estimate_s=0.1196, latency_sigma_s=0.0113,
                       latency_not_applied="not significant yet")
    lines = summary_lines(RunStats(sources={"scan": rep}))
    line = next(ln for ln in lines if "latency" in ln)
    assert "latency 0.0 ms in use; measured 119.6 +- 11.3 ms, not applied (not significant yet)" in line
    rep.latency_s, rep.latency_not_applied = 0.1196, None
    line = next(ln for ln in summary_lines(RunStats(sources={"scan": rep})) if "latency" in ln)
    assert "latency 119.6 +- 11.3 ms (estimated)" in line
    # five fixes: an estimate of -25463.5 +- 29575301.7 ms is no number to print
    rep.latency_s, rep.latency_estimate_s, rep.latency_sigma_s = 0.0, -25.4635, 29575.3017
    rep.latency_not_applied = "not significant yet"
    line = next(ln for ln in summary_lines(RunStats(sources={"scan": rep})) if "latency" in ln)
    assert "latency 0.0 ms in use; too few fixes to measure it" in line
    assert "25463" not in line


# ------------------------------------------------------------------ the table of docs/user-errors.md
@pytest.fixture(scope="module")
def inputs(short_log, tmp_path_factory) -> dict:
    """Damaged and wrong inputs beside the good short log."""
    import yaml

    d = tmp_path_factory.mktemp("bad")
    (d / "empty.mcap").write_bytes(b"")
    (d / "garbage.bag").write_bytes(bytes(range(256)) * 40)
    (d / "three.tum").write_text("1 2 3\n")
    (d / "notes.txt").write_text("my notes\n")
    (d / "exists.tum").write_text("# not fgloc's\n")
    vel = [False] * 6 + [True, True, False, False, False, True] + [False] * 3
    (d / "typo.yaml").write_text(yaml.safe_dump({"ekf_node": {"ros__parameters": {
        "odom0": "/odom", "odom0_confg": vel, "imu0": "/imu", "imu0_config": [False] * 5 + [True] + [False] * 9}}}))
    (d / "badkey.yaml").write_text("pipeline:\n  frontend_evry: 1\n")
    import shutil

    shutil.copy(short_log["log"], d / "run.mcap")  # a log named as fgloc run's output
    rc, _, err = fgloc("import", short_log["log"], "-o", d / "scans.mcap", "--topic", "/scan", "--topic", "/tf_static")
    assert rc == 0, err  # scans without odometry
    return {**short_log, "bad": d}


#: (id, command line with {log} {map} {bad} {tmp}, exit status, the start of the one line on stderr or stdout)
CASES = [
    ("run-missing-log", "run {bad}/nope.mcap -o {tmp}/o", 2, "{bad}/nope.mcap: log file not found"),
    ("run-empty-log", "run {bad}/empty.mcap -o {tmp}/o", 2, "{bad}/empty.mcap: empty file (0 bytes), not an MCAP log"),
    ("run-not-a-log", "run {bad}/garbage.bag -o {tmp}/o", 2, "{bad}/garbage.bag: not a log fgloc reads"),
    ("run-absent-topic", "run {log} -o {tmp}/o --odom-topic /wheels", 2, "{log}: --odom-topic /wheels: no such topic"),
    ("run-wrong-type", "run {log} -o {tmp}/o --scan-topic /odom", 2,
     "{log}: topic '/odom' has type nav_msgs/msg/Odometry"),
    ("run-yaw-degrees", "run {log} --map {map} --initial-pose 2.5 3 90 -o {tmp}/o", 2,
     "--initial-pose: yaw 90 is in radians (did you mean 1.5708 for 90 deg?)"),
    ("run-two-values", "run {log} --initial-pose 2.5 3 -o {tmp}/o", 2, "--initial-pose needs three values X Y YAW"),
    ("run-map-image", "run {log} --map {dir}/map.pgm -o {tmp}/o", 2, "{dir}/map.pgm: this is the map's image"),
    ("run-bad-config-key", "run {log} --config {bad}/badkey.yaml -o {tmp}/o", 2,
     "{bad}/badkey.yaml: pipeline.frontend_evry: unknown key"),
    ("run-unknown-backend", "run {log} --backend ukf -o {tmp}/o", 2, "unknown back-end 'ukf'"),
    ("run-output-is-input", "run {bad}/run.mcap -o {bad}", 2, "{bad}/run.mcap"),
    ("batch-no-match", "batch run {bad}/nothing-*.mcap -o {tmp}/b", 2, "{bad}/nothing-*.mcap: pattern matches no file"),
    ("batch-engine", "batch run {log} -o {tmp}/b --engine spark", 2, "unknown engine 'spark'"),
    ("batch-corrupt-log", "batch run {log} {bad}/garbage.bag -o {tmp}/b -j 1 -q", 1, ""),
    ("map-not-a-log", "map {bad}/garbage.bag -o {tmp}/m -q", 2, "{bad}/garbage.bag: not a log fgloc reads"),
    ("map-no-odometry", "map {bad}/scans.mcap -o {tmp}/m -q --odom-topic /wheels", 2,
     "{bad}/scans.mcap: no odometry on /wheels"),
    ("map-check-no-map", "map-check {bad}/none.yaml {log} -q", 2, "{bad}/none.yaml"),
    ("eval-one-file", "eval {dir}/ground_truth.tum", 2, "{dir}/ground_truth.tum: fgloc eval needs an estimate"),
    ("eval-three-columns", "eval {bad}/three.tum {dir}/ground_truth.tum", 2, "{bad}/three.tum:1: expected 8 numbers"),
    ("eval-wrong-topic", "eval {dir}/ground_truth.tum {log}:/scan", 2, "{log}: /scan is sensor_msgs/msg/LaserScan"),
    ("export-exists", "export {log} -o {bad}/exists.tum", 2, "{bad}/exists.tum: exists; pass --force"),
    ("import-rename-form", "import {log} -o {tmp}/i.mcap --rename /scan", 2, "--rename /scan: give OLD=NEW"),
    ("import-missing-topic", "import {log} -o {tmp}/i.mcap --topic /laser", 2,
     "{log}: --topic /laser: no such topic in the log"),
    ("import-output-is-input", "import {log} -o {log}", 2, "{log}: is the input"),
    ("port-typo", "config from-robot-localization {bad}/typo.yaml -o {tmp}/c.yaml", 2,
     "{bad}/typo.yaml: the converted config has no source of motion"),
    ("port-not-params", "config from-robot-localization {bad}/notes.txt", 2, "{bad}/notes.txt: not a YAML mapping"),
    ("live-no-sensor", "live --duration 0.1", 2, "fgloc live: give --serial URL and/or --laser HOST:PORT"),
    ("live-missing-port", "live --serial {bad}/ttyUSB9 --duration 0.1", 2, "{bad}/ttyUSB9: no such serial port"),
    ("simulate-no-output", "simulate paper", 2, "fgloc simulate paper: give the output folder"),
    ("simulate-unknown-scenario", "simulate scenario wheelslip -o {tmp}/s", 2,
     "wheelslip: no such scenario file, and no shipped scenario of that name (did you mean wheel_slip?)"),
    ("info-missing", "info {bad}/nope.bag", 2, "{bad}/nope.bag: log file not found"),
    ("config-missing", "config show --config {bad}/none.yaml", 2, "{bad}/none.yaml: config file not found"),
]


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_case(inputs, tmp_path, case):
    """Each mistake: the documented exit status and one line (``fgloc: error: ...`` for status 2)."""
    _id, line, rc_want, start = case
    fmt = {"log": inputs["log"], "map": inputs["map"], "bad": inputs["bad"], "tmp": tmp_path, "dir": inputs["dir"]}
    rc, out, err = fgloc(*line.format(**fmt).split())
    assert rc == rc_want, (line, rc, out, err)
    assert "Traceback" not in out + err
    if rc_want == 2:
        msg = one_error_line(err)
        assert msg.startswith(start.format(**fmt)), msg
        assert len([ln for ln in err.splitlines() if ln.startswith("fgloc: error:")]) == 1


def test_batch_writes_no_bar_into_a_pipe(short_log, tmp_path):
    rc, out, err = fgloc("batch", "run", short_log["log"], "-o", tmp_path / "b", "-j", "1")
    assert rc == 0, out + err
    assert "\r" not in err and "\r" not in out
