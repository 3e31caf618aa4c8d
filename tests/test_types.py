import numpy as np
import pytest

from fgloc.types import LaserScan, Trajectory


def test_trajectory_requires_increasing_stamps():
    with pytest.raises(ValueError, match="strictly increasing"):
        Trajectory([0.0, 1.0, 1.0], np.zeros((3, 3)))
    with pytest.raises(ValueError, match="stamps"):
        Trajectory([0.0, 1.0], np.zeros((3, 3)))
    with pytest.raises(ValueError, match="non-finite"):
        Trajectory([0.0, 1.0], [[0, 0, 0], [np.nan, 0, 0]])


def test_trajectory_from_unsorted_and_interpolate():
    t = Trajectory.from_unsorted(np.array([2.0, 0.0, 1.0, 1.0]), np.array(
        [[2, 0, 0], [0, 0, 0], [9, 9, 9], [1, 0, 0]], dtype=float))
    assert np.allclose(t.stamps, [0, 1, 2])
    assert np.allclose(t.poses[:, 0], [0, 1, 2])  # duplicate stamp keeps the last
    assert np.allclose(t.interpolate(1.5)[0, :2], [1.5, 0])
    assert t.path_length() == pytest.approx(2.0)


def test_laserscan_valid_mask_rep117():
    r = np.array([1.0, np.inf, -np.inf, np.nan, 0.0, 0.2, 60.0, 2.0], dtype=np.float32)
    s = LaserScan(0.0, -np.pi / 2, np.pi / 7, 0.5, 50.0, r)
    assert s.valid_mask().tolist() == [True, False, False, False, False, False, False, True]
    pts = s.points()
    assert pts.shape == (2, 2)
    assert np.allclose(pts[0], [0.0, -1.0], atol=1e-9)
