"""The simulator's Must-show properties, measured on the paper run (seed 0)."""

from importlib import resources
from pathlib import Path

import numpy as np
import pytest

from fgloc.geometry import compose, wrap_angle
from fgloc.sim import load_scenario, run_scenario, simulate_paper

SCEN = Path(str(resources.files("fgloc.config") / "scenarios"))  # shipped in the package


def dead_reckon(odom, start_pose, t_end):
    p = np.array(start_pose, dtype=float)
    out = []
    for a, b in zip(odom[:-1], odom[1:], strict=True):
        if b.stamp > t_end:
            break
        dt = b.stamp - a.stamp
        vx, vy, wz = b.twist
        th = p[2] + 0.5 * wz * dt
        p = p + [(vx * np.cos(th) - vy * np.sin(th)) * dt, (vx * np.sin(th) + vy * np.cos(th)) * dt, wz * dt]
        out.append((b.stamp, p.copy()))
    return out


def test_paper_run_shape(paper_sim):
    gt = paper_sim.ground_truth
    assert gt.path_length() == pytest.approx(78.0, abs=0.05)
    assert 100 < gt.duration < 125
    speed = np.hypot(*np.diff(gt.poses[:, :2], axis=0).T) / np.diff(gt.stamps)
    assert speed.max() == pytest.approx(0.8, abs=0.01)
    scans = paper_sim.topic("/scan")
    assert len(scans[0].ranges) == 541
    assert np.rad2deg(scans[0].angle_max if hasattr(scans[0], "angle_max") else
                      scans[0].angle_min + 540 * scans[0].angle_increment) == pytest.approx(135.0)
    periods = np.diff([s.stamp for s in scans])
    assert 0.0375 < periods.min() and periods.max() < 0.0425  # 25 Hz +- 5 %
    assert periods.std() > 0.0005  # jitter present
    stamps = [m.stamp for _, m in paper_sim.messages[1:]]
    assert np.all(np.diff(stamps) >= 0)


def test_dead_reckoning_first_10s_within_5cm(paper_sim):
    odom = paper_sim.topic("/odom")
    gt = paper_sim.ground_truth
    start = gt.interpolate(odom[0].stamp)[0]
    track = dead_reckon(odom, start, odom[0].stamp + 10.0)
    err = max(np.hypot(*(p[:2] - gt.interpolate(t)[0, :2])) for t, p in track)
    assert err < 0.05
    # and the robot really moved: 10 s includes acceleration to 0.8 m/s
    assert np.hypot(*(track[-1][1][:2] - start[:2])) > 5.0


def test_scans_land_on_occupied_cells(paper_sim):
    m, gt, mount = paper_sim.map, paper_sim.ground_truth, paper_sim.laser_mount.pose
    dists = []
    for s in paper_sim.topic("/scan")[::25]:
        n = len(s.ranges)
        lp = compose(gt.interpolate(s.stamp + s.time_increment * np.arange(n)), mount)  # per-beam motion
        ok = np.isfinite(s.ranges)
        a = lp[:, 2] + s.angles
        pts = (lp[:, :2] + s.ranges[:, None] * np.column_stack([np.cos(a), np.sin(a)]))[ok]
        rc = m.world_to_grid(pts)
        inside = m.occupied[rc[:, 0], rc[:, 1]]
        d = np.maximum(m.distance_at(pts) - m.resolution / 2, 0.0)  # to the cell's edge, 0 inside
        d[inside] = 0.0
        dists.append(d)
    d = np.concatenate(dists)
    assert np.median(d) < 0.02
    assert np.percentile(d, 95) < 0.05


def test_compass_is_map_yaw_plus_offset(paper_sim):
    gt = paper_sim.ground_truth
    imu = paper_sim.topic("/imu")
    t = np.array([m.stamp for m in imu])
    yaw = np.array([m.yaw_rad for m in imu])
    err = wrap_angle(yaw - gt.interpolate(t)[:, 2] - paper_sim.compass_offset_rad)
    # noise 0.3 deg plus the position-dependent magnetic distortion (amplitude 1 deg)
    assert 0.3 < np.rad2deg(np.sqrt(np.mean(err**2))) < 1.2
    assert abs(np.rad2deg(np.median(err))) < 0.5
    assert 5.0 <= abs(np.rad2deg(paper_sim.compass_offset_rad)) <= 25.0
    # 0.1 deg integer steps on the wire
    deci = np.rad2deg(np.mod(yaw, 2 * np.pi)) * 10
    assert np.allclose(deci, np.round(deci), atol=1e-6)


