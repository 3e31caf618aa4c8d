"""Robots beyond the paper's: skid steer with scrub, a rotated IMU, late and bursty sensors, strafing."""

from importlib import resources
from pathlib import Path

import numpy as np
import pytest

from fgloc.frames.imu import imu_in_base, mount_rotation
from fgloc.geometry import wrap_angle
from fgloc.sim import load_scenario, run_scenario
from fgloc.sim.simulate import scrub_factor
from fgloc.types import Imu, Transform3D

SCEN = Path(str(resources.files("fgloc.config") / "scenarios"))  # shipped in the package
SHORT = [[17.5, 3.0], [27.5, 3.0], [27.5, 9.0]]


def _skid(mount_rpy=(0.0, 0.0, 90.0), **kw):
    sc = {"drive": "skid", "route": SHORT, "speed_mps": 0.7, "yaw_rate_radps": 0.7,
          "robot": {"wheel_radius_m": 0.165, "half_wheelbase_m": 0.26, "half_track_m": 0.28},
          "odom": {"rate_hz": 20.0, "twist_sigma": [0.02, 0.01, 0.02], "scrub_factor": [1.4, 2.5],
                   "scrub_ref_radps": 0.7},
          "imu": {"mount_rpy_deg": list(mount_rpy), "offset_deg": 12.0}, "laser": {"enabled": False}}
    sc.update(kw)
    return run_scenario(sc, seed=1)


def _true_rate(gt, t):
    yaw = np.unwrap(gt.poses[:, 2])
    return np.interp(t, 0.5 * (gt.stamps[1:] + gt.stamps[:-1]), np.diff(yaw) / np.diff(gt.stamps))


def test_skid_steer_odometry_over_reports_turning_and_claims_0_02():
    sim = _skid()
    odom = sim.topic("/odom")
    assert len(odom) == pytest.approx(20.0 * sim.ground_truth.duration, rel=0.01)  # 20 Hz
    t = np.array([o.stamp for o in odom])
    w = np.array([o.twist[2] for o in odom])
    assert all(o.twist[1] == 0.0 for o in odom)
    assert all(np.sqrt(o.twist_cov[2, 2]) == pytest.approx(0.02) for o in odom)
    wt = _true_rate(sim.ground_truth, t - 0.025)  # the twist is the mean over the last 50 ms
    turning = np.abs(wt) > 0.3
    ratio = w[turning] / wt[turning]
    assert 1.35 < np.median(ratio) < 2.6
    assert ratio.max() > 2.2 and np.percentile(ratio, 5) < 2.2  # varies with the turning speed
    # integrated: the wheels claim about twice the 90 deg turn
    assert np.sum(w) * 0.05 == pytest.approx(np.pi / 2 * np.median(ratio), rel=0.15)
    assert scrub_factor(sim.scenario, [0.0, 0.35, 0.7, 2.0]) == pytest.approx([1.4, 1.95, 2.5, 2.5])


@pytest.mark.parametrize("rpy,axis", [((0.0, 0.0, 90.0), 2), ((90.0, 0.0, 0.0), 1)])
def test_rotated_imu_reads_in_its_own_frame_and_rotates_back(rpy, axis):
    sim = _skid(mount_rpy=rpy)
    mount = sim.imu_mount
    assert isinstance(mount, Transform3D) and mount.child == "imu_link"
    imu = [m for m in sim.topic("/imu")]
    assert all(isinstance(m, Imu) for m in imu)
    t = np.array([m.stamp for m in imu])
    w_imu = np.array([m.angular_velocity_radps for m in imu])
    wt = _true_rate(sim.ground_truth, t)
    # hand computed: a yawed mount keeps z; turned +90 deg about x, the IMU's y axis is base z
    # (R_bi = Rx(90): R_bi^T [0, 0, 1] = [0, 1, 0])
    others = [i for i in range(3) if i != axis]
    assert np.mean(w_imu[:, axis] - wt) == pytest.approx(0.002, abs=0.0006)  # gyro bias
    assert np.std(w_imu[:, axis] - wt) < 0.012
    assert np.abs(np.mean(w_imu[:, others], axis=0)).max() < 0.001
    # the orientation is the sensor frame's: with the yawed mount its yaw is 90 deg more
    R_bi = mount_rotation(mount)
    base = [imu_in_base(m, R_bi)[0] for m in imu]
    yaw = np.array([b.yaw_rad for b in base])
    e = wrap_angle(yaw - sim.ground_truth.interpolate(t)[:, 2] - np.deg2rad(12.0))
    assert abs(np.rad2deg(np.mean(e))) < 0.3 and np.rad2deg(np.std(e)) < 1.5
    rate = np.array([b.yaw_rate_radps for b in base])
    assert np.mean(rate - wt) == pytest.approx(0.002, abs=0.0006)
    # the claimed covariances rotate back to the base frame's (yaw variance on base z)
    assert base[0].yaw_rate_var == pytest.approx(0.005**2)
    assert base[0].yaw_var == pytest.approx(np.deg2rad(0.5) ** 2 + 0.5 * np.deg2rad(1.0) ** 2)


