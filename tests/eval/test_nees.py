"""The NEES of a trajectory's poses against their own covariances: the metric and ``fgloc eval --nees``."""

from __future__ import annotations

import json

import numpy as np
import pytest

from fgloc.cli import main
from fgloc.eval.nees import CHI2_3DOF_95, evaluate_nees, pose_nees
from fgloc.io.tum import write_tum
from fgloc.localization.monitor import status_csv
from fgloc.types import Trajectory

from .helpers import rectangle


def _honest(n_seed: int = 0, scale: float = 1.0, rate: float = 400.0):
    """The rectangle route with errors drawn from per-pose covariances (each pose its own, correlated,
    in the map frame); the covariances scaled by ``scale`` as the estimate reports them."""
    rng = np.random.default_rng(n_seed)
    gt = rectangle(width=6.0, height=4.0, rate=rate)
    n = len(gt)
    L = np.zeros((n, 3, 3))
    L[:, 0, 0] = rng.uniform(0.005, 0.05, n)
    L[:, 1, 1] = rng.uniform(0.005, 0.05, n)
    L[:, 1, 0] = rng.uniform(-0.02, 0.02, n)
    L[:, 2, 2] = np.radians(rng.uniform(0.1, 2.0, n))
    L[:, 2, 0] = np.radians(rng.uniform(-0.5, 0.5, n))
    P = L @ np.swapaxes(L, 1, 2)
    e = np.einsum("nij,nj->ni", L, rng.standard_normal((n, 3)))
    est = Trajectory(gt.stamps, gt.poses + e, covs=P * scale)
    return est, gt


def test_honest_covariances_give_nees_three():
    est, gt = _honest()
    m = evaluate_nees(est, gt)
    assert m.n == len(gt) > 5000 and m.n_without_cov == 0
    assert m.nees_mean == pytest.approx(3.0, abs=0.12)
    assert m.nees_median == pytest.approx(2.37, abs=0.12)
    assert m.inside_95 == pytest.approx(0.95, abs=0.01)
    assert (m.nees_x, m.nees_y, m.nees_yaw) == pytest.approx((1.0, 1.0, 1.0), abs=0.06)


@pytest.mark.parametrize("scale", [0.1, 4.0])
def test_covariances_too_small_or_too_large_show(scale):
    est, gt = _honest(1, scale=scale)
    m = evaluate_nees(est, gt)
    assert m.nees_mean == pytest.approx(3.0 / scale, rel=0.05)
    assert (m.inside_95 < 0.6) if scale < 1 else (m.inside_95 > 0.999)


def test_poses_without_a_usable_covariance_are_counted_apart():
    e = np.array([[0.01, 0.0, 0.0]] * 3)
    P = np.stack([np.eye(3) * 1e-4, np.full((3, 3), np.nan), np.zeros((3, 3))])
    v = pose_nees(e, P)
    assert v[0] == pytest.approx(1.0) and np.isnan(v[1]) and np.isnan(v[2])
    est = Trajectory(np.array([0.0, 1.0, 2.0]), e, covs=P)
    m = evaluate_nees(est, Trajectory(np.array([0.0, 1.0, 2.0]), np.zeros((3, 3))))
    assert (m.n, m.n_without_cov, m.nees_mean, m.inside_95) == (1, 2, pytest.approx(1.0), 1.0)
    assert CHI2_3DOF_95 == pytest.approx(7.8147, abs=1e-4)


def _write_run(folder, est: Trajectory) -> None:
    """``trajectory.tum`` and ``trajectory_status.csv`` as ``fgloc run`` writes them."""
    assert est.covs is not None
    write_tum(folder / "trajectory.tum", est)
    rows = [[t, *p, "ok", *(c[i][j] for i, j in ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))), ""]
            for t, p, c in zip(est.stamps.tolist(), est.poses.tolist(), est.covs.tolist(), strict=True)]
    (folder / "trajectory_status.csv").write_text(status_csv(rows))


def test_eval_nees_reads_the_status_file_beside_the_trajectory(tmp_path, capsys):
    est, gt = _honest(2, scale=0.25, rate=50.0)
    _write_run(tmp_path, est)
    write_tum(tmp_path / "gt.tum", gt)
    assert main(["eval", str(tmp_path / "trajectory.tum"), str(tmp_path / "gt.tum"), "--nees", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["nees"]["n"] == len(gt)
    assert doc["nees"]["nees_mean"] == pytest.approx(12.0, rel=0.1)
    assert main(["eval", str(tmp_path / "trajectory.tum"), str(tmp_path / "gt.tum"), "--nees"]) == 0
    out = capsys.readouterr().out
    assert "NEES mean" in out and "inside the 95 % bound" in out


def test_eval_nees_without_covariances_is_a_one_line_error(tmp_path, capsys):
    est, gt = _honest(3, rate=20.0)
    write_tum(tmp_path / "est.tum", est)
    write_tum(tmp_path / "gt.tum", gt)
    assert main(["eval", str(tmp_path / "est.tum"), str(tmp_path / "gt.tum"), "--nees"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "no per-pose covariance" in err and "trajectory_status.csv" in err
    (tmp_path / "bad.csv").write_text("t,x,y\n1,2,3\n")
    assert main(["eval", str(tmp_path / "est.tum"), str(tmp_path / "gt.tum"), "--nees", "--cov",
                 str(tmp_path / "bad.csv")]) == 2
    assert "not a pose status file" in capsys.readouterr().err
