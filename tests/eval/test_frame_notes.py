"""An estimate in another frame than its reference (a simulator's world frame against the map's, as
Stage's /base_pose_ground_truth; a map scaled against the world, as Stage's bitmap fitted to a size)
reads as metres of error; ``fgloc eval`` notes the offset or the scale the errors are made of."""

from __future__ import annotations

import contextlib
import io
import math

import numpy as np
import pytest

from fgloc.eval.checks import frame_note as _frame_note
from fgloc.eval.metrics import associate
from fgloc.types import Trajectory


def frame_note(label: str, est: Trajectory, ref: Trajectory, max_gap: float) -> str | None:
    return _frame_note(label, associate(est, ref, max_gap=max_gap))


def _loop(n: int = 400) -> tuple[np.ndarray, np.ndarray]:
    """A 10 m x 6 m loop around the origin, 40 s."""
    t = np.linspace(0.0, 40.0, n)
    a = 2 * math.pi * t / 40.0
    xy = np.c_[5.0 * np.cos(a), 3.0 * np.sin(a)]
    return t, xy


def _traj(t, xy) -> Trajectory:
    yaw = np.arctan2(np.gradient(xy[:, 1]), np.gradient(xy[:, 0]))
    return Trajectory(t, np.c_[xy, yaw])


def test_an_offset_is_noted_and_align_removes_it(tmp_path):
    t, xy = _loop()
    ref, est = _traj(t, xy), _traj(t, xy + [15.05, 15.05] + 0.03 * np.sin(t)[:, None])
    note = frame_note("est", est, ref, 0.5)
    assert note is not None and note.startswith("the errors of est are mostly one offset (+15.05, +15.05) m")
    assert note.endswith("--align fits one rigid transform")
    for name, tr in (("est.tum", est), ("ref.tum", ref)):
        with open(tmp_path / name, "w") as f:
            for s, (x, y, yaw) in zip(tr.stamps, tr.poses, strict=True):
                f.write(f"{s:.6f} {x:.6f} {y:.6f} 0 0 0 {math.sin(yaw / 2):.9f} {math.cos(yaw / 2):.9f}\n")
    from fgloc.cli import main

    for extra, noted in (([], True), (["--align"], False)):
        err = io.StringIO()
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
            assert main(["eval", str(tmp_path / "est.tum"), str(tmp_path / "ref.tum"), *extra]) == 0
        assert ("mostly one offset" in err.getvalue()) is noted, err.getvalue()


def test_a_scaled_map_is_noted():
    t, xy = _loop()
    note = frame_note("est", _traj(t, 1.2 * xy + [0.5, -0.3]), _traj(t, xy), 0.5)
    assert note is not None and note.startswith("est is the reference scaled by 1.200")


def test_a_different_path_or_small_errors_are_not_noted():
    t, xy = _loop()
    drift = xy + np.c_[0.05 * t, -0.04 * t]  # odometry drifting away: neither one offset nor a scale
    assert frame_note("est", _traj(t, drift), _traj(t, xy), 0.5) is None
    assert frame_note("est", _traj(t, xy + 0.1), _traj(t, xy), 0.5) is None  # an offset, but 0.14 m


def _write_tum(path, tr: Trajectory) -> None:
    with open(path, "w") as f:
        for s, (x, y, yaw) in zip(tr.stamps, tr.poses, strict=True):
            f.write(f"{s:.6f} {x:.6f} {y:.6f} 0 0 0 {math.sin(yaw / 2):.9f} {math.cos(yaw / 2):.9f}\n")


def _moved(tr: Trajectory, pose) -> Trajectory:
    from fgloc.geometry import compose

    return Trajectory(tr.stamps, compose(np.asarray(pose, dtype=float), tr.poses))


def test_a_rigid_transform_is_noted():
    t, xy = _loop()
    ref = _traj(t, xy)
    note = frame_note("est", _moved(ref, [2.0, -1.0, math.radians(30.0)]), ref, 0.5)
    assert note is not None and note.startswith("the errors of est are mostly one rigid transform (a turn of +30.0 deg")