def test_late_scans_bursty_imu_and_20hz_odometry():
    sc = load_scenario(SCEN / "latency.yaml")
    sc["route"] = SHORT
    late = run_scenario(sc, seed=2)
    sc["laser"]["stamp_delay_s"] = 0.0
    sc["imu"]["burst_period_s"] = 0.0
    on_time = run_scenario(sc, seed=2)
    d = np.array([a.stamp - b.stamp for a, b in zip(late.topic("/scan"), on_time.topic("/scan"), strict=True)])
    assert np.allclose(d, 0.035)
    # bursts: the IMU's messages arrive 10 at a time, after odometry stamped later than them
    order = [(topic, m.stamp) for topic, m in late.messages[1:] if topic in ("/imu", "/odom")]
    inversions = sum(1 for (ta, sa), (tb, sb) in zip(order[:-1], order[1:], strict=True) if sb < sa - 1e-9)
    assert inversions > 0.5 * len(late.topic("/odom"))
    imu_t = np.array([m.stamp for m in late.topic("/imu")])
    assert np.all(np.diff(imu_t) > 0)  # each stream is still in its own order
    assert len(late.topic("/odom")) == pytest.approx(20.0 * late.ground_truth.duration, rel=0.01)


def test_mecanum_strafing_keeps_heading_and_reports_lateral_velocity():
    sim = run_scenario({"route": SHORT, "strafe_legs": [1], "laser": {"enabled": False}}, seed=0)
    gt = sim.ground_truth
    assert np.ptp(gt.poses[:, 2]) < 1e-9  # never turns: faces +x all along
    assert gt.poses[-1, :2] == pytest.approx([27.5, 9.0], abs=1e-6)
    vy = np.array([o.twist[1] for o in sim.topic("/odom")])
    assert vy.max() == pytest.approx(0.8, abs=0.03)


def test_arcs_drive_corners_without_stopping():
    sim = run_scenario({"route": SHORT, "turn_radii_m": 1.0, "laser": {"enabled": False}}, seed=0)
    gt = sim.ground_truth
    speed = np.hypot(*np.diff(gt.poses[:, :2], axis=0).T) / np.diff(gt.stamps)
    mid = (gt.stamps[1:] > 5.0) & (gt.stamps[1:] < gt.stamps[-1] - 5.0)
    assert speed[mid].min() > 0.75  # no stop at the corner
    assert gt.poses[-1, :2] == pytest.approx([27.5, 9.0], abs=1e-6)
    assert np.rad2deg(gt.poses[-1, 2]) == pytest.approx(90.0, abs=1e-6)


def test_shipped_robot_scenarios_load():
    for name in ("skid_steer", "skid_steer_imu_x90", "latency", "mecanum_strafe"):
        sc = load_scenario(SCEN / f"{name}.yaml")
        assert sc["laser"]["rate_hz"] == 25.0
    assert load_scenario(SCEN / "skid_steer.yaml")["imu"]["mount_rpy_deg"] == [0.0, 0.0, 90.0]
    assert load_scenario(SCEN / "skid_steer_imu_x90.yaml")["imu"]["mount_rpy_deg"] == [90.0, 0.0, 0.0]


