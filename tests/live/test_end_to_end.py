"""Runs replayed through the emulators (pty / socket:// + TCP) into the live localizer,
compared with `fgloc run` on a log of exactly the replayed messages, and the live
recording re-run through `fgloc run`.

Compared like with like: the live online poses (published as they happen) with
`fgloc run`'s online trajectory, the live session's smoothed trajectory
(``Localizer.finish()`` at shutdown) with `fgloc run`'s smoothed one.  The full paper
run is measured by ``tools/bench_latency.py --duration 0``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fgloc.app.run import RunRequest, run_log
from fgloc.eval.metrics import evaluate
from fgloc.io import open_log
from fgloc.io.mcap_writer import LogWriter
from fgloc.io.tum import read_tum
from fgloc.testing.harness import replay_live
from fgloc.types import Trajectory

from .streams import world

try:
    from fgloc.sim import simulate_paper  # noqa: F401

    HAVE_SIM = True
except ImportError:
    HAVE_SIM = False


def _write_log(path: Path, msgs, mount) -> Path:
    with LogWriter(path) as w:
        w.write("/tf_static", [mount], msgs[0][1].stamp)
        for topic, m in msgs:
            if topic in ("/odom", "/imu", "/scan"):
                w.write(topic, m)
    return path


def _without_skipped_scans(rec: Path, out: Path) -> Path:
    """The recording's inputs without the scans live skipped (those without a /fused_pose at their stamp)."""
    fused = {round(float(m.stamp), 6) for _, m in open_log(rec).messages(["/fused_pose"])}
    with LogWriter(out) as w:
        for rc in open_log(rec).records():
            if rc.topic == "/fused_pose" or (rc.topic == "/scan" and round(float(rc.msg.stamp), 6) not in fused):
                continue
            w.copy(rc)
    return out


def _host_to_run(traj: Trajectory, clock) -> Trajectory:
    return Trajectory(np.asarray(clock.to_run(traj.stamps)), traj.poses)


def _compare(msgs, occ, mount, gt, robot, tmp_path, speed, mode, slack_m, sick_kw=None):
    """Replay live, run offline, re-run the recording; return the RMSEs (m) and the live summary."""
    init = gt.interpolate(float(msgs[0][1].stamp))[0]
    log = _write_log(tmp_path / "replayed.mcap", msgs, mount)
    map_yaml = occ.save(tmp_path / "map.yaml")
    rec = tmp_path / "live.mcap"
    res = replay_live(msgs, occ, mount, robot=robot, backend="smoother", initial_pose=init, speed=speed,
                      mode=mode, record=rec, sick_kw=sick_kw)
    c = res.summary.counters
    assert c["serial"]["crc_errors"] == 0 and c["serial"]["dropped"] == 0
    assert c["laser"]["malformed"] == 0 and c["localizer_errors"] == 0
    n_scans = sum(1 for t, _ in msgs if t == "/scan")
    # every scan read and either fused or counted as skipped (a newer one already queued: a busy
    # host skips some, an idle one none)
    skipped = c["scans_skipped_backlog"]
    assert c["laser"]["scans"] == n_scans and c["scans_fused"] + skipped == n_scans, (c, res.summary.events)
    assert res.summary.n_poses == c["scans_fused"]  # a pose for every fused scan

    run_log(RunRequest(log, tmp_path / "run", map_yaml=map_yaml, backend="smoother", initial_pose=tuple(init)))
    out = run_log(RunRequest(rec, tmp_path / "rerun", map_yaml=map_yaml, backend="smoother",
                             initial_pose=tuple(init)))
    assert out.truncated is None  # the recording was closed properly
    r = {
        "live_online": evaluate(res.live_run, gt).position_rmse_m,
        "live_smoothed": evaluate(res.smoothed_run, gt).position_rmse_m,
        "run_online": evaluate(read_tum(tmp_path / "run" / "online.tum"), gt).position_rmse_m,
        "run_smoothed": evaluate(read_tum(tmp_path / "run" / "trajectory.tum"), gt).position_rmse_m,
        "rerun_online": evaluate(_host_to_run(read_tum(tmp_path / "rerun" / "online.tum"), res.clock),
                                 gt).position_rmse_m,
        "rerun_smoothed": evaluate(_host_to_run(read_tum(tmp_path / "rerun" / "trajectory.tum"), res.clock),
                                   gt).position_rmse_m,
    }
    # live compared with fgloc run on the scans live fused: all of them (the replayed log), or when
    # scans were skipped, the recording without them (the scans that have no /fused_pose)
    ref = {"online": r["run_online"], "smoothed": r["run_smoothed"]}
    if skipped:
        fused_only = _without_skipped_scans(rec, tmp_path / "fused_only.mcap")
        run_log(RunRequest(fused_only, tmp_path / "fused", map_yaml=map_yaml, backend="smoother",
                           initial_pose=tuple(init)))
        for k, f in (("online", "online.tum"), ("smoothed", "trajectory.tum")):
            ref[k] = r[f"fused_{k}"] = evaluate(_host_to_run(read_tum(tmp_path / "fused" / f), res.clock),
                                                gt).position_rmse_m
    print(f"\n{skipped} of {n_scans} scans skipped  " + "  ".join(f"{k} {v * 1e3:.3f} mm" for k, v in r.items()))
    # live within 1.5x of fgloc run (plus `slack_m` of clock-alignment error: the live stamps
    # carry the unobservable minimum transport delay, ~0.1-0.2 ms here)
    assert r["live_online"] <= 1.5 * ref["online"] + slack_m, r
    assert r["live_smoothed"] <= 1.5 * ref["smoothed"] + slack_m, r
    # the recording gives the same result through fgloc run
    for k in ("online", "smoothed"):
        assert abs(r[f"rerun_{k}"] - r[f"run_{k}"]) <= 0.25 * r[f"run_{k}"] + slack_m
    return r, res.summary


