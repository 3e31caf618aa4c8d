"""``fgloc map`` on a log with laser scans and no odometry (a handheld or tracked lidar, a leg
tracker's bags, a motion-capture arena run): the scans are matched to each other alone, each guess
the last tracked pose moved on at the last step's velocity.  Logs written here: the ring world's
corridor driven at 10 Hz, a robot standing still."""

from __future__ import annotations

import numpy as np
import yaml

from fgloc.cli import main
from fgloc.geometry import between, wrap_angle
from fgloc.io.mcap_writer import LogWriter
from fgloc.io.tum import read_tum
from fgloc.types import Odometry, Trajectory

from . import synth

SCANS_ALONE = ("no odometry in the log: the scans were matched to each other alone (a scan that does not fit the "
               "local map is placed by a constant-velocity guess)")


def _write(path, traj: Trajectory, odom_topics: tuple[str, ...] = ()) -> None:
    world = synth.world_grid()
    rng = np.random.default_rng(3)
    with LogWriter(path) as w:
        for t, p in zip(traj.stamps, traj.poses, strict=True):
            for topic in odom_topics:  # odometry that says the robot never moves
                w.write(topic, Odometry(stamp=float(t) - 0.01, twist=np.zeros(3), pose=np.zeros(3)))
            w.write("/scan", synth.scan_at(world, p, float(t), rng=rng))


def _cli(args, capsys):
    capsys.readouterr()
    rc = main([str(a) for a in args])
    o, e = capsys.readouterr()
    assert "Traceback" not in o + e
    return rc, o, e


def _errors(est: Trajectory, truth: Trajectory) -> tuple[float, float]:
    """Largest position (m) and heading (deg) error of ``est`` (the map frame: the first scan at the
    origin) against ``truth`` seen from its first pose, scan by scan."""
    rel = np.array([between(truth.poses[0], p) for p in truth.poses])
    assert len(est) == len(rel)
    d = np.hypot(est.poses[:, 0] - rel[:, 0], est.poses[:, 1] - rel[:, 1])
    dyaw = np.abs(wrap_angle(est.poses[:, 2] - rel[:, 2]))
    return float(d.max()), float(np.degrees(dyaw.max()))


def test_a_log_of_scans_alone_is_mapped_from_the_scans(tmp_path, capsys):
    full = synth.ring_drive(laps=1, dt=0.1)
    truth = Trajectory(full.stamps[:600], full.poses[:600])  # 36 m along two corridors and a corner turn
    log = tmp_path / "lidar.mcap"
    _write(log, truth)
    rc, out, err = _cli(["map", log, "-o", tmp_path / "map", "-q", "--no-check"], capsys)
    assert rc == 0, err                    # was: rc 2, "no odometry on /odom: fgloc map pairs every scan with ..."
    assert f"warning: {SCANS_ALONE}" in err
    pos, yaw = _errors(read_tum(tmp_path / "map" / "trajectory.tum"), truth)
    assert pos < 0.15 and yaw < 2.0        # measured 0.078 m, 1.05 deg
    doc = yaml.safe_load((tmp_path / "map" / "mapping.yaml").read_text())
    assert doc["stats"]["scans_only"] == 1 and doc["stats"]["tracked"] >= 595
    # localizing the scans alone on it, each back-end carrying the robot's velocity from scan to scan (the
    # smoother once had none: each guess stood where the last fix was, the fixes slid along the corridor,
    # 16.5 m median error with every pose "ok"; then it was refused)
    m = tmp_path / "map" / "map.yaml"
    rel = np.array([between(truth.poses[0], p) for p in truth.poses])
    for backend in ("smoother", "ekf"):
        rc, _, err = _cli(["run", log, "--map", m, "--initial-pose", "0", "0", "0", "--backend", backend,
                           "-o", tmp_path / backend, "-q"], capsys)
        assert rc == 0, err
        est = read_tum(tmp_path / backend / "trajectory.tum")
        k = np.clip(np.searchsorted(truth.stamps, est.stamps - 1e-6), 0, len(rel) - 1)
        err_m = np.hypot(est.poses[:, 0] - rel[k, 0], est.poses[:, 1] - rel[k, 1])
        assert float(np.median(err_m)) < 0.1, backend   # measured: smoother 0.034 m, EKF 0.037 m


