"""Engines, inputs and summary pieces of ``fgloc batch``: crash isolation, shipping, names, manifests."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from fgloc.batch import EngineOptions, InlineEngine, Job, LocalEngine, batch_run, read_summary_csv, run_batch
from fgloc.batch.inputs import discover_logs, read_manifest, unique_names
from fgloc.batch.runner import read_marker
from fgloc.errors import ConfigError

from .helpers import CORRUPT, OUTPUTS, ROUTES, START, crash_or_count, fgloc_cli, single_run_here


def test_a_crashed_worker_fails_only_its_own_job(tmp_path):
    """A worker killed by SIGKILL mid-job: that job is reported, the pool replaces the worker and
    every other job (also those queued behind it) finishes; shipped bytes arrive whole."""
    data = tmp_path / "in.bin"
    data.write_bytes(b"x" * 12345)
    jobs = [Job("run", n, str(tmp_path / n), {"log": str(data)}) for n in ("a", "boom", "b", "c", "d")]
    got = dict(LocalEngine(2).run(crash_or_count, jobs, ship=True))
    assert sorted(got) == [0, 1, 2, 3, 4]
    assert not got[1].ok and "SIGKILL" in (got[1].error or "")
    assert all(got[i].ok and got[i].row["poses"] == 12345 for i in (0, 2, 3, 4))


def test_force_reruns_and_a_lost_output_file_invalidates_the_marker(batch_logs, tmp_path):
    from fgloc.batch.inputs import run_jobs

    jobs = run_jobs([batch_logs["logs"] / "charlie.mcap"], tmp_path, batch_logs["map"], list(START))
    rep = run_batch(jobs, tmp_path, InlineEngine(), progress=False)
    assert rep.ran == 1 and rep.ok and read_marker(jobs[0]) is not None
    assert run_batch(jobs, tmp_path, InlineEngine(), progress=False).skipped == 1
    assert run_batch(jobs, tmp_path, InlineEngine(), force=True, progress=False).ran == 1
    (tmp_path / "charlie" / "fixes.tum").unlink()
    assert read_marker(jobs[0]) is None  # incomplete outputs: not done
    other = run_jobs([batch_logs["logs"] / "charlie.mcap"], tmp_path, batch_logs["map"], [2.5, 3.0, 0.1])
    assert other[0].fingerprint() != jobs[0].fingerprint()  # other options: run again


def test_shipped_inputs_give_the_same_outputs(batch_logs, tmp_path):
    """--ship-inputs with a map whose YAML names its image by absolute path in another folder: the
    worker runs on temporary copies, the outputs equal the single run's and name the original paths."""
    maps = tmp_path / "maps"
    maps.mkdir()
    text = batch_logs["map"].read_text()
    img = batch_logs["map"].with_suffix(".pgm").resolve()
    yaml_path = maps / "hall.yaml"
    yaml_path.write_text("\n".join(f"image: {img}" if line.startswith("image:") else line
                                   for line in text.splitlines()) + "\n")
    rep = batch_run([str(batch_logs["logs"] / "alpha.mcap")], tmp_path / "out",
                    EngineOptions("inline", ship=True, progress=False), map_yaml=yaml_path, initial_pose=list(START))
    assert rep.ok
    ref = single_run_here(batch_logs["logs"] / "alpha.mcap", batch_logs["map"], tmp_path / "ref")
    for f in OUTPUTS[:-1]:
        assert (tmp_path / "out" / "alpha" / f).read_bytes() == (ref / f).read_bytes()
    cfg = (tmp_path / "out" / "alpha" / "config.yaml").read_text()
    assert str(yaml_path.resolve()) in cfg and str((batch_logs["logs"] / "alpha.mcap").resolve()) in cfg
    assert "fgloc-batch-" not in cfg


