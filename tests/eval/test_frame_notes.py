"""An estimate in another frame than its reference (a simulator's world frame against the map's, as
Stage's /base_pose_ground_truth; a map scaled against the world, as Stage's bitmap fitted to a size)
reads as metres of error; ``fgloc eval`` notes the offset or the scale the errors are made of."""

from __future__ import annotations

import contextlib
import io
import math

import numpy as np

from fgloc.commands.eval import frame_note
from fgloc.types import Trajectory


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
