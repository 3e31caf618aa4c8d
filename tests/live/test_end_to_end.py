"""The paper run through the emulators (pty + TCP) into the live localizer, against `fgloc run`."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("fgloc.sim")

from fgloc.commands.run import run_log  # noqa: E402
from fgloc.eval.metrics import evaluate  # noqa: E402
from fgloc.io.tum import read_tum  # noqa: E402
from fgloc.live.harness import replay_live  # noqa: E402
from fgloc.types import Trajectory  # noqa: E402

WINDOW_S = 25.0  # seconds of the paper run replayed in real time (the full run: tools/bench_latency.py)


def _window(traj: Trajectory, t0: float, t1: float) -> Trajectory:
    m = (traj.stamps >= t0) & (traj.stamps <= t1)
    return Trajectory(traj.stamps[m], traj.poses[m])


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
