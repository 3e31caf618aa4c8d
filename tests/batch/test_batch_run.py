"""``fgloc batch run`` on the local process pool and on Ray: same files as single runs, errors isolated,
resumption, Ctrl-C."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from fgloc.batch import MARKER, read_summary_csv

from .helpers import CORRUPT, ROUTES, START, assert_identical, crash_or_count, fgloc_cli, single_run_here


def check_summary(outdir: Path, batch_logs, references, ok_status=("ok",)) -> dict[str, dict[str, str]]:
    """summary.csv: one row per log in name order; numbers equal to the single runs'; the corrupt
    log's one-line error equal to what ``fgloc run`` says."""
    from fgloc.eval.metrics import evaluate
    from fgloc.io import open_log
    from fgloc.io.tum import read_tum

    rows = {r["log"]: r for r in read_summary_csv(outdir / "summary.csv")}
    assert list(rows) == sorted(batch_logs["names"])
    for name in ROUTES:
        r = rows[name]
        assert r["status"] in ok_status, r
        tr = read_tum(references["dir"] / name / "trajectory.tum")
        assert int(r["poses"]) == len(tr)
        # the log's span (a run lost over part of it has poses over less): here the poses cover it but for
        # the start-up before the first keyframe
        span = float(open_log(batch_logs["logs"] / f"{name}.mcap").summary()["duration"])
        assert float(r["duration_s"]) == pytest.approx(max(span, tr.duration), abs=1e-3)
        assert tr.duration > span - 0.5
        m = evaluate(tr, batch_logs["gt"][name])
        assert float(r["rmse_m"]) == pytest.approx(m.position_rmse_m, abs=1e-6)
        assert float(r["rmse_m"]) < 0.02
        assert float(r["lost_time_s"]) == 0.0  # tracked from the given start: never without fixes
        assert r["error"] == ""
    bad = rows[CORRUPT]
    assert bad["status"] == "error" and bad["poses"] == ""
    assert bad["error"] == references["errors"][CORRUPT]
    assert "\n" not in bad["error"] and f"{CORRUPT}.mcap" in bad["error"]
    return rows


def test_local_pool_matches_single_runs_and_resumes(batch_logs, references):
    out = batch_logs["root"] / "out-local"
    args = ("batch", "run", batch_logs["logs"], "--map", batch_logs["map"], "--initial-pose", *map(str, START),
            "-o", out, "-j", "2", "-q")
    rc, stdout, _ = fgloc_cli(*args)
    assert rc == 1  # one log failed
    assert set(references["errors"]) == {CORRUPT}
    assert_identical(out, references, ROUTES)
    check_summary(out, batch_logs, references)
    assert "3/4 done" in stdout and "1 failed" in stdout
    assert not (out / CORRUPT / MARKER).exists()
    # again: the three finished logs are skipped (outputs untouched), the failed one is retried
    stamps = {n: (out / n / "trajectory.tum").stat().st_mtime_ns for n in ROUTES}
    rc, stdout, _ = fgloc_cli(*args)
    assert rc == 1 and "1 ran, 3 already done" in stdout
    rows = check_summary(out, batch_logs, references, ok_status=("done",))
    assert all(rows[n]["status"] == "done" for n in ROUTES)
    assert stamps == {n: (out / n / "trajectory.tum").stat().st_mtime_ns for n in ROUTES}


def _ray_gone() -> bool:
    """No Ray connection in this process and no thread holding one."""
    import threading

    import ray

    return not ray.is_initialized() and not [t for t in threading.enumerate() if t.name == "fgloc-ray-start"]


