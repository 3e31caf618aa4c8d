"""The relations metric (Kuemmerle et al. 2009): file round trip, known offsets, references."""

from __future__ import annotations

import numpy as np
import pytest

from fgloc.errors import LogError
from fgloc.eval.relations import (
    Relation,
    evaluate_relations,
    read_relations,
    relations_from_reference,
    write_relations,
)
from fgloc.geometry import compose
from fgloc.types import Trajectory


def _loop_traj(n=600, dt=0.1):
    """Two laps of a 4 m x 3 m rounded rectangle at 0.5 m/s (t = 0 .. 60 s)."""
    t = np.arange(n) * dt
    s = 0.5 * t
    per = 2 * (4 + 3)
    u = s % per
    x = np.where(u < 4, u, np.where(u < 7, 4, np.where(u < 11, 4 - (u - 7), 0)))
    y = np.where(u < 4, 0, np.where(u < 7, u - 4, np.where(u < 11, 3, 3 - (u - 11))))
    yaw = np.unwrap(np.arctan2(np.gradient(y), np.gradient(x)))
    return Trajectory(t, np.column_stack([x, y, yaw]))


def test_round_trip(tmp_path):
    rels = [Relation(1.5, 2.75, np.array([0.5, -0.25, 0.1])), Relation(3.0, 40.0, np.array([-1.0, 2.0, -3.0]))]
    p = tmp_path / "r.txt"
    write_relations(p, rels)
    back = read_relations(p)
    assert len(back) == 2
    for a, b in zip(rels, back, strict=True):
        assert a.t1 == pytest.approx(b.t1) and a.t2 == pytest.approx(b.t2)
        assert np.allclose(a.delta, b.delta)
    # the Freiburg format: "t1 t2 x y z roll pitch yaw"
    assert p.read_text().splitlines()[1].split()[4:7] == ["0", "0", "0"]


def test_read_errors_name_file_and_line(tmp_path):
    p = tmp_path / "bad.txt"
    p.write_text("# c\n1 2 3 4 0 0 0 0.1\n1 2 3\n")
    with pytest.raises(LogError, match=r"bad.txt:3"):
        read_relations(p)
    with pytest.raises(LogError, match="not found"):
        read_relations(tmp_path / "missing.txt")


def test_identical_and_globally_moved_trajectories_score_zero():
    ref = _loop_traj()
    rels = relations_from_reference(ref)
    moved = Trajectory(ref.stamps, compose(np.array([10.0, -3.0, 1.2]), ref.poses))
    for tr in (ref, moved):
        ev = evaluate_relations(tr, rels)
        assert ev["n"] == len(rels) and ev["unmatched"] == 0
        assert ev["trans_mean"] < 1e-9 and ev["rot_mean_deg"] < 1e-9


def test_known_offset_gives_known_error():
    ref = _loop_traj()
    rels = [Relation(10.0, 11.5, np.zeros(3))]
    # a trajectory where pose(11.5) is 0.1 m ahead and 2 deg turned relative to pose(10.0)
    p1 = np.array([1.0, 1.0, 0.5])
    est = Trajectory(np.array([10.0, 11.5]), np.array([p1, compose(p1, [0.1, 0.0, np.radians(2)])]))
    ev = evaluate_relations(est, rels)
    assert ev["n"] == 1
    assert ev["trans_mean"] == pytest.approx(0.1, abs=1e-9)
    assert ev["rot_mean_deg"] == pytest.approx(2.0, abs=1e-9)
    # a constant 5 cm shift of one pose among many: each relation touching it errs by 5 cm
    poses = ref.poses.copy()
    poses[300] = compose(poses[300], [0.05, 0.0, 0.0])
    ev = evaluate_relations(Trajectory(ref.stamps, poses), relations_from_reference(ref, loop_closures=False))
    rels2 = relations_from_reference(ref, loop_closures=False)
    touching = sum(1 for r in rels2 if abs(r.t1 - ref.stamps[300]) < 1e-9 or abs(r.t2 - ref.stamps[300]) < 1e-9)
    assert touching == 2
    assert ev["trans_mean"] * ev["n"] == pytest.approx(2 * 0.05, abs=1e-9)


def test_reference_relations_spacing_and_loop_closures():
    ref = _loop_traj()
    rels = relations_from_reference(ref, 1.0, 2.0)
    local = [r for r in rels if r.t2 - r.t1 <= 2.0]
    loops = [r for r in rels if r.t2 - r.t1 > 2.0]
    assert all(1.0 - 1e-9 <= r.t2 - r.t1 <= 2.0 for r in local)
    assert len(local) > 500
    # the second lap passes the first lap's poses 28 s later: loop-closure relations
    assert len(loops) > 10
    assert all(r.t2 - r.t1 >= 30.0 - 1e-6 and np.hypot(*r.delta[:2]) <= 1.0 + 1e-9 for r in loops)
    assert not relations_from_reference(ref, loop_closures=False) == rels


def test_association_window_counts_unmatched():
    ref = _loop_traj()
    rels = relations_from_reference(ref, loop_closures=False)
    sparse = Trajectory(ref.stamps[5::10], ref.poses[5::10])  # 1 Hz, at 0.5 s, 1.5 s, ...
    ev = evaluate_relations(sparse, rels, max_assoc_dt=0.05)
    assert ev["unmatched"] + ev["n"] == len(rels)
    assert ev["unmatched"] > 0.85 * len(rels)  # only relations between x.5 s stamps match
    assert evaluate_relations(sparse, rels, max_assoc_dt=0.5)["unmatched"] == 0
