"""Scans on a map and nothing else (no odometry; an IMU at most): the smoother carries the graph's own
velocity from keyframe to keyframe, so its guesses move with the robot and its fixes do not slide.
Runs here: the paper hall's simulator with its odometry (and compass) taken out, driven straight,
stop-turn-go and on arcs; the ring world's corridors, turning in place at the corners."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from fgloc.bench.common import localize_sim
from fgloc.geometry import between, interpolate_poses, wrap_angle
from fgloc.localization import build_session
from fgloc.sim import simulate_paper
from fgloc.types import Trajectory

ROUTES = {
    "straight": {"route": [[2.5, 3.0], [20.0, 3.0]]},
    "stop_turn_go": {"route": [[14.0, 3.0], [27.5, 3.0], [27.5, 10.0]]},
    "arcs": {"route": [[14.0, 3.0], [27.5, 3.0], [27.5, 10.0]], "turn_radii_m": 1.5},
}


@pytest.fixture(scope="module", params=sorted(ROUTES))
def drive(request):
    return request.param, simulate_paper(seed=2, **ROUTES[request.param])


def _scans_only(sim, keep_imu: bool = False):
    out = copy.copy(sim)
    drop = {"/odom"} if keep_imu else {"/odom", "/imu"}
    out.messages = [m for m in sim.messages if m[0] not in drop]
    return out


def _errors(traj: Trajectory, gt: Trajectory) -> tuple[float, float]:
    """Position RMSE (m) and heading RMSE (deg) of ``traj`` against the truth at its stamps."""
    g = interpolate_poses(gt.stamps, gt.poses, traj.stamps)
    d = np.hypot(traj.poses[:, 0] - g[:, 0], traj.poses[:, 1] - g[:, 1])
    a = np.degrees(wrap_angle(traj.poses[:, 2] - g[:, 2]))
    return float(np.sqrt(np.mean(d * d))), float(np.sqrt(np.mean(a * a)))


@pytest.mark.parametrize("imu", [False, True], ids=["scans", "scans+imu"])
def test_the_smoother_tracks_scans_alone_as_well_as_the_ekf(drive, imu):
    name, sim = drive
    run = _scans_only(sim, keep_imu=imu)
    final, online, loc, _ = localize_sim(run, "smoother", "native")
    assert loc.stats["odometry"] == 0 and loc.stats["status"]["counts"]["lost"] == 0
    (fin, fin_yaw), (onl, _) = _errors(final, sim.ground_truth), _errors(online, sim.ground_truth)
    # measured (m, final / online): 0.014 / 0.014 on each drive, with the IMU or without; the EKF 0.014.
    # Before (no motion between keyframes: each guess where the last one was, and the graph pulled back
    # towards it): online 0.70-0.74 m, the poses ~1 s behind the robot.
    assert fin < 0.03 and onl < 0.03 and fin_yaw < 0.5, (name, fin, onl, fin_yaw)
    if not imu:
        ekf, _, _, _ = localize_sim(run, "ekf", "native")
        assert fin < 1.5 * _errors(ekf, sim.ground_truth)[0] + 0.005


def test_the_prediction_runs_on_with_the_robot():
    """Between scans the guess moves at the graph's velocity (it stood at the last keyframe)."""
    sim = _scans_only(simulate_paper(seed=2, **ROUTES["straight"]))
    session = build_session(sim.map, sim.laser_mount, backend="smoother", frontend="native",
                            initial_pose=sim.ground_truth.poses[0])
    scans = [m for m in sim.messages if m[0] == "/scan"]
    half = len(scans) // 2
    for topic, msg in sim.messages:
        session.feed(topic, msg)
        if msg is scans[half][1]:
            break
    backend = session.loc.backend
    t_kf = backend.current(covariance=False)[0]
    t = t_kf + 0.5
    guess, cov = backend.predict(t)
    truth = interpolate_poses(sim.ground_truth.stamps, sim.ground_truth.poses, np.array([t]))[0]
    moved = between(interpolate_poses(sim.ground_truth.stamps, sim.ground_truth.poses, np.array([t_kf]))[0], truth)
    assert moved[0] > 0.3                                       # the robot drove 0.4 m in that half second
    off = float(np.hypot(*(guess[:2] - truth[:2])))
    assert off < 0.05                   # measured 0.004 m (was 0.40 m: left behind)
    # its covariance covers half a second of unknown acceleration (was 2.5e-5 m^2: zero motion, sure of it)
    assert 0.005 < float(cov[0, 0]) < 0.05   # measured 0.021 m^2


def test_no_odometry_no_scales_and_no_wait():
    """Without odometry no speed or yaw-rate scale is estimated (the motion prior is no wheel), and a
    keyframe is not held back waiting for odometry that never comes."""
    sim = _scans_only(simulate_paper(seed=2, **ROUTES["straight"]))
    final, online, loc, _ = localize_sim(sim, "smoother", "native")
    backend = loc.backend
    assert np.allclose(backend.odom_scales(), 1.0)
    assert "odom_speed_scale" not in backend.chains and "odom_yaw_scale" not in backend.chains
    # every keyframe's online pose is the solver's (not a prediction made while it waited)
    assert len(online) >= len(final)


def test_the_motion_model_line_says_what_is_used():
    """The run summary's motion-model line names the velocity carried on, not an odometry that never came."""
    sim = _scans_only(simulate_paper(seed=2, route=[[2.5, 3.0], [6.0, 3.0]]))
    lines = {}
    for backend in ("smoother", "ekf"):
        _, _, loc, _ = localize_sim(sim, backend, "native")
        lines[backend] = loc.stats["motion_model"]
    assert lines["smoother"] == ("no odometry: the graph's own velocity is carried from keyframe to keyframe "
                                 "(constant velocity, a random walk of it between the scans' fixes)")
    assert lines["ekf"] == ("no odometry: the filter's own velocity carries the pose from fix to fix; "
                            "differential [x, y, yaw, v, w] (the fixes never moved sideways)")
    _, _, loc, _ = localize_sim(_scans_only(simulate_paper(seed=2, route=[[2.5, 3.0], [6.0, 3.0]]), keep_imu=True),
                                "smoother", "native")
    assert loc.stats["motion_model"].endswith("; the gyro's yaw rate turns it")