def test_a_robot_standing_still_stays_put(tmp_path, capsys):
    """No odometry to say the robot stands still: every scan is matched (none skipped as stationary)."""
    stamps = 1000.0 + 0.1 * np.arange(80)
    truth = Trajectory(stamps, np.tile([[3.0, 1.5, 0.3]], (80, 1)))
    log = tmp_path / "still.mcap"
    _write(log, truth)
    rc, out, err = _cli(["map", log, "-o", tmp_path / "map", "-q", "--no-check"], capsys)
    assert rc == 0, err
    est = read_tum(tmp_path / "map" / "trajectory.tum")
    assert len(est) == 80
    assert float(np.abs(est.poses).max()) < 0.01
    doc = yaml.safe_load((tmp_path / "map" / "mapping.yaml").read_text())
    assert doc["stats"]["keyframes"] == 1 and doc["stats"]["tracked"] == 79


def test_odom_topic_empty_maps_the_scans_alone_beside_odometry(tmp_path, capsys):
    """``--odom-topic ''`` (as ``fgloc run``'s): odometry that cannot be trusted is left out."""
    full = synth.ring_drive(laps=1, dt=0.1)
    truth = Trajectory(full.stamps[:150], full.poses[:150])
    log = tmp_path / "frozen_wheels.mcap"
    _write(log, truth, odom_topics=("/odom",))
    rc, out, err = _cli(["map", log, "-o", tmp_path / "map", "-q", "--no-check", "--odom-topic", ""], capsys)
    assert rc == 0, err
    assert f"warning: {SCANS_ALONE}" in err
    pos, _ = _errors(read_tum(tmp_path / "map" / "trajectory.tum"), truth)
    assert pos < 0.1


def test_several_odometry_topics_and_none_named_is_an_error(tmp_path, capsys):
    full = synth.ring_drive(laps=1, dt=0.1)
    log = tmp_path / "two_odoms.mcap"
    _write(log, Trajectory(full.stamps[:20], full.poses[:20]), odom_topics=("/wheel/odom", "/visual/odom"))
    rc, _, err = _cli(["map", log, "-o", tmp_path / "map", "-q"], capsys)
    assert rc == 2
    line = err.strip()
    assert line.startswith(f"fgloc: error: {log}: no odometry on /odom: name the wheel odometry's topic with "
                           "--odom-topic (or map the scans alone with --odom-topic ''); its topics: ")
    assert "/visual/odom (nav_msgs/msg/Odometry, 20)" in line and "/wheel/odom" in line
    assert not (tmp_path / "map").exists()


def test_the_wheels_beside_a_filters_output_are_mapped_on(tmp_path, capsys, caplog):
    """robot_localization's output recorded with its inputs: the wheels' topic is the odometry."""
    full = synth.ring_drive(laps=1, dt=0.1)
    log = tmp_path / "wheels_and_filter.mcap"
    _write(log, Trajectory(full.stamps[:20], full.poses[:20]), odom_topics=("/wheel/odom", "/odometry/filtered"))
    with caplog.at_level("WARNING"):
        rc, _, err = _cli(["map", log, "-o", tmp_path / "map", "-q", "--no-check"], capsys)
    assert rc == 0, err
    assert "using /wheel/odom" in caplog.text and "named as filters' outputs (/odometry/filtered)" in caplog.text


def test_several_lasers_and_no_scan_topic_name_the_choice(tmp_path, capsys):
    """A leg tracker's bag: /left_scan, /right_scan, /rear_scan and nothing else (was: "topic '/scan' not
    in log")."""
    world = synth.world_grid()
    log = tmp_path / "three_lasers.mcap"
    with LogWriter(log) as w:
        for k in range(10):
            for topic in ("/left_scan", "/right_scan", "/rear_scan"):
                w.write(topic, synth.scan_at(world, [3.0, 1.5, 0.0], 1000.0 + 0.1 * k))
    rc, _, err = _cli(["map", log, "-o", tmp_path / "map", "-q"], capsys)
    assert rc == 2
    assert err.strip() == (f"fgloc: error: {log}: no /scan; the log has 3 laser scan topics: name the one to map "
                           "with --scan-topic /left_scan | /rear_scan | /right_scan")
    rc, _, err = _cli(["map", log, "-o", tmp_path / "map", "-q", "--no-check", "--scan-topic", "/rear_scan"], capsys)
    assert rc == 0, err
    assert len(read_tum(tmp_path / "map" / "trajectory.tum")) == 10