def test_world_live_vs_fgloc_run_and_recording(tmp_path):
    """A self-made room (no simulator needed), replayed at 2x through socket:// and TCP."""
    occ, mount, gt, msgs = world(duration=10.0)
    _compare(msgs, occ, mount, gt, {"drive": "mecanum"}, tmp_path, speed=2.0, mode="tcp", slack_m=0.0005)


@pytest.mark.skipif(not HAVE_SIM, reason="fgloc.sim has not landed yet")
def test_paper_run_live_vs_fgloc_run_and_recording(paper_sim, tmp_path):
    """The first 10 s of the simulated paper run, real time, serial over a pty (whole run: bench_latency)."""
    sim = paper_sim
    s0 = min(float(m.stamp) for _, m in sim.messages if hasattr(m, "stamp"))
    msgs = [(t, m) for t, m in sim.messages if t in ("/odom", "/imu", "/scan") and m.stamp <= s0 + 10.0]
    _compare(msgs, sim.map, sim.laser_mount, sim.ground_truth, sim.robot, tmp_path, speed=1.0, mode="pty",
             slack_m=0.0002)


def test_tim571_shaped_laser_live_trajectory(tmp_path):
    """The laser speaks a TiM571's telegram shape (tests/live/real_telegrams.py: 15 Hz, 0.3333 deg steps,
    811 beams from -45 deg device angle, RSSI1 as a second 16-bit channel, a name block, DeviceIdent
    TiM571) over real TCP into the live localizer; the trajectory matches ground truth and fgloc run."""
    tim = {"start_deg": -135.0, "step_deg": 0.3333, "n": 811, "hz": 15.0, "beam_dt_s": 1 / 16200,
           "range_max_m": 25.0, "noise_m": 0.012}
    occ, mount, gt, msgs = world(duration=8.0, laser=tim)
    sick_kw = {"telegram": {"rssi_bits": 16, "name": "fgloc-tim"}, "device_ident": "E TiM571-2050101 6 V3.50"}
    r, summary = _compare(msgs, occ, mount, gt, {"drive": "mecanum"}, tmp_path, speed=2.0, mode="tcp",
                          slack_m=0.0005, sick_kw=sick_kw)
    lc = summary.counters["laser"]
    assert lc["device"] == "TiM571-2050101" and lc["device_errors"] == 0 and lc["other_layer"] == 0
    assert r["live_online"] < 0.03 and r["live_smoothed"] < 0.03, r


def test_cola_b_laser_live_trajectory(tmp_path):
    """The laser set to CoLa-B (binary, sick_scan_xd's dialect): the live client finds it in the first
    answer, reads every scan in CoLa-B, and the trajectory matches fgloc run on the same log."""
    occ, mount, gt, msgs = world(duration=6.0)
    r, summary = _compare(msgs, occ, mount, gt, {"drive": "mecanum"}, tmp_path, speed=2.0, mode="tcp",
                          slack_m=0.0005, sick_kw={"dialect": "B"})
    lc = summary.counters["laser"]
    assert lc["dialect"] == "B" and lc["cola_b_bad_checksum"] == 0 and lc["malformed"] == 0
    assert r["live_online"] < 0.03 and r["live_smoothed"] < 0.03, r
