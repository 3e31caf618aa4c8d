"""What `fgloc run` writes and how cheaply: the inputs copied into run.mcap as the log
stores them, its own messages on the input's log-time clock, the fused pose's covariance
refreshed at a bounded rate, the time split and the damage counters in RunResult."""

from __future__ import annotations

import numpy as np
import pytest

from fgloc.app.run import RunRequest, run_log
from fgloc.io import open_log
from fgloc.io.mcap_writer import LogWriter
from fgloc.localization import CallbackSink, Localizer, Session

SHORT_ROUTE = [[2.5, 3.0], [8.5, 3.0]]  # 6 m along the paper hall's south side, ~11 s
LOG_CLOCK_OFFSET_NS = 1_000_000_000  # the recorder's clock 1 s ahead of the header stamps


@pytest.fixture(scope="module")
def short_sim():
    from fgloc.sim import run_scenario

    return run_scenario({"route": SHORT_ROUTE, "laser": {"rate_hz": 10.0}}, seed=0)


@pytest.fixture(scope="module")
def offset_log(short_sim, tmp_path_factory):
    """The short run written with log times 1 s after the header stamps (a recorder on its own clock)."""
    from fgloc.io.ros import stamp_to_ns

    d = tmp_path_factory.mktemp("offset_log")
    short_sim.map.save(d / "map.yaml")
    with LogWriter(d / "log.mcap") as w:
        for i, (topic, msg) in enumerate(short_sim.messages):
            if i == 0:  # /tf_static
                w.write(topic, msg, stamp=0.0, log_time_ns=LOG_CLOCK_OFFSET_NS)
                continue
            w.write(topic, msg, log_time_ns=stamp_to_ns(float(msg.stamp)) + LOG_CLOCK_OFFSET_NS)
    return d


def test_run_copies_the_inputs_and_writes_on_the_input_clock(offset_log, short_sim, tmp_path):
    out = tmp_path / "out"
    r = run_log(RunRequest(log=offset_log / "log.mcap", outdir=out, map_yaml=offset_log / "map.yaml",
                           initial_pose=tuple(short_sim.ground_truth.poses[0]), view_channels=False))
    assert r.poses > 50 and r.damaged_chunks == 0 and r.damage is None
    topics = ["/scan", "/odom", "/imu", "/tf_static"]
    src = {(rec.topic, rec.log_time_ns): rec.data for rec in open_log(offset_log / "log.mcap").records(topics)}
    got = {(rec.topic, rec.log_time_ns): rec.data for rec in open_log(out / "run.mcap").records(topics)}
    assert got == src  # every input, its own bytes at its own log time: no decode / encode round trip
    input_times = {t for _, t in src}
    fused = list(open_log(out / "run.mcap").records(["/fused_pose"]))
    assert len(fused) == r.stats.scans
    for rec in fused:
        # written while its scan was processed: at that input's log time, stamped with the pose's own time
        assert rec.log_time_ns in input_times
        assert abs(rec.log_time_ns - LOG_CLOCK_OFFSET_NS - round(rec.msg.stamp * 1e9)) < 100_000_000
    t = r.timings
    assert set(t) >= {"setup_s", "read_s", "write_s", "view_s", "localize_s", "finish_s", "outputs_s", "total_s"}
    assert all(v >= 0 for v in t.values()) and t["view_s"] == 0.0
    parts = t["setup_s"] + t["read_s"] + t["write_s"] + t["localize_s"] + t["finish_s"] + t["outputs_s"]
    assert parts == pytest.approx(t["total_s"], rel=0.05, abs=0.05)


def test_fused_covariance_refreshed_at_a_bounded_rate_poses_unchanged(short_sim):
    """A marginal per covariance_period_s of log time, not per scan; every pose and the final
    trajectory exactly as with a marginal at every scan."""
    runs = {}
    for period in (0.0, 1.0):
        loc = Localizer(short_sim.map, short_sim.laser_mount, backend="smoother", frontend="native",
                        initial_pose=short_sim.ground_truth.poses[0])
        fresh = []
        current = loc.current

        def counted(covariance: bool = True, current=current, fresh=fresh, **kw):  # type: ignore[no-untyped-def]
            fresh.append(covariance)
            return current(covariance, **kw)

        loc.current = counted  # type: ignore[method-assign]
        fused = []
        sink = CallbackSink(on_scan=lambda stamp, scan, what, f, fused=fused: fused.append(f))
        final = Session(loc, sinks=[sink], covariance_period_s=period).run(short_sim.messages)
        runs[period] = (final, [f for f in fused if f is not None], fresh)
    (final0, fused0, fresh0), (final1, fused1, fresh1) = runs[0.0], runs[1.0]
    duration = float(short_sim.ground_truth.duration)
    assert all(fresh0) and len(fresh0) == len(fresh1)  # asked at every scan, a fresh marginal each time
    assert sum(fresh1) <= duration / 1.0 + 2 < len(fresh1) / 3  # at most one a second of log time
    assert np.array_equal(final0.poses, final1.poses) and np.array_equal(final0.stamps, final1.stamps)
    assert len(fused0) == len(fused1)
    for a, b in zip(fused0, fused1, strict=True):
        assert a.stamp == b.stamp and np.array_equal(a.pose, b.pose)
        assert np.all(np.isfinite(b.cov)) and np.all(np.diag(b.cov) > 0)


def test_a_progress_sink_does_not_ask_for_the_fused_pose(short_sim):
    loc = Localizer(short_sim.map, short_sim.laser_mount, backend="smoother", frontend="native",
                    initial_pose=short_sim.ground_truth.poses[0])
    calls = []
    current = loc.current
    loc.current = lambda covariance=True, **kw: calls.append(covariance) or current(covariance, **kw)  # type: ignore[method-assign]
    seen = []
    Session(loc, sinks=[CallbackSink(on_message=lambda t, m: seen.append(t))]).run(short_sim.messages)
    assert len(seen) == len(short_sim.messages) and calls == []


def test_run_summary_compares_with_the_logs_ground_truth_not_the_papers_numbers(offset_log, short_sim, tmp_path):
    """``fgloc run`` on a log with /ground_truth prints the errors; the paper's reported values (its
    robot, its hall) are no reference for a user's log and were printed beside them as "paper (EKF)"
    (probe10, on a Gazebo TurtleBot3 log).  ``fgloc eval --paper`` and ``fgloc bench paper`` keep them."""
    from fgloc.commands.run import run_summary_lines

    r = run_log(RunRequest(log=offset_log / "log.mcap", outdir=tmp_path / "out", map_yaml=offset_log / "map.yaml",
                           initial_pose=tuple(short_sim.ground_truth.poses[0]), view_channels=False))
    assert r.metrics is not None
    out = "\n".join(run_summary_lines(r))
    header = next(line for line in out.splitlines() if line.strip().startswith("metric"))
    assert header.split() == ["metric", "unit", "smoother", "(final)", "smoother", "(online)"]
    assert "0.0203" not in out and "paper" not in out