def test_rep117_infinities(paper_sim):
    r = np.concatenate([s.ranges for s in paper_sim.topic("/scan")[::50]])
    finite = r[np.isfinite(r)]
    assert finite.min() >= 0.5 and finite.max() <= 50.0
    # the hall is closed: all beams return, no +inf on the paper run; a too-close obstacle gives -inf
    res = simulate_paper(seed=0, route=[[1.0, 10.0], [1.0, 12.0]], loops=1)
    rr = np.concatenate([s.ranges for s in res.topic("/scan")])
    assert np.isneginf(rr).any()


def test_deterministic_per_seed():
    a = simulate_paper(seed=3, route=[[3.0, 3.0], [6.0, 3.0]])
    b = simulate_paper(seed=3, route=[[3.0, 3.0], [6.0, 3.0]])
    c = simulate_paper(seed=4, route=[[3.0, 3.0], [6.0, 3.0]])
    sa, sb, sc = (x.topic("/scan")[5].ranges for x in (a, b, c))
    assert np.array_equal(sa, sb)
    assert not np.array_equal(sa, sc)
    assert a.compass_offset_rad == b.compass_offset_rad != c.compass_offset_rad
    for topic in ("/odom", "/imu", "/scan"):
        ta, tb = a.topic(topic), b.topic(topic)
        assert [m.stamp for m in ta] == [m.stamp for m in tb]
    assert all(np.array_equal(x.twist, y.twist) for x, y in zip(a.topic("/odom"), b.topic("/odom"), strict=True))
    assert [m.yaw_rad for m in a.topic("/imu")] == [m.yaw_rad for m in b.topic("/imu")]
    assert [m.yaw_rad for m in a.topic("/imu")] != [m.yaw_rad for m in c.topic("/imu")]


LEG = [[2.5, 3.0], [27.5, 3.0]]  # one 25 m leg (~34 s) keeps the fault tests quick


def test_shipped_scenarios_load():
    from fgloc.sim import load_scenario

    names = {p.stem for p in SCEN.glob("*.yaml")}
    assert {"paper", "compass_disturbance", "wheel_slip", "kidnap", "willow", "obstacles", "blackout"} <= names
    for p in SCEN.glob("*.yaml"):
        sc = load_scenario(p)
        assert sc["route"] and sc["laser"]["rate_hz"] == 25.0
    assert load_scenario(SCEN / "wheel_slip.yaml")["faults"]["wheel_slip"]["fraction"] == 0.3
    assert load_scenario(SCEN / "compass_disturbance.yaml")["faults"]["compass_disturbance"]["offset_deg"] == 25.0


def test_willow_scenario_runs_in_the_real_map(shared_data):
    r = run_scenario(SCEN / "willow.yaml", seed=0)
    assert r.map.resolution == pytest.approx(0.1)
    assert r.ground_truth.path_length() > 40
    s = r.topic("/scan")[100]
    assert np.isfinite(s.ranges).mean() > 0.5
    # the world is the map's non-free cells: endpoints land on the robot map's occupied border
    m, gt = r.map, r.ground_truth
    d = []
    for s in r.topic("/scan")[::50]:
        n = len(s.ranges)
        lp = compose(gt.interpolate(s.stamp + s.time_increment * np.arange(n)), r.laser_mount.pose)
        ok = np.isfinite(s.ranges)
        a = lp[:, 2] + s.angles
        pts = (lp[:, :2] + s.ranges[:, None] * np.column_stack([np.cos(a), np.sin(a)]))[ok]
        dd = np.maximum(m.distance_at(pts) - m.resolution / 2, 0.0)
        rc = m.world_to_grid(pts)
        dd[m.occupied[rc[:, 0], rc[:, 1]]] = 0.0
        d.append(dd)
    assert np.median(np.concatenate(d)) < 0.02


