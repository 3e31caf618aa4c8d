"""Issue 17's simulator acceptance runs (mostly the EKF, the quicker back-end; both with a map)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from fgloc.config import scenario_path
from fgloc.eval.metrics import evaluate
from fgloc.geometry import compose, inverse
from fgloc.localization import Localizer, Session
from fgloc.sim import run_scenario

SCEN = Path(__file__).resolve().parents[2] / "fgloc" / "config" / "scenarios"


def test_skid_steer_imu_turned_about_x_no_map_within_1_percent():
    sim = run_scenario(SCEN / "skid_steer_imu_x90.yaml", seed=0)
    msgs = [(t, m) for t, m in sim.messages if t != "/scan"]  # raw sensor_msgs/Imu through the mount
    loc = Localizer(None, sim.laser_mount, backend="ekf")
    tr = Session(loc).run(msgs)
    gt = sim.ground_truth
    end = compose(compose(gt.interpolate(tr.stamps[0])[0], inverse(tr.poses[0])), tr.poses[-1])
    err = float(np.hypot(*(end[:2] - gt.interpolate(tr.stamps[-1])[0][:2])))
    assert err < 0.01 * gt.path_length()  # measured 0.08 m of 154 m (25 m before issue 17)
    h = loc.stats["sources"]
    assert h["odom"].yaw_rate_scale == pytest.approx(2.3, abs=0.3)  # the scrub, 1.4-2.5
    assert h["imu"].gyro_bias_radps == pytest.approx(0.002, abs=0.001)


def test_late_scans_latency_estimated_within_5_ms():
    sim = run_scenario(SCEN / "latency.yaml", seed=0)
    loc = Localizer(sim.map, sim.laser_mount, backend="ekf", initial_pose=sim.ground_truth.poses[0])
    tr = Session(loc).run(sim.messages)
    assert loc.backend.latency_estimate() == pytest.approx(0.035, abs=0.005)
    assert evaluate(tr, sim.ground_truth).position_rmse_m <= 0.01  # 0.0054 (0.024 uncorrected)
    assert loc.stats["sources"]["scan"].latency_s == pytest.approx(0.035, abs=0.005)


def test_mecanum_strafing_ekf_within_1_2x_of_its_fixes():
    sim = run_scenario(SCEN / "mecanum_strafe.yaml", seed=0)
    loc = Localizer(sim.map, sim.laser_mount, backend="ekf", initial_pose=sim.ground_truth.poses[0])
    tr = Session(loc).run(sim.messages)
    e_ekf = evaluate(tr, sim.ground_truth).position_rmse_m
    e_fix = evaluate(loc.fixes_trajectory(), sim.ground_truth).position_rmse_m
    assert loc.backend.stats["omni"]
    assert e_ekf <= 1.2 * e_fix  # 1.04x (89x with the diff-drive state)


@pytest.mark.parametrize("backend", ["ekf", "smoother"])
def test_skid_steer_with_map_within_3_cm_and_half_a_degree_no_false_latency(backend):
    sc = yaml.safe_load(scenario_path("skid_steer_imu_x90").read_text())
    sc["route"], sc["turn_radii_m"] = sc["route"][:4], [1.5, 0.0]  # 63 m: an arc and a stop-turn-go corner
    sim = run_scenario(sc, seed=1)
    loc = Localizer(sim.map, sim.laser_mount, backend=backend, initial_pose=sim.ground_truth.poses[0])
    ev = evaluate(Session(loc).run(sim.messages), sim.ground_truth)
    assert ev.position_rmse_m <= 0.03 and ev.heading_rmse_deg <= 0.5  # 0.0033 m, 0.11 / 0.03 deg
    # the scans are stamped on time: de-skewed with the wheels' scrubbed yaw they read as ~25 ms late
    assert abs(loc.backend.latency_estimate()) < 0.005
    assert loc.stats["sources"]["imu"].gyro_bias_radps == pytest.approx(0.002, rel=0.1)  # 0.00205