def test_ray_local_instance_matches_single_runs(batch_logs, references, tmp_path):
    """``--engine ray -j 2``: the private local instance (2 CPUs, workers at this process's niceness, not
    Ray's default of 15 more: the suite may itself run under ``nice``), started in the
    background while the jobs are prepared and stopped at the end (also when preparing fails), the
    same files as single runs; on that instance a worker killed mid-job fails only its own job."""
    pytest.importorskip("ray")
    from fgloc.batch import Job, RayEngine

    rc, _, err = fgloc_cli("batch", "run", batch_logs["logs"] / "nothing-*.mcap", "-o", tmp_path / "none",
                           "--engine", "ray", "-j", "2")
    assert rc == 2 and "pattern matches no file" in err
    assert _ray_gone()  # the instance started for the batch was stopped again
    out = batch_logs["root"] / "out-ray"
    rc, stdout, _ = fgloc_cli("batch", "run", batch_logs["logs"], "--map", batch_logs["map"], "--initial-pose",
                              *map(str, START), "-o", out, "--engine", "ray", "-j", "2", "-q")
    assert rc == 1
    assert "local Ray instance, 2 CPU(s)" in stdout
    assert _ray_gone()
    assert_identical(out, references, ROUTES)
    rows = check_summary(out, batch_logs, references)
    # the jobs ran in Ray worker processes (one per CPU, reused), not in this one
    assert all(r["host"] and not r["host"].endswith(f":{os.getpid()}") for r in rows.values())
    assert len({r["host"] for r in rows.values() if r["host"]}) <= 2
    engine = RayEngine(2)
    engine.connect()  # connected by hand: kept after a run, until shutdown()
    try:
        assert engine.ray.cluster_resources()["CPU"] == 2
        data = tmp_path / "in.bin"
        data.write_bytes(b"x" * 4321)
        jobs = [Job("run", n, str(tmp_path / n), {"log": str(data)}) for n in ("a", "boom", "b")]
        # the Ray workers cannot import this test package: they get the function by value
        engine.ray.cloudpickle.register_pickle_by_value(sys.modules[crash_or_count.__module__])
        got = dict(engine.run(crash_or_count, jobs, ship=True))
        assert not got[1].ok and "died" in (got[1].error or "")
        assert [got[i].row for i in (0, 2)] == [{"poses": 4321, "nice": os.nice(0)}] * 2
    finally:
        engine.shutdown()


def test_ctrl_c_keeps_finished_logs(batch_logs, references, tmp_path):
    """SIGINT to the process group (what Ctrl-C sends): exit 130, finished logs kept with their
    markers, the summary lists the rest as not run, the workers are gone; running again finishes."""
    import psutil

    out = tmp_path / "out"
    args = ["batch", "run", str(batch_logs["logs"]), "--map", str(batch_logs["map"]), "--initial-pose",
            *map(str, START), "-o", str(out), "-q"]
    exe = Path(sys.executable).parent / "fgloc"
    # SIGINT at its default in the child even when this test runs with it ignored (a background job
    # of a non-interactive shell): a Python started with SIGINT ignored never raises KeyboardInterrupt
    p = subprocess.Popen([str(exe), *args, "-j", "1"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         start_new_session=True, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        deadline = time.monotonic() + 120
        while not list(out.glob(f"*/{MARKER}")) and p.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        workers = [c for c in psutil.Process(p.pid).children(recursive=True)
                   if "spawn_main" in " ".join(c.cmdline())]
        os.killpg(p.pid, signal.SIGINT)
        stdout, stderr = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
    assert p.returncode == 130, stderr
    assert "interrupted" in stdout
    rows = {r["log"]: r for r in read_summary_csv(out / "summary.csv")}
    finished = [n for n, r in rows.items() if r["status"] == "ok"]
    assert 1 <= len(finished) < 4
    assert {r["status"] for n, r in rows.items() if n not in finished} <= {"not run", "error"}
    assert "not run" in {r["status"] for r in rows.values()}
    assert all((out / n / MARKER).exists() for n in finished)
    assert workers  # the pool's worker process(es) were running ...
    _, alive = psutil.wait_procs(workers, timeout=10)
    assert not alive  # ... and are gone with the driver
    rc, stdout, _ = fgloc_cli(*args)
    assert rc == 1 and f"{len(finished)} already done" in stdout
    assert_identical(out, references, ROUTES)


def test_manifest_rows_give_their_own_map_and_start(batch_logs, tmp_path):
    """A manifest with relative paths, one row without a pose (the --initial-pose default), run
    in-process on the inline engine: the same files as the single runs."""
    from fgloc.batch import EngineOptions, batch_run

    man = batch_logs["root"] / "fleet.csv"
    man.write_text("log,map,x,y,yaw\n"
                   f"logs/alpha.mcap,map.yaml,{START[0]},{START[1]},{START[2]}\n"
                   "logs/charlie.mcap,,,,\n")
    rep = batch_run([], tmp_path / "out", EngineOptions("inline", progress=False), manifest=man,
                    map_yaml=batch_logs["map"], initial_pose=list(START))
    assert [r.log for r in rep.rows] == ["alpha", "charlie"] and rep.ok
    for name in ("alpha", "charlie"):
        single_run_here(batch_logs["logs"] / f"{name}.mcap", batch_logs["map"], tmp_path / "ref" / name)
    assert_identical(tmp_path / "out", tmp_path / "ref", ["alpha", "charlie"])