def test_fault_wheel_slip_only_inside_window():
    r = run_scenario({"route": LEG, "laser": {"enabled": False},
                      "faults": {"wheel_slip": {"start": 12.0, "duration": 3.0, "fraction": 0.3}}})
    gt = r.ground_truth
    odom = r.topic("/odom")
    t = np.array([o.stamp for o in odom])
    v_odom = np.array([o.twist[0] for o in odom])
    v_true = np.interp(t, gt.stamps, np.r_[0, np.hypot(*np.diff(gt.poses[:, :2], axis=0).T) / np.diff(gt.stamps)])
    inside = (t > 12.2) & (t < 14.8) & (v_true > 0.5)
    outside = (t > 16) & (t < 30) & (v_true > 0.5)
    assert np.median(v_odom[inside] / v_true[inside]) == pytest.approx(1.3, abs=0.02)
    assert np.median(v_odom[outside] / v_true[outside]) == pytest.approx(1.0, abs=0.01)


def test_fault_compass_blackout_kidnap():
    r = run_scenario({"route": LEG, "laser": {"enabled": False}, "faults": {"compass_disturbance": {
        "start": 10.0, "duration": 5.0, "offset_deg": 25.0}}})
    imu = r.topic("/imu")
    t = np.array([m.stamp for m in imu])
    err = np.rad2deg(wrap_angle(np.array([m.yaw_rad for m in imu]) - r.ground_truth.interpolate(t)[:, 2]
                                - r.compass_offset_rad))
    assert np.median(err[(t > 10.2) & (t < 14.8)]) == pytest.approx(25.0, abs=0.5)
    assert abs(np.median(err[(t > 16) & (t < 30)])) < 0.2

    r = run_scenario({"route": LEG, "faults": {"laser_blackout": {"start": 15.0, "duration": 4.0}}})
    ts = np.array([s.stamp for s in r.topic("/scan")])
    assert not np.any((ts >= 15.0) & (ts < 19.0))
    assert np.any((ts > 10) & (ts < 15)) and np.any((ts > 19) & (ts < 24))

    r = run_scenario({"route": LEG + [[27.5, 17.0]], "faults": {"kidnap": {"time": 20.0, "skip_s": 8.0}}})
    gt = r.ground_truth
    jumps = np.hypot(*np.diff(gt.poses[:, :2], axis=0).T)
    k = int(np.argmax(jumps))
    assert jumps[k] > 5.0 and gt.stamps[k] == pytest.approx(20.0, abs=0.02)
    odom = r.topic("/odom")
    op = np.array([o.pose[:2] for o in odom])
    assert np.hypot(*np.diff(op, axis=0).T).max() < 0.05  # odometry never jumps


def test_moving_obstacles_seen_by_laser_not_in_map():
    base = simulate_paper(seed=0, route=LEG)
    obs = run_scenario({"route": LEG, "faults": {"moving_obstacles": [
        {"path": [[14.0, 1.5], [14.0, 18.5]], "speed_mps": 0.9, "radius_m": 0.3}]}}, seed=0)
    assert np.array_equal(base.map.data, obs.map.data)
    short = 0
    for a, b in zip(base.topic("/scan")[::10], obs.topic("/scan")[::10], strict=True):
        ok = np.isfinite(a.ranges) & np.isfinite(b.ranges)
        short += int(np.sum(b.ranges[ok] < a.ranges[ok] - 0.3))
    assert short > 50


def test_simulate_cli_writes_files(tmp_path, capsys):
    from fgloc.cli import main
    from fgloc.io import open_log
    from fgloc.io.tum import read_tum
    from fgloc.maps import load_map

    scen = tmp_path / "short.yaml"
    scen.write_text("route: [[3.0, 3.0], [8.0, 3.0]]\n")
    assert main(["simulate", "scenario", str(scen), "-o", str(tmp_path / "out"), "--seed", "2"]) == 0
    out = tmp_path / "out"
    assert load_map(out / "map.yaml").occupied.sum() > 1000
    gt = read_tum(out / "ground_truth.tum")
    assert gt.path_length() == pytest.approx(5.0, abs=0.01)
    counts = open_log(out / "log.mcap").summary()
    assert "/scan" in str(counts) and "/ground_truth" in str(counts)
    assert "compass offset" in capsys.readouterr().out


