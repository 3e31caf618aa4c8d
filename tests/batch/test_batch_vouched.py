"""``fgloc batch``'s RMSE is over the poses the run vouches for, as ``fgloc run``'s table: a run without a
start pose is not charged for the poses it called lost before its global localization converged."""

from __future__ import annotations

import numpy as np

from fgloc.batch import adapter
from fgloc.eval.metrics import associate, association_metrics
from fgloc.eval.trajectories import STATUS_FILE, read_statuses, statuses_at
from fgloc.io.tum import read_tum


def test_a_run_without_a_start_pose_is_judged_on_its_vouched_poses(tmp_path):
    from fgloc.sim import simulate_paper, write_sim

    sim = simulate_paper(seed=1, route=[[2.5, 3.0], [8.5, 3.0]])
    d = write_sim(sim, tmp_path / "sim")
    out = tmp_path / "out"
    r = adapter.localize_log(d / "log.mcap", out, d / "map.yaml", None, None, "ekf", "amcl", None, None, None)
    tr = read_tum(out / "trajectory.tum")
    statuses = np.asarray(statuses_at(tr, *read_statuses(out / STATUS_FILE)), dtype=object)
    n_lost = int(np.count_nonzero(statuses == "lost"))
    assert n_lost > 20  # the global search's poses before it converged
    every = association_metrics(associate(tr, sim.ground_truth)).position_rmse_m
    assert every > 1.0
    assert r.position_rmse_m is not None and r.position_rmse_m < 0.05
    said = [w for w in r.warnings if w.startswith("RMSE over the")]
    assert len(said) == 1 and f"left out {n_lost} lost pose(s)" in said[0] and f"{every:.4f} m RMSE" in said[0]
