"""Every command tried as a new user would: mistakes and damaged inputs give one line and the
documented exit code (docs/user-errors.md lists each case with the test here or elsewhere that
holds it)."""

from __future__ import annotations

import contextlib
import io

import pytest


def fgloc(*args) -> tuple[int, str, str]:
    """``fgloc ARGS`` in this process: (exit status, stdout, stderr)."""
    from fgloc.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main([str(a) for a in args])
    return rc, out.getvalue(), err.getvalue()


def one_error_line(err: str) -> str:
    """The ``fgloc: error: ...`` line of stderr (warnings may come before it), checked to be the last."""
    lines = [ln for ln in err.strip().splitlines() if ln]
    assert lines and lines[-1].startswith("fgloc: error: "), err
    assert "Traceback" not in err
    return lines[-1].removeprefix("fgloc: error: ")


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
    assert "compass 0," in out and "compass 0," not in fgloc("run", short_log["log"], "-o", a, *common)[1]
    rc, _, err = fgloc("run", short_log["log"], "-o", c, *common, "--scan-topic", "laser_scan")
    assert rc == 2 and one_error_line(err).startswith(f"{short_log['log']}: --scan-topic /laser_scan: no such topic")
