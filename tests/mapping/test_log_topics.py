"""Which topics ``fgloc map`` and ``fgloc run`` read, on logs written here: one rule for a default
topic the log lacks (its only topic of that type, as ``fgloc import``; said on stderr), a
scan-only log refused up front with a one-line ``fgloc: error: FILE: problem`` (one with an IMU
but no odometry too, without a map), and a laser
whose frame is called ``rear_laser`` kept unless a front laser shares its topic."""

from __future__ import annotations

import numpy as np
import pytest

from fgloc.cli import main
from fgloc.io.mcap_writer import LogWriter
from fgloc.io.tum import read_tum
from fgloc.mapping.source import pair_scans, rear_frames
from fgloc.types import Imu, LaserScan, Odometry, Trajectory

from . import synth


def _write(path, n=60, scan_topic="/scan", odom_topic: str | None = "/odom", frame="laser",
           imu_topic: str | None = None):
    world = synth.world_grid()
    full = synth.ring_drive(laps=1)
    traj = Trajectory(full.stamps[:n], full.poses[:n])
    odom = synth.odometry_of(traj)
    rng = np.random.default_rng(5)
    with LogWriter(path) as w:
        for k, (t, p) in enumerate(zip(traj.stamps, traj.poses, strict=True)):
            if odom_topic is not None:
                w.write(odom_topic, Odometry(stamp=float(t) - 0.01, twist=np.zeros(3), pose=odom[k].copy()))
            if imu_topic is not None:
                yaw = float(p[2])
                w.write(imu_topic, Imu(stamp=float(t) - 0.005, angular_velocity_radps=np.zeros(3),
                                       orientation_xyzw=np.array([0.0, 0.0, np.sin(yaw / 2), np.cos(yaw / 2)])))
            sc = synth.scan_at(world, p, float(t), rng=rng)
            sc.frame_id = frame
            w.write(scan_topic, sc)
    return path


def _cli(args, capsys):
    capsys.readouterr()
    rc = main(args)
    o, e = capsys.readouterr()
    assert "Traceback" not in o + e
    return rc, o, e


def test_a_scan_only_log_is_refused_up_front_without_a_map(tmp_path, capsys):
    log = _write(tmp_path / "scans.mcap", odom_topic=None)
    out = tmp_path / "run"
    rc, _, err = _cli(["run", str(log), "-o", str(out), "-q"], capsys)
    assert rc == 2                         # was: outputs written, then rc 3 "no pose was estimated"
    assert err.strip() == (
        f"fgloc: error: {log}: the log has laser scans only (60 on /scan), no odometry or IMU: localize them on "
        f"a map with --map MAP.yaml (fgloc map {log} builds one from the scans), or name the odometry / IMU "
        "topic with --odom-topic / --imu-topic; its topics: /scan (sensor_msgs/msg/LaserScan, 60)")
    assert not out.exists()


def test_an_odometry_topic_that_is_not_there_is_an_error_not_scans_alone(tmp_path, capsys):
    log = _write(tmp_path / "scans.mcap", odom_topic=None)
    rc, _, err = _cli(["map", str(log), "-o", str(tmp_path / "map"), "--no-progress", "--odom-topic", "/wheels"],
                      capsys)
    assert rc == 2
    assert err.strip() == (
        f"fgloc: error: {log}: no odometry on /wheels: name the wheel odometry's topic with --odom-topic (or map "
        "the scans alone with --odom-topic ''); its topics: /scan (sensor_msgs/msg/LaserScan, 60)")


def test_scans_and_an_imu_without_odometry_are_refused_without_a_map(tmp_path, capsys):
    """An IMU turns the robot but never moves it: without odometry and without a map every pose
    would stay at the start (an Isaac Sim log with /scan and /imu_data, a robot driving a 123 s loop,
    was written as 895 poses at x = y = 0 with rc 0).  With the map, the scans place the robot."""
    log = _write(tmp_path / "scan_imu.mcap", odom_topic=None, imu_topic="/imu")
    out = tmp_path / "run"
    rc, _, err = _cli(["run", str(log), "-o", str(out), "-q"], capsys)
    assert rc == 2
    assert err.strip() == (
        f"fgloc: error: {log}: no odometry, and the IMU (60 on /imu) gives heading only: without a map every "
        "pose would stay at the start; localize on a map with --map MAP.yaml, or name the odometry topic with "
        "--odom-topic; its topics: /imu (sensor_msgs/msg/Imu, 60), /scan (sensor_msgs/msg/LaserScan, 60)")
    assert not out.exists()
    mp = tmp_path / "world.yaml"
    synth.world_grid().save(mp)
    rc, so, err = _cli(["run", str(log), "-o", str(out), "-q", "--map", str(mp)], capsys)
    assert rc == 0, err
    traj = read_tum(out / "trajectory.tum")
    assert np.ptp(traj.poses[:, 0]) > 1.0 or np.ptp(traj.poses[:, 1]) > 1.0   # the robot moves