def test_log_discovery_and_names(tmp_path):
    for p in ("day1/run.mcap", "day2/run.mcap", "day2/other.mcap", "notes.txt", "out/x/run.mcap"):
        (tmp_path / p).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / p).write_bytes(b"")
    found = discover_logs([str(tmp_path)], exclude=tmp_path / "out")
    assert [p.relative_to(tmp_path).as_posix() for p in found] == ["day1/run.mcap", "day2/other.mcap",
                                                                   "day2/run.mcap"]
    assert unique_names(found) == ["day1_run", "other", "day2_run"]
    assert discover_logs([str(tmp_path / "day*" / "run.mcap"), str(tmp_path / "day1/run.mcap")]) == \
        [(tmp_path / "day1/run.mcap").resolve(), (tmp_path / "day2/run.mcap").resolve()]
    assert unique_names([Path("/a/intel.clf.bz2"), Path("/b/fr079.clf")]) == ["intel", "fr079"]
    with pytest.raises(ConfigError, match="matches no file"):
        discover_logs([str(tmp_path / "nope*.mcap")])
    with pytest.raises(ConfigError, match="not found"):
        discover_logs([str(tmp_path / "missing.mcap")])


def test_manifest(tmp_path):
    m = tmp_path / "m.csv"
    m.write_text("log,map,x,y,yaw\nlogs/a.mcap,maps/a.yaml,1,2,0.5\n/abs/b.mcap,,,,\n\n")
    rows = read_manifest(m)
    assert rows[0] == {"log": (tmp_path / "logs/a.mcap").resolve(), "map": (tmp_path / "maps/a.yaml").resolve(),
                       "pose": [1.0, 2.0, 0.5]}
    assert rows[1] == {"log": Path("/abs/b.mcap"), "map": None, "pose": None}
    for body, msg in (("log,x,y\na,1,2\n", "header"), ("log,map,x,y,yaw\na,,1,,\n", ":2: give all"),
                      ("log,map,x,y,yaw\na,,1,two,3\n", ":2: x, y, yaw must be numbers"),
                      ("log,map,x,y,yaw\n", "no rows")):
        m.write_text(body)
        with pytest.raises(ConfigError, match=msg):
            read_manifest(m)


def test_a_lost_run_is_reported_as_fgloc_run_exits_3(batch_logs, tmp_path):
    """A 2 m x 2 m map without walls, away from the robot: no scan matches, ``fgloc run`` exits 3
    (lost); the batch writes the outputs, reports the log as lost with the same line and fails,
    unless --allow-lost.  (Small, so that the global searches of a lost localizer stay cheap.)"""
    import numpy as np
    from PIL import Image

    Image.fromarray(np.full((40, 40), 254, dtype=np.uint8)).save(tmp_path / "empty.pgm")
    empty = tmp_path / "empty.yaml"
    empty.write_text(batch_logs["map"].read_text().replace("map.pgm", "empty.pgm"))
    log = batch_logs["logs"] / "charlie.mcap"
    rc, _, err = fgloc_cli("run", log.resolve(), "--map", empty, "--initial-pose", *map(str, START),
                           "-o", tmp_path / "single", "-q")
    assert rc == 3
    line = err.strip().splitlines()[-1].removeprefix("fgloc: lost: ")
    args = ("batch", "run", log, "--map", empty, "--initial-pose", *map(str, START), "-o", tmp_path / "out",
            "--engine", "inline", "-q")
    rc, stdout, _ = fgloc_cli(*args)
    assert rc == 1 and "1 failed" in stdout
    row = read_summary_csv(tmp_path / "out" / "summary.csv")[0]
    assert row["status"] == "lost" and row["error"] == line
    assert float(row["lost_time_s"]) > 0.9 * float(row["duration_s"])
    assert (tmp_path / "out" / "charlie" / "trajectory.tum").exists()
    rc, stdout, _ = fgloc_cli(*args)  # finished (its outputs are complete): not run again, still lost
    assert rc == 1 and "0 ran, 1 already done" in stdout
    rc, stdout, _ = fgloc_cli(*args, "--allow-lost")  # judged again, not run again: accepted
    row = read_summary_csv(tmp_path / "out" / "summary.csv")[0]
    assert rc == 0 and "0 ran, 1 already done" in stdout
    assert row["status"] == "done" and row["error"] == line