def test_robot_paper_yaml_matches_defaults():
    import yaml

    from fgloc.sim import DEFAULT_SCENARIO

    cfg = yaml.safe_load((SCEN.parent / "robot_paper.yaml").read_text())
    for section in ("odom", "compass", "laser"):
        for k, v in cfg[section].items():
            assert DEFAULT_SCENARIO[section][k] == v, (section, k)
    for k, v in cfg["robot"].items():
        assert (DEFAULT_SCENARIO["drive"] if k == "drive" else DEFAULT_SCENARIO["robot"][k]) == v
    for k, v in cfg["motion"].items():
        assert DEFAULT_SCENARIO[k] == v


def test_rep117_plus_inf_beyond_range_max():
    # a 10 m scanner in the 30 m hall: long beams have no return -> +inf, never a finite value > 10 m
    r = simulate_paper(seed=0, route=[[3.0, 3.0], [5.0, 3.0]], laser={"range_max_m": 10.0})
    rr = np.concatenate([s.ranges for s in r.topic("/scan")])
    assert np.isposinf(rr).mean() > 0.2
    assert rr[np.isfinite(rr)].max() <= 10.0
    assert r.topic("/scan")[0].range_max == 10.0


def test_kidnap_to_pose_and_diff_drive_odometry():
    to = [15.0, 10.5, np.pi / 2]  # carried onto the middle of the hall, facing north
    r = run_scenario({"route": [[3.0, 3.0], [9.0, 3.0]], "drive": "diff", "laser": {"enabled": False},
                      "faults": {"kidnap": {"time": 5.0, "to": to}}})
    gt = r.ground_truth
    k = int(np.searchsorted(gt.stamps, 5.0))
    assert np.allclose(gt.poses[k], to, atol=1e-9)
    assert np.hypot(*(gt.poses[k - 1][:2] - to[:2])) > 5.0  # a real jump
    odom = r.topic("/odom")
    assert all(o.twist[1] == 0.0 for o in odom)  # a differential drive never slides sideways
    op = np.array([o.pose[:2] for o in odom])
    assert np.hypot(*np.diff(op, axis=0).T).max() < 0.05
    assert r.topic("/scan") == []


def test_paper_yaml_is_simulate_paper():
    from fgloc.sim import DEFAULT_SCENARIO, load_scenario

    sc = load_scenario(SCEN / "paper.yaml")
    assert sc == DEFAULT_SCENARIO


def test_odometry_dropout_and_late_delivery():
    short = [[2.5, 3.0], [8.5, 3.0]]
    quiet = {"enabled": False}  # no laser: the odometry alone
    r = run_scenario({"route": short, "laser": quiet, "faults": {"odometry_dropout": {"start": 3.0, "duration": 2.0}}})
    t = np.array([m.stamp for m in r.topic("/odom")])
    assert not np.any((t >= 3.0) & (t < 5.0)) and np.any(t > 5.0) and np.any(t < 3.0)
    r = run_scenario({"route": short, "laser": quiet, "faults": {"odometry_dropout": {"start": 3.0, "duration": None}}})
    assert max(m.stamp for m in r.topic("/odom")) < 3.0  # stopped for good
    r = run_scenario({"route": short, "faults": {"odometry_late": {"delay_s": 0.3}}})
    newest = -np.inf
    behind = []
    for topic, m in r.messages:  # arrival order: at each scan the newest odometry stamp is 0.3 s behind it
        if topic == "/odom":
            newest = max(newest, m.stamp)
        elif topic == "/scan" and m.stamp > 1.0:
            behind.append(m.stamp - newest)
    assert 0.28 < float(np.median(behind)) < 0.32


def test_a_robot_without_compass_or_imu():
    """``compass: null`` (and no ``imu``): a robot with neither (a Stage Pioneer): no /imu at all, the rest as
    with one."""
    base = {"route": LEG, "laser": {"enabled": False}}
    bare, full = run_scenario({**base, "compass": None}, seed=2), run_scenario(base, seed=2)
    assert not bare.topic("/imu") and full.topic("/imu")
    assert [m.stamp for m in bare.topic("/odom")] == [m.stamp for m in full.topic("/odom")]
    assert load_scenario({"compass": None})["compass"] is None