def test_the_only_topic_of_a_type_stands_in_for_a_missing_default(tmp_path, capsys, caplog):
    log = _write(tmp_path / "named.mcap", scan_topic="scan", odom_topic="wheel/odom")  # no /scan, no /odom
    rc, so, err = _cli(["map", str(log), "-o", str(tmp_path / "map"), "--no-progress"], capsys)
    assert rc == 0, err                    # was: rc 2, "topic '/scan' not in log"
    said = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]  # stderr: "fgloc: WARNING: ..."
    assert f"{log}: no /scan topic; using scan (sensor_msgs/msg/LaserScan), the log's only topic of that type" in said
    assert f"{log}: no /odom topic; using wheel/odom (nav_msgs/msg/Odometry), the log's only topic of that type" in said
    assert len(read_tum(tmp_path / "map" / "trajectory.tum")) == 60
    caplog.clear()
    rc, so, err = _cli(["run", str(log), "-o", str(tmp_path / "run"), "-q", "--map",
                        str(tmp_path / "map" / "map.yaml")], capsys)
    assert rc == 0, err
    said = " ".join(r.getMessage() for r in caplog.records)
    assert "using scan (sensor_msgs/msg/LaserScan)" in said and "using wheel/odom" in said
    line = " ".join(so.split())
    assert "scans 60, fixes 30," in line and "odom (odometry wheel/odom: vx vy vyaw): 60 accepted" in line
    # a name the user gives is theirs: an absent one is an error, not a guess
    rc, _, err = _cli(["map", str(log), "-o", str(tmp_path / "m2"), "--no-progress", "--scan-topic", "/base_scan"],
                      capsys)
    assert rc == 2 and f"fgloc: error: {log}: topic '/base_scan' not in log" in err


def test_a_rear_laser_alone_is_kept(tmp_path, capsys):
    log = _write(tmp_path / "rear.mcap", frame="rear_laser")
    rc, _, err = _cli(["map", str(log), "-o", str(tmp_path / "map"), "--no-progress"], capsys)
    assert rc == 0, err                    # was: rc 2, "log has no laser scans"
    assert len(read_tum(tmp_path / "map" / "trajectory.tum")) == 60


def test_a_rear_laser_beside_a_front_one_is_left_out():
    assert rear_frames({"laser", "rear_laser"}) == {"rear_laser"}
    assert rear_frames({"rear_laser"}) == set()
    assert rear_frames({"/rear_laser", "rear_laser"}) == set()

    def scan(t, frame):
        return LaserScan(stamp=t, angle_min=0.0, angle_increment=0.1, range_min=0.1, range_max=10.0,
                         ranges=np.ones(5, dtype=np.float32), frame_id=frame)

    msgs = [("/odom", Odometry(stamp=0.0, twist=np.zeros(3), pose=np.zeros(3)))]
    msgs += [("/scan", scan(0.1 * k, "rear_laser" if k % 2 else "laser")) for k in range(1, 7)]
    msgs += [("/odom", Odometry(stamp=1.0, twist=np.zeros(3), pose=np.array([1.0, 0.0, 0.0])))]
    recs, _ = pair_scans(msgs)
    assert [r.stamp for r in recs] == pytest.approx([0.2, 0.4, 0.6])
    assert [r.odom[0] for r in recs] == pytest.approx([0.2, 0.4, 0.6])


def test_a_config_whose_sources_are_not_in_the_log_names_the_logs_topics(tmp_path, capsys):
    """A converted robot_localization file names its robot's topics.  On a log with other ones it
    said "the log has laser scans only ..., no odometry or IMU" although the log had /odom and
    /imu (a public TurtleBot3 bag with a classmate's ekf.yaml); now it says which of the config's
    topics are missing and which odometry / IMU topics the log has."""
    log = _write(tmp_path / "tb3.mcap", imu_topic="/imu")
    cfg = tmp_path / "rl.yaml"
    cfg.write_text("sources:\n  inputs:\n"
                   "    odom0: {type: odometry, topic: /diff_drive_controller/odom, use: [vx, vyaw]}\n"
                   "    imu0: {type: imu, topic: /imu_broadcaster/imu, use: [vyaw]}\n")
    out = tmp_path / "run"
    rc, _, err = _cli(["run", str(log), "--config", str(cfg), "-o", str(out), "-q"], capsys)
    assert rc == 2
    assert err.strip() == (
        f"fgloc: error: {log}: none of the config's sources is in the log (sources.inputs: "
        "/diff_drive_controller/odom (odometry), /imu_broadcaster/imu (imu)); its odometry / IMU topics: "
        "/imu (sensor_msgs/msg/Imu, 60), /odom (nav_msgs/msg/Odometry, 60): set sources.inputs.NAME.topic")
    assert not out.exists()
