"""AMCL on a log of scans alone (no odometry): its motion is unknown, so the cloud is spread by a random
walk between updates and updates on time instead of on odometry motion; with and without a start pose."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from fgloc.bench.common import localize_sim
from fgloc.frontends.amcl import diffuse
from fgloc.geometry import interpolate_poses
from fgloc.sim import simulate_paper


@pytest.fixture(scope="module")
def scans_only():
    sim = simulate_paper(seed=3, route=[[14.0, 3.0], [27.5, 3.0], [27.5, 10.0]])
    out = copy.copy(sim)
    out.messages = [m for m in sim.messages if m[0] not in ("/odom", "/imu")]
    return out


@pytest.mark.parametrize("backend", ["smoother", "ekf"])
@pytest.mark.parametrize("start", ["given", "global"])
def test_amcl_localizes_scans_alone(scans_only, backend, start):
    final, _online, loc, _ = localize_sim(scans_only, backend, "amcl", use_initial=start == "given")
    assert loc.stats["odometry"] == 0
    counts = loc.stats["status"]["counts"]
    # measured on this drive (seed 3, 19 s): every pose but the global phase's first 1-6 ok.
    # Before: every update "waiting for motion" (zero odometry motion never reached update_min_d):
    # no fix in the whole run, every pose lost.
    assert loc.stats["fixes"] > 0.2 * loc.stats["scans"]  # 208-209 of 834 (every 0.1 s of the matched scans)
    assert counts["lost"] <= 10 and counts["ok"] >= 0.95 * sum(counts.values())
    g = interpolate_poses(scans_only.ground_truth.stamps, scans_only.ground_truth.poses, final.stamps)
    e = np.hypot(final.poses[:, 0] - g[:, 0], final.poses[:, 1] - g[:, 1])
    assert float(np.median(e)) < 0.03, (backend, start, float(np.median(e)))


def test_diffuse_spreads_by_the_walk_over_the_time():
    rng = np.random.default_rng(0)
    p = np.zeros((20000, 3))
    out = diffuse(p, 0.25, (1.0, 0.5), rng)
    assert np.allclose(out[:, :2].std(axis=0), 0.25, rtol=0.03)
    assert np.isclose(out[:, 2].std(), 0.125, rtol=0.03)
    assert np.all(np.abs(out[:, 2]) <= np.pi) and np.all(p == 0)
