"""Front-end fixtures: the paper run's scans with ground truth and odometry deltas."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from fgloc.geometry import between, compose, interpolate_poses
from fgloc.maps import OccupancyMap
from fgloc.types import LaserScan, Odometry, StaticTransform


@dataclass
class ScanSet:
    map: OccupancyMap
    laser_mount: StaticTransform
    scans: list[LaserScan]
    truth: np.ndarray          # (N, 3) base_link in map at each scan stamp
    odom_deltas: list          # odometry motion since the previous scan (None for the first)


def odom_poses_at(odoms: list[Odometry], stamps: np.ndarray) -> np.ndarray:
    """Odometry-frame poses at ``stamps``: the messages' poses if present, else integrated twists."""
    t = np.array([o.stamp for o in odoms])
    if all(o.pose is not None for o in odoms):
        p = np.array([o.pose for o in odoms], dtype=float)
    else:
        p = np.zeros((len(odoms), 3))
        for i in range(1, len(odoms)):
            p[i] = compose(p[i - 1], np.asarray(odoms[i - 1].twist, dtype=float) * (t[i] - t[i - 1]))
    return interpolate_poses(t, p, stamps)


@pytest.fixture(scope="session")
def paper_scans(request) -> ScanSet:
    try:
        from fgloc.sim import simulate_paper  # noqa: F401
    except ImportError:
        pytest.skip("simulator (fgloc.sim.simulate_paper) not available yet")
    sim = request.getfixturevalue("paper_sim")
    scans = [m for _, m in sim.messages if isinstance(m, LaserScan)]
    odoms = [m for topic, m in sim.messages if isinstance(m, Odometry) and topic != "/ground_truth"]
    stamps = np.array([s.stamp for s in scans])
    truth = sim.ground_truth.interpolate(stamps)
    od = odom_poses_at(odoms, stamps)
    deltas = [None] + [between(od[i - 1], od[i]) for i in range(1, len(scans))]
    return ScanSet(sim.map, sim.laser_mount, scans, truth, deltas)