def test_align_start_moves_the_start_and_gives_the_end_error(tmp_path):
    """Two odometry frames (fgloc's run without a map, robot_localization's output): the estimate drifts
    0.5 m by the end; in its own frame it starts 3 m and 40 deg away from the reference."""
    import json

    t, xy = _loop()
    ref = _traj(t, xy)
    drifted = _traj(t, xy + np.c_[0.5 * t / t[-1], np.zeros_like(t)])
    _write_tum(tmp_path / "ref.tum", ref)
    _write_tum(tmp_path / "est.tum", _moved(drifted, [3.0, 0.0, math.radians(40.0)]))
    from fgloc.cli import main

    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        assert main(["eval", str(tmp_path / "est.tum"), str(tmp_path / "ref.tum"), "--align-start", "--json"]) == 0
    doc = json.loads(out.getvalue())
    assert doc["end_error_m"] == pytest.approx(0.5, abs=0.01)
    assert doc["metrics"]["position_rmse_m"] < 0.4  # the drift, not the 3 m / 40 deg between the frames
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        assert main(["eval", str(tmp_path / "est.tum"), str(tmp_path / "ref.tum"), "--align-start", "--align"]) == 2
    assert "--align or --align-start, not both" in err.getvalue()


def _write_tum(path, tr: Trajectory) -> None:
    with open(path, "w") as f:
        for s, (x, y, yaw) in zip(tr.stamps, tr.poses, strict=True):
            f.write(f"{s:.6f} {x:.6f} {y:.6f} 0 0 0 {math.sin(yaw / 2):.9f} {math.cos(yaw / 2):.9f}\n")


@pytest.mark.parametrize("align", [False, True])
def test_a_reference_whose_body_axes_are_turned_is_noted(tmp_path, align):
    """A motion-capture rigid body defined ~100 deg off the robot's axes (IST's ISR course bag): the
    positions agree within centimetres, the heading RMSE reads 99 deg; a note says what it is."""
    from fgloc.cli import main

    t, xy = _loop()
    ref = _traj(t, xy)
    ref = Trajectory(ref.stamps, np.c_[ref.poses[:, :2], ref.poses[:, 2] + math.radians(100.0)])
    est = _traj(t, xy + 0.02 * np.sin(3 * t)[:, None])
    if align:  # another frame too: --align removes it, the turned body axes stay
        c, s = math.cos(0.3), math.sin(0.3)
        moved = est.poses[:, :2] @ np.array([[c, s], [-s, c]]) + [2.0, -1.0]
        est = Trajectory(est.stamps, np.c_[moved, est.poses[:, 2] + 0.3])
    _write_tum(tmp_path / "est.tum", est)
    _write_tum(tmp_path / "ref.tum", ref)
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        assert main(["eval", str(tmp_path / "est.tum"), str(tmp_path / "ref.tum"),
                     *(["--align"] if align else [])]) == 0
    assert "note: the heading errors of est are mostly one offset (-100.0 deg, " in err.getvalue(), err.getvalue()
    assert "mostly one offset (+" not in err.getvalue()  # no position-offset note


def test_no_heading_note_on_an_ordinary_estimate_or_a_wrong_one():
    from fgloc.eval.checks import heading_note

    t, xy = _loop()
    ref = _traj(t, xy)
    good = _traj(t, xy + 0.02 * np.sin(3 * t)[:, None])
    assert heading_note("est", associate(good, ref, max_gap=0.5)) is None
    # turned 100 deg about the origin: positions metres off as well, not a body-axes offset
    c, s = math.cos(math.radians(100)), math.sin(math.radians(100))
    turned = Trajectory(t, np.c_[xy @ np.array([[c, s], [-s, c]]), good.poses[:, 2] + math.radians(100)])
    assert heading_note("est", associate(turned, ref, max_gap=0.5)) is None
