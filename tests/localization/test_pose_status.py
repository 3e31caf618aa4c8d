"""Every pose has a status (fgloc.localization.monitor): a silent laser gives dead-reckoned poses with a
growing covariance and a degraded status; the status file beside trajectory.tum; a map no scan
matches is an error, not "lost 0 %"."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from fgloc.config import load_config
from fgloc.localization import Localizer, Session
from fgloc.localization.monitor import STATUS_COLUMNS, ConsistencyMonitor
from fgloc.localization.session import BaseSink

BLACKOUT = (10.0, 30.0)  # start, duration (s)
ROUTE = [[2.5, 3.0], [27.5, 3.0], [27.5, 17.0]]  # two legs of the paper's rectangle (55 s)


class Poses(BaseSink):
    """The fused poses the session reports, with or without a scan."""

    def __init__(self) -> None:
        self.scan: list[tuple[float, str]] = []
        self.dead_reckoned: list[tuple[float, str, float]] = []

    def on_scan(self, stamp, scan, fix_or_reason, fused) -> None:
        if fused is not None:
            self.scan.append((stamp, fused.status))

    def on_pose(self, stamp, fused) -> None:
        self.dead_reckoned.append((stamp, fused.status, float(np.trace(fused.cov[:2, :2]))))


@pytest.fixture(scope="module")
def silent_laser():
    from fgloc.sim import run_scenario

    return run_scenario({"route": ROUTE, "faults": {"laser_blackout": {"start": BLACKOUT[0], "duration": BLACKOUT[1]}}},
                        seed=0)


@pytest.mark.parametrize("backend", ["smoother", "ekf"])
def test_a_silent_laser_dead_reckons_with_a_growing_covariance(silent_laser, backend):
    sim = silent_laser
    t0, t1 = BLACKOUT[0], BLACKOUT[0] + BLACKOUT[1]
    msgs = [(t, m) for t, m in sim.messages if t != "/ground_truth"]
    loc = Localizer(sim.map, sim.laser_mount, backend, "native", initial_pose=sim.ground_truth.poses[0],
                    config=load_config())
    sink = Poses()
    est = Session(loc, sinks=[sink]).run(msgs)
    # poses keep coming while no scan arrives: every 0.1 s after a second of silence (the online trajectory)
    online = loc.online_trajectory().stamps
    inside = online[(online > t0 + 1.2) & (online < t1 - 0.1)]
    assert len(inside) > 250 and float(np.diff(inside).max()) < 0.15
    dr = [(t, s, c) for t, s, c in sink.dead_reckoned if t0 < t < t1]
    assert len(dr) > 250
    assert {s for _, s, _ in dr} == {"degraded"}
    # ... with a covariance that grows with the odometry
    c = np.array([c for _, _, c in dr])
    tc = np.array([t for t, _, _ in dr])
    blocks = [float(c[(tc >= a) & (tc < a + 3.0)].mean()) for a in np.arange(t0 + 1.5, t1 - 3.0, 3.0)]
    assert np.all(np.diff(blocks) > 0) and blocks[-1] > 5 * blocks[0]  # measured 61x (smoother), 9x (EKF)
    # the monitor's records say why
    status, why = loc.monitor.at(inside)
    assert set(status) == {"degraded"} and all("no scan for" in w for w in why)
    # dead reckoning stays close (the paper robot's odometry; the online poses: a smoother's final
    # trajectory has its keyframes, at scans) and the map takes over again at once
    on = loc.online_trajectory()
    err = np.hypot(*(on.poses[:, :2] - sim.ground_truth.interpolate(on.stamps)[:, :2]).T)
    assert float(err[(on.stamps > t0) & (on.stamps < t1)].max()) < 0.5  # 30 s, a turn: 0.34 m (smoother), 0.20 m (EKF)
    fin = np.hypot(*(est.poses[:, :2] - sim.ground_truth.interpolate(est.stamps)[:, :2]).T)
    assert float(fin[est.stamps > t1 + 1.0].max()) < 0.1
    after = [s for t, s in sink.scan if t1 + 1.0 < t < t1 + 5.0]
    assert after and set(after) == {"ok"}


def test_monitor_records_amends_and_answers_at_any_stamp():
    m = ConsistencyMonitor()
    for t in np.arange(0.0, 10.0, 1.0):
        m.record(t, "ok")
    m.record(9.0, "degraded", "replaced")  # the same stamp again: replaced
    assert m.current == ("degraded", "replaced")
    assert m.amend(3.0, 5.0, "lost", "relocalized") == 3
    assert m.amend(0.0, 9.0, "suspect", "x") == 7  # lost stays lost
    s, w = m.at([-1.0, 3.5, 9.5])
    assert s == ["lost", "lost", "suspect"] and w[0] == "no pose yet"
    assert m.counts() == {"ok": 0, "degraded": 0, "suspect": 7, "lost": 3}


def test_run_writes_the_status_file_and_the_fused_pose_without_scans(tmp_path, paper_sim):
    """A wheels + compass log (no laser) gets /fused_pose and /fgloc/pose/status in run.mcap and a status
    file beside trajectory.tum, one row per pose."""
    from mcap.reader import make_reader

    from fgloc.app.run import RunRequest, run_log
    from fgloc.sim import write_sim
    from fgloc.types import LaserScan

    sim = paper_sim
    no_laser = type(sim)(sim.map, [(t, m) for t, m in sim.messages if not isinstance(m, LaserScan)],
                         sim.ground_truth, sim.laser_mount, sim.compass_offset_rad, sim.robot, sim.scenario)
    d = write_sim(no_laser, tmp_path / "sim")
    r = run_log(RunRequest(log=d / "log.mcap", outdir=tmp_path / "out"))
    assert r.mode == "odom" and r.poses > 1000 and r.failure() is None
    assert "trajectory_status.csv" in r.written
    lines = (tmp_path / "out" / "trajectory_status.csv").read_text().splitlines()
    assert lines[0].startswith("# fgloc pose status")
    rows = list(csv.reader(lines[1:]))
    assert tuple(rows[0]) == STATUS_COLUMNS and len(rows) - 1 == r.poses
    traj = np.loadtxt(tmp_path / "out" / "trajectory.tum")
    np.testing.assert_allclose([float(x[0]) for x in rows[1:]], traj[:, 0], atol=1e-9)
    assert {x[4] for x in rows[1:]} == {"ok"} and r.status["counts"]["ok"] == r.poses
    assert all(float(x[5]) > 0 and float(x[8]) > 0 for x in rows[1:])
    with open(tmp_path / "out" / "run.mcap", "rb") as f:
        topics = [c.topic for _, c, _ in make_reader(f).iter_messages(topics=["/fused_pose", "/fgloc/pose/status"])]
    assert topics.count("/fused_pose") >= r.poses - 1
    assert topics.count("/fgloc/pose/status") == topics.count("/fused_pose")


def test_a_map_no_scan_matches_is_an_error_not_lost_0_percent(tmp_path, capsys):
    """A few metres of the paper run on a map with no walls: 0 fixes.  Dead reckoning presented as
    localization before ("lost 0 %", exit 0); now one line and exit 3."""
    from fgloc.cli import main
    from fgloc.maps import OccupancyMap
    from fgloc.sim import simulate_paper, write_sim

    sim = simulate_paper(seed=0, route=[[2.5, 3.0], [3.7, 3.0]])  # 1.2 m: every scan a global search
    d = write_sim(sim, tmp_path / "sim")
    m = sim.map
    no_walls = OccupancyMap(np.where(m.data > 50, 0, m.data).astype(np.int16), m.resolution, m.origin)
    no_walls.save(tmp_path / "empty.yaml")
    rc = main(["run", str(d / "log.mcap"), "--map", str(tmp_path / "empty.yaml"), "--initial-pose", "2.5",
               "3.0", "0.0", "-o", str(tmp_path / "out"), "-q"])
    out = capsys.readouterr()
    assert rc == 3
    assert "no scan matched the map: no fix in" in out.err and len(out.err.strip().splitlines()) == 1
    assert "pose status:" in out.out and "lost 0 %" not in out.out
    rows = list(csv.reader((tmp_path / "out" / "trajectory_status.csv").read_text().splitlines()[2:]))
    assert len(rows) > 10 and {r[4] for r in rows} == {"lost"}  # never confirmed by the map


def test_status_file_format_is_documented_in_the_readme():
    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    assert "trajectory_status.csv" in readme
    for col in STATUS_COLUMNS:
        assert col in readme


def test_too_many_suspect_or_lost_poses_make_the_run_unusable():
    from fgloc.app.run import RunResult
    from fgloc.localization.stats import RunStats

    def result(counts: dict[str, int], verdicts: list | None = None) -> RunResult:
        n = sum(counts.values())
        return RunResult("map", "map", "smoother", "native", n, n, n, RunStats(), 1.0, 10.0, Path("."), [],
                         status={"counts": counts, "bad_share": (counts["suspect"] + counts["lost"]) / n,
                                             "verdicts": verdicts or []})

    assert result({"ok": 80, "degraded": 5, "suspect": 10, "lost": 5}).failure() is None  # 15 % <= 20 %
    line = result({"ok": 70, "degraded": 5, "suspect": 20, "lost": 5}).failure()
    assert line is not None and line.startswith("25 % of the poses are suspect or lost (20 suspect, 5 lost of 100")
    assert "--allow-lost" in line
    v = {"kind": "no_fix", "message": "no scan matched the map: ...", "unusable": True}
    line = result({"ok": 100, "degraded": 0, "suspect": 0, "lost": 0}, [v]).failure()
    assert line is not None and line.startswith("no scan matched the map")
    v = {"kind": "initial_pose", "message": "the initial pose ...", "unusable": False}
    assert result({"ok": 100, "degraded": 0, "suspect": 0, "lost": 0}, [v]).failure() is None


def test_monitor_keeps_a_bounded_history_when_asked():
    m = ConsistencyMonitor()
    m.history_s = 10.0  # Localizer.keep_history (a live session)
    for t in np.arange(0.0, 1000.0, 0.1):
        m.record(t, "ok")
    assert len(m.t) <= 201 and m.t[-1] == pytest.approx(999.9) and m.at([995.0])[0] == ["ok"]


def test_a_back_end_heading_that_diverges_makes_its_poses_suspect_and_is_said():
    """A back-end that counts log time its fused heading followed none of its heading sources (the
    smoother's heading check, in its ``stats["heading_diverged_s"]``): the poses while the counter grows
    are suspect, and the run says so in one line.  The counter is advanced here as the back-end does."""
    from fgloc.sim import simulate_paper

    sim = simulate_paper(seed=0, route=[[2.5, 3.0], [16.5, 3.0]])  # 20 s
    msgs = [(t, m) for t, m in sim.messages if t != "/ground_truth"]
    loc = Localizer(sim.map, sim.laser_mount, "ekf", "native", initial_pose=sim.ground_truth.poses[0],
                    config=load_config())
    session = Session(loc)
    stamp = [float(getattr(m, "stamp", 0.0)) for _, m in msgs]
    t0 = stamp[0]
    for (topic, msg), t in zip(msgs, stamp, strict=True):
        if 10.0 <= t - t0 < 14.0:  # diverging for 4 s
            loc.backend.stats["heading_diverged_s"] = t - t0 - 10.0
            loc.backend.stats["heading_divergence_spans"] = 1
        session.feed(topic, msg)
    est = session.finish()
    status, why = loc.monitor.at(est.stamps)
    rel = est.stamps - t0
    bad = {s for s, r in zip(status, rel, strict=True) if 10.5 < r < 14.0}
    assert bad == {"suspect"} and all("heading diverged" in w for w, r in zip(why, rel, strict=True) if 10.5 < r < 14.0)
    assert {s for s, r in zip(status, rel, strict=True) if r < 9.5 or r > 15.5} == {"ok"}
    (v,) = [v for v in loc.stats["status"]["verdicts"] if v["kind"] == "heading_diverged"]
    assert v["message"].startswith("the ekf's heading followed none of its heading sources for 4.0 s")
    assert not v["unusable"]