def test_wheel_noise_makes_a_noisier_odometry_that_claims_the_same():
    """``odom.wheel_noise``: each wheel's turn between two readings off by a random share of it; 0 (the
    default) draws nothing, so every other message is as before."""
    base = {"route": SHORT, "laser": {"enabled": False}}
    quiet, same = run_scenario(base, seed=3), run_scenario({**base, "odom": {"wheel_noise": 0.0}}, seed=3)
    noisy = run_scenario({**base, "odom": {"wheel_noise": 0.1}}, seed=3)
    q, s, n = (np.array([o.twist for o in r.topic("/odom")]) for r in (quiet, same, noisy))
    assert np.array_equal(q, s) and len(q) == len(n)
    assert np.array_equal([m.yaw_rad for m in quiet.topic("/imu")], [m.yaw_rad for m in noisy.topic("/imu")])
    moving = np.abs(q[:, 0]) > 0.5
    rel = (n[moving, 0] - q[moving, 0]) / q[moving, 0]
    assert 0.04 < float(np.std(rel)) < 0.1  # four wheels' shares averaged: about 0.1 / 2
    pairs = zip(quiet.topic("/odom"), noisy.topic("/odom"), strict=True)
    assert all(np.array_equal(a.twist_cov, b.twist_cov) for a, b in pairs)


def _mounted(**kw):
    sc = {"route": SHORT, "laser": {"jitter": 0.0, "angle_sigma_deg": 0.0}}
    for section, over in kw.items():
        sc[section] = {**sc.get(section, {}), **over}
    return run_scenario(sc, seed=2)


def test_sensors_mounted_otherwise_than_the_tf_says():
    """The tf keeps the declared mount; the sensor measures from where it really is."""
    from fgloc.geometry import compose

    right = _mounted()
    yawed = _mounted(laser={"mount_error": [0.0, 0.0, 5.0]})
    moved = _mounted(laser={"mount": compose(np.array([0.25, 0.03, 0.0]), np.array([0.0, 0.0, np.deg2rad(5.0)])
                                             ).tolist()})
    assert yawed.laser_mount.pose == pytest.approx(right.laser_mount.pose)  # the tf: as declared
    for a, b in zip(yawed.topic("/scan")[::50], moved.topic("/scan")[::50], strict=True):
        np.testing.assert_array_equal(a.ranges, b.ranges)  # measured from the mount turned 5 deg
    flipped = _mounted(laser={"upside_down": True})
    r, f = right.topic("/scan")[30].ranges, flipped.topic("/scan")[30].ranges
    both = np.isfinite(r) & np.isfinite(f[::-1])
    # upside down: the same beams, swept the other way (range noise 4 mm)
    assert np.median(np.abs(r - f[::-1])[both]) < 0.01 and both.mean() > 0.9
    assert np.mean(np.abs(r - f)[np.isfinite(r) & np.isfinite(f)] > 0.2) > 0.3
    w = np.array([o.twist for o in right.topic("/odom")])
    wf = np.array([o.twist for o in _mounted(odom={"yaw_rate_sign": -1}).topic("/odom")])
    np.testing.assert_array_equal(wf[:, :2], w[:, :2])
    np.testing.assert_array_equal(wf[:, 2], -w[:, 2])
    up = _mounted(imu={"offset_deg": 12.0}, laser={"enabled": False})
    down = _mounted(imu={"offset_deg": 12.0, "mount_error_rpy_deg": [180.0, 0.0, 0.0]}, laser={"enabled": False})
    assert down.imu_mount.rotation_xyzw == pytest.approx(up.imu_mount.rotation_xyzw)  # the tf: upright
    gz_up = np.array([m.angular_velocity_radps[2] for m in up.topic("/imu")])
    gz_down = np.array([m.angular_velocity_radps[2] for m in down.topic("/imu")])
    assert np.abs(gz_up).max() > 0.5
    assert np.abs(gz_up + gz_down).max() < 0.05  # the unit upside down: its z rate negated (noise 0.005 each)