def test_without_ray_a_one_line_hint(batch_logs, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # as if Ray were not installed
    rc, _, err = fgloc_cli("batch", "run", batch_logs["logs"] / "alpha.mcap", "-o", tmp_path, "--engine", "ray")
    assert rc == 2
    assert err.strip() == 'fgloc: error: the ray engine needs Ray: pip install "fgloc[cluster]"'


def test_usage_errors_are_one_line(batch_logs, tmp_path):
    rc, _, err = fgloc_cli("batch", "run", "-o", tmp_path)
    assert rc == 2 and "give LOGS" in err
    rc, _, err = fgloc_cli("batch", "run", batch_logs["logs"], "-o", tmp_path, "--engine", "spark")
    assert rc == 2 and "unknown engine 'spark'" in err
    rc, _, err = fgloc_cli("batch", "run", batch_logs["logs"], "-o", tmp_path, "--address", "1.2.3.4:1")
    assert rc == 2 and "--address is for --engine ray" in err
    assert {CORRUPT, *ROUTES} == set(batch_logs["names"])


def test_batch_map_writes_what_fgloc_map_writes(batch_logs, tmp_path):
    """``fgloc batch map`` (in-process engine, by path) vs ``fgloc map`` on the same log: the map and
    trajectories are the same bytes, every file ``fgloc map`` wrote is there, the row has the
    scans and an SE(2)-aligned RMSE against /ground_truth."""
    from fgloc.batch import batch_map

    log = batch_logs["logs"] / "charlie.mcap"
    rc, _, err = fgloc_cli("map", log.resolve(), "-o", tmp_path / "single", "--no-progress")
    assert rc == 0, err
    rep = batch_map([str(log)], tmp_path / "out", EngineOptions("inline", progress=False))
    assert rep.ok and rep.rows[0].log == "charlie"
    single = {p.name for p in (tmp_path / "single").iterdir()}
    assert single <= {p.name for p in (tmp_path / "out" / "charlie").iterdir()}
    for f in ("map.yaml", "map.pgm", "trajectory.tum"):
        assert (tmp_path / "out" / "charlie" / f).read_bytes() == (tmp_path / "single" / f).read_bytes()
    row = rep.rows[0]
    assert row.poses is not None and row.poses > 100 and row.rmse_m is not None and row.rmse_m < 0.05
    assert not [p for p in (tmp_path / "out").iterdir() if p.name.startswith(".fgloc-staging")]  # no staging left


def test_ray_errors_become_one_line():
    """Ray's multi-line, coloured task errors: the innermost 'Type: message' (a node without fgloc
    gets a hint), a dead worker as such."""
    from fgloc.batch.engines import ray_error_line

    class RayTaskError(Exception):
        pass

    class WorkerCrashedError(Exception):
        pass

    text = ("\x1b[36mray::_ray_task()\x1b[39m (pid=31285, ip=192.0.2.2)\n  At least one of the input arguments for "
            "this task could not be computed:\nray.exceptions.RaySystemError: System error: No module named 'fgloc'\n"
            "traceback: Traceback (most recent call last):\n          ^^^^^^^^\nModuleNotFoundError: No module named "
            "'fgloc'")
    assert ray_error_line(RayTaskError(text)) == ("ModuleNotFoundError: No module named 'fgloc' (on the Ray worker: "
                                                  "is fgloc installed on every node?)")
    assert ray_error_line(RayTaskError("\x1b[36mray::_ray_task()\x1b[39m (pid=1)\n  File x\nValueError: bad")) == \
        "ValueError: bad"
    assert ray_error_line(WorkerCrashedError("The worker died unexpectedly while executing this task.")) == \
        "Ray worker died while running this log (WorkerCrashedError)"
    assert ray_error_line(RayTaskError("")) == "RayTaskError"
