"""Errors over the poses a run vouches for: ``split_by_status``, ``fgloc eval`` with a status file and
``fgloc run``'s summary lines (a run that was lost before a global localization converged)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from fgloc.cli import main
from fgloc.eval.metrics import associate, association_metrics, split_by_status
from fgloc.io.tum import write_tum
from fgloc.localization.monitor import status_csv
from fgloc.types import Trajectory

from .helpers import rectangle

N_LOST = 90


def _lost_start(offset_m: float = 10.0):
    """The rectangle route 1 cm off, its first :data:`N_LOST` poses ``offset_m`` off and called lost (a
    global search's poses before it converged), 20 degraded ones among the rest."""
    gt = rectangle(width=6.0, height=4.0, rate=20.0)
    poses = gt.poses.copy()
    poses[:, 1] += 0.01
    poses[:N_LOST, 0] += offset_m
    statuses = ["lost"] * N_LOST + ["ok"] * (len(gt) - N_LOST)
    statuses[200:220] = ["degraded"] * 20
    return Trajectory(gt.stamps, poses), gt, statuses


def test_the_vouched_poses_make_the_metrics_and_the_others_are_counted_with_their_error():
    est, gt, statuses = _lost_start()
    a = associate(est, gt)
    sp = split_by_status(a, statuses)
    assert sp.metrics is not None and sp.metrics.n == len(gt) - N_LOST and sp.metrics.n_unassociated == 0
    assert sp.metrics.position_rmse_m == pytest.approx(0.01, abs=1e-9)
    assert sp.left_out == {"lost": N_LOST} and sp.n_left_out == N_LOST
    assert sp.left_out_rmse_m == pytest.approx(np.hypot(10.0, 0.01), abs=1e-6)
    assert sp.left_out_max_m == pytest.approx(np.hypot(10.0, 0.01), abs=1e-6)
    every = association_metrics(a).position_rmse_m
    assert every > 2.0 and sp.all_rmse_m == pytest.approx(every)


def test_alignment_is_fitted_to_the_vouched_poses():
    est, gt, statuses = _lost_start(offset_m=30.0)
    sp = split_by_status(associate(est, gt), statuses, align=True)
    assert sp.metrics is not None and sp.metrics.aligned
    assert sp.metrics.position_rmse_m < 1e-6  # the 1 cm shift is the alignment's; the lost poses do not pull it
    assert association_metrics(associate(est, gt), align=True).position_rmse_m > 1.0


def test_fewer_than_two_vouched_poses_give_no_metrics():
    est, gt, _ = _lost_start()
    sp = split_by_status(associate(est, gt), ["lost"] * len(gt))
    assert sp.metrics is None and sp.left_out == {"lost": len(gt)}


def _run_folder(folder: Path, sigma: float | None = None) -> tuple[Path, Path]:
    """trajectory.tum, its trajectory_status.csv (covariances ``sigma``^2 on x, y and yaw, or none) and gt.tum."""
    est, gt, statuses = _lost_start()
    write_tum(folder / "trajectory.tum", est)
    write_tum(folder / "gt.tum", gt)
    v = float("nan") if sigma is None else sigma**2
    z = float("nan") if sigma is None else 0.0
    rows = [[float(t), *map(float, p), s, v, z, z, v, z, v, "" if s == "ok" else "why"]
            for t, p, s in zip(est.stamps, est.poses, statuses, strict=True)]
    (folder / "trajectory_status.csv").write_text(status_csv(rows))
    return folder / "trajectory.tum", folder / "gt.tum"


def test_eval_takes_the_status_file_beside_the_trajectory(tmp_path, capsys):
    est, gt = _run_folder(tmp_path)
    assert main(["eval", str(est), str(gt), "--json"]) == 0
    cap = capsys.readouterr()
    doc = json.loads(cap.out)
    assert doc["metrics"]["position_rmse_m"] == pytest.approx(0.01, abs=1e-9)
    assert doc["by_status"]["left_out"] == {"lost": N_LOST}
    assert doc["by_status"]["left_out_max_m"] == pytest.approx(10.0, abs=1e-3)
    assert f"left out {N_LOST} lost pose(s)" in cap.err
    assert main(["eval", str(est), str(gt), "--json", "--all-poses"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["metrics"]["position_rmse_m"] > 2.0 and "by_status" not in doc


def test_eval_nees_is_over_the_poses_the_table_is_over(tmp_path, capsys):
    est, gt = _run_folder(tmp_path, sigma=0.01)
    assert main(["eval", str(est), str(gt), "--json", "--nees"]) == 0
    nees = json.loads(capsys.readouterr().out)["nees"]
    n = len(_lost_start()[1])
    assert nees["n"] == n - N_LOST
    assert nees["nees_mean"] == pytest.approx(1.0, rel=1e-6)  # 1 cm off with a 1 cm sigma; the lost 1e6 left out
    assert main(["eval", str(est), str(gt), "--json", "--nees", "--all-poses"]) == 0
    nees = json.loads(capsys.readouterr().out)["nees"]
    assert nees["n"] == n and nees["nees_mean"] > 1e4


def test_eval_align_start_aligns_on_the_first_vouched_pose(tmp_path, capsys):
    est, gt = _run_folder(tmp_path)
    assert main(["eval", str(est), str(gt), "--json", "--align-start"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["end_error_m"] < 1e-6  # the 1 cm offset is the first ok pose's: aligned away
    assert doc["metrics"]["position_rmse_m"] < 1e-6
    assert main(["eval", str(est), str(gt), "--json", "--align-start", "--all-poses"]) == 0
    assert json.loads(capsys.readouterr().out)["end_error_m"] == pytest.approx(10.0, abs=0.01)  # on a lost pose


def test_eval_refuses_the_status_file_of_another_trajectory(tmp_path, capsys):
    est, gt = _run_folder(tmp_path)
    other = Trajectory(np.arange(50) * 0.013 + 0.005, np.zeros((50, 3)))
    write_tum(tmp_path / "online.tum", other)
    assert main(["eval", str(tmp_path / "online.tum"), str(gt), "--json"]) == 0  # beside it, not its: unused
    assert "by_status" not in json.loads(capsys.readouterr().out)
    assert main(["eval", str(tmp_path / "online.tum"), str(gt), "--status",
                 str(tmp_path / "trajectory_status.csv")]) == 2
    assert "not the status file of" in capsys.readouterr().err


def test_run_summary_prints_the_vouched_poses_and_says_what_it_left_out():
    from fgloc.app.run import RunResult
    from fgloc.commands.run import truth_lines
    from fgloc.localization.stats import RunStats

    est, gt, statuses = _lost_start()
    a = associate(est, gt)
    n = len(gt)
    r = RunResult("map", "map", "smoother", "amcl", n, n, n, RunStats(), 1.0, 10.0, Path("."), [],
                  metrics=association_metrics(a), by_status=split_by_status(a, statuses))
    text = "\n".join(truth_lines(r))
    assert f"over the poses the run vouches for (ok or degraded: {n - N_LOST} of {n} final)" in text
    rmse = next(ln for ln in text.splitlines() if "position RMSE" in ln)
    assert rmse.split()[-1] == "0.0100"
    assert f"left out of smoother (final): {N_LOST} lost pose(s), 10.0000 m RMSE" in text
    r.by_status = split_by_status(a, ["ok"] * n)  # nothing left out: the table as it always was
    text = "\n".join(truth_lines(r))
    assert "  vs /ground_truth:" in text and "left out" not in text
    r.by_status = split_by_status(a, ["lost"] * n)  # every pose lost (a map that does not fit): every pose, said
    text = "\n".join(truth_lines(r))
    said = f"over every pose (the run vouches for fewer than 2; ok or degraded: smoother (final): 0 of {n} ({n} lost))"
    assert said in text
    assert "left out" not in text  # the table has them all
    rmse = next(ln for ln in text.splitlines() if "position RMSE" in ln)
    assert float(rmse.split()[-1]) > 2.0


def test_eval_of_a_run_mcap_takes_the_status_published_with_each_pose(tmp_path, capsys):
    from fgloc.eval.trajectories import RUN_STATUS_TOPIC
    from fgloc.io.mcap_writer import LogWriter
    from fgloc.types import PoseFix

    est, gt, statuses = _lost_start()
    write_tum(tmp_path / "gt.tum", gt)
    with LogWriter(tmp_path / "run.mcap") as w:
        for t, p, s in zip(est.stamps, est.poses, statuses, strict=True):
            ns = int(round(float(t) * 1e9))
            w.write("/fused_pose", PoseFix(float(t), p, np.eye(3) * 1e-4), log_time_ns=ns)
            w.write_raw(RUN_STATUS_TOPIC, "fgloc.PoseStatus", b"{}", json.dumps(
                {"stamp": float(t), "status": s, "why": "", "frame_id": "map"}).encode(), ns,
                schema_encoding="jsonschema", message_encoding="json")
    assert main(["eval", str(tmp_path / "run.mcap"), str(tmp_path / "gt.tum"), "--json"]) == 0
    cap = capsys.readouterr()
    doc = json.loads(cap.out)
    assert doc["metrics"]["position_rmse_m"] == pytest.approx(0.01, abs=1e-6)
    assert doc["by_status"]["left_out"] == {"lost": N_LOST}
    assert RUN_STATUS_TOPIC in cap.err
