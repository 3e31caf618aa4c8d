"""Runs through the emulators (pty + TCP) into the live localizer, against `fgloc run`."""

from __future__ import annotations

import numpy as np
import pytest

from fgloc.commands.run import run_log
from fgloc.eval.metrics import evaluate
from fgloc.io.log import LogWriter
from fgloc.io.tum import read_tum
from fgloc.live.harness import replay_live
from fgloc.types import Trajectory

from .streams import world

try:
    from fgloc.sim import simulate_paper  # noqa: F401

    HAVE_SIM = True
except ImportError:
    HAVE_SIM = False

WINDOW_S = 25.0  # seconds of the paper run replayed in real time (the full run: tools/bench_latency.py)


def _window(traj: Trajectory, t0: float, t1: float) -> Trajectory:
    m = (traj.stamps >= t0) & (traj.stamps <= t1)
    return Trajectory(traj.stamps[m], traj.poses[m])


def test_world_live_vs_fgloc_run_and_recording(tmp_path):
    """A self-made world (no simulator needed), replayed at 2x through socket:// + TCP."""
    occ, mount, gt, msgs = world(duration=12.0)
    log = tmp_path / "world.mcap"
    with LogWriter(log) as w:
        w.write("/tf_static", [mount], msgs[0][1].stamp)  # type: ignore[attr-defined]
        for topic, m in msgs:
            w.write(topic, m)
    map_yaml = occ.save(tmp_path / "map.yaml")
    init = gt.poses[0]
    rec = tmp_path / "live.mcap"
    res = replay_live(msgs, occ, mount, robot={"drive": "mecanum"}, backend="smoother", initial_pose=init,
                      speed=2.0, mode="tcp", record=rec)
    c = res.summary.counters
    assert c["serial"]["crc_errors"] == 0 and c["laser"]["malformed"] == 0 and c["localizer_errors"] == 0
    assert c["scans_fused"] >= 0.95 * len([1 for t, _ in msgs if t == "/scan"])
    live = evaluate(res.live_run, gt)
    run_log(log, tmp_path / "run", map_yaml=map_yaml, backend="smoother", initial_pose=list(init), quiet=True)
    run_online = evaluate(read_tum(tmp_path / "run" / "online.tum"), gt)
    run_final = evaluate(read_tum(tmp_path / "run" / "trajectory.tum"), gt)
    print(f"\nworld: live {live.position_rmse_m * 1e3:.2f} mm, fgloc run online "
          f"{run_online.position_rmse_m * 1e3:.2f} mm, smoothed {run_final.position_rmse_m * 1e3:.2f} mm")
    # errors here are ~1 mm, so allow 1 mm of clock-alignment error (0.5 ms at 1 m/s) on top
    assert live.position_rmse_m <= 1.5 * run_online.position_rmse_m + 0.001
    out = run_log(rec, tmp_path / "rerun", map_yaml=map_yaml, backend="smoother", initial_pose=list(init),
                  quiet=True)
    assert out["truncated"] is None
    rerun = read_tum(tmp_path / "rerun" / "trajectory.tum")
    rerun_m = evaluate(Trajectory(np.asarray(res.clock.to_run(rerun.stamps)), rerun.poses), gt)
    print(f"world: recorded MCAP through fgloc run {rerun_m.position_rmse_m * 1e3:.2f} mm")
    assert rerun_m.position_rmse_m <= 1.5 * run_final.position_rmse_m + 0.001


@pytest.mark.skipif(not HAVE_SIM, reason="fgloc.sim has not landed yet")
def test_paper_run_live_vs_fgloc_run_and_recording(paper_sim, paper_dir, tmp_path):
    sim = paper_sim
    gt = sim.ground_truth
    stamps = [float(m.stamp) for _, m in sim.messages if hasattr(m, "stamp")]
    s0 = min(stamps)
    init = gt.interpolate(s0)[0]
    rec = tmp_path / "live.mcap"
    res = replay_live(sim.messages, sim.map, sim.laser_mount, robot=sim.robot, backend="smoother",
                      initial_pose=init, t_start=s0, duration=WINDOW_S, speed=1.0, mode="pty", record=rec)
    c = res.summary.counters
    assert c["serial"]["crc_errors"] == 0 and c["laser"]["malformed"] == 0
    assert c["scans_fused"] >= 0.95 * c["laser"]["scans"] > 0
    t_end = float(res.live_run.stamps[-1])
    live = evaluate(res.live_run, gt)

    # fgloc run on the simulated log, same start pose, scored on the same window
    out = run_log(paper_dir / "log.mcap", tmp_path / "run", map_yaml=paper_dir / "map.yaml",
                  backend="smoother", initial_pose=list(init), quiet=True)
    run_final = evaluate(_window(read_tum(tmp_path / "run" / "trajectory.tum"), s0, t_end), gt)
    run_online = evaluate(_window(read_tum(tmp_path / "run" / "online.tum"), s0, t_end), gt)
    assert out["poses"] > 0
    print(f"\nlive RMSE {live.position_rmse_m:.4f} m over {live.n} poses; fgloc run: smoothed "
          f"{run_final.position_rmse_m:.4f} m, online {run_online.position_rmse_m:.4f} m")
    assert live.position_rmse_m <= 1.5 * run_final.position_rmse_m
    assert live.position_rmse_m <= 1.5 * run_online.position_rmse_m

    # the live recording re-runs through fgloc run to the same accuracy (host time -> run time)
    init_host = init
    out2 = run_log(rec, tmp_path / "rerun", map_yaml=paper_dir / "map.yaml", backend="smoother",
                   initial_pose=list(init_host), quiet=True)
    assert out2["truncated"] is None and out2["poses"] > 0
    rerun = read_tum(tmp_path / "rerun" / "trajectory.tum")
    rerun_run = Trajectory(np.asarray(res.clock.to_run(rerun.stamps)), rerun.poses)
    rerun_m = evaluate(rerun_run, gt)
    print(f"recorded MCAP through fgloc run: {rerun_m.position_rmse_m:.4f} m")
    assert rerun_m.position_rmse_m <= 1.2 * run_final.position_rmse_m + 0.002
    assert abs(rerun_m.position_rmse_m - run_final.position_rmse_m) <= 0.25 * run_final.position_rmse_m + 0.002
