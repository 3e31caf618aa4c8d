"""The recorded trajectory keeps the poses it sent: the same message bytes as made from scratch."""

from __future__ import annotations

import numpy as np

from fgloc.view.encode import GrowingPoses, poses_message


def test_growing_trajectory_message_is_the_one_made_from_scratch():
    rng = np.random.default_rng(4)
    rows = np.column_stack([rng.normal(0, 20, 3000), rng.normal(0, 20, 3000), rng.uniform(-7, 7, 3000)])
    rows[5:9, 2] = [np.pi, -np.pi, 0.0, -0.0]
    grow = GrowingPoses()
    n = 0
    for k, step in enumerate((1, 7, 0, 100, 3, 517, 1, 1000, 1371)):
        n += step
        stamp = 10.0 + k
        got = grow.message(stamp, "map", rows[:n]).encode()
        assert got == poses_message(stamp, "map", rows[:n]).encode(), n
    # another trajectory (a restart): made anew, not glued onto the old poses
    other = rows[::-1][:50].copy()
    assert grow.message(1.0, "odom", other).encode() == poses_message(1.0, "odom", other).encode()
    assert grow.message(2.0, "odom", other[:10]).encode() == poses_message(2.0, "odom", other[:10]).encode()
