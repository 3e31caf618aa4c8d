"""The native matcher's compiled kernels give what their plain definitions give.

``lm_system`` (the LM's pass: field lookups in one loop, robust weights and sums in another) against
a per-point sum of ``point_residual`` / ``rho_weight`` (the plain definition; the fused pass differs in the last
bits only); ``heading_probe`` (the heading check's two scores in one call) against the two
``correlative_search`` calls it stands for, bit for bit.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from fgloc.frontends import make_frontend
from fgloc.frontends.native import correlative_search, heading_probe, lm_system, point_residual, rho_weight

from .synth import MOUNT, free_poses, make_map, make_scan


@pytest.fixture(scope="module")
def setup():
    world = make_map()
    fe = make_frontend("native", world, MOUNT, {"surface_depth_cells": 0.0})
    rng = np.random.default_rng(5)
    poses = free_poses(world, 12, rng)
    scans = []
    for p in poses:
        pts, why = fe.pre(make_scan(world, p, rng), None)
        assert pts is not None, why
        scans.append((np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1]), p))
    return fe, scans, rng


def _plain_system(fe, px, py, pose, c, outlier):
    """cost, H, g as the per-point sum of the residual and robust weight (Python loop)."""
    lx, ly, backcos = fe._lb
    cs, sn = math.cos(pose[2]), math.sin(pose[2])
    H = np.zeros((3, 3))
    g = np.zeros(3)
    cost = 0.0
    for x, y in zip(px, py, strict=True):
        r, gx, gy, front = point_residual(fe.field, fe.A, fe.b, fe.far, pose, cs, sn, x, y, lx, ly, backcos, fe.depth_m)
        if not front:
            r = fe.far
        rho, w = rho_weight(r, c, fe.loss, outlier)
        cost += rho
        if w == 0.0:
            continue
        J = np.array([gx, gy, gx * (-sn * x - cs * y) + gy * (cs * x - sn * y)])
        H += w * np.outer(J, J)
        g += w * r * J
    return cost, H, g


@pytest.mark.parametrize("stage", [0, 1, 2])
def test_system_is_the_per_point_sum(setup, stage):
    fe, scans, rng = setup
    c, outlier = float(fe.scales[stage]), float(fe.outliers[stage])
    lx, ly, backcos = fe._lb
    for px, py, truth in scans:
        for k in range(3):
            pose = truth + (rng.normal(0.0, [0.05, 0.05, 0.03]) if k else 0.0)
            H, g = np.zeros((3, 3)), np.zeros(3)
            cost = lm_system(fe.field, fe.A, fe.b, fe.far, px, py, pose, c, fe.loss, outlier, lx, ly, backcos,
                           fe.depth_m, H, g)
            want_cost, want_H, want_g = _plain_system(fe, px, py, pose, c, outlier)
            assert cost == pytest.approx(want_cost, rel=1e-9, abs=1e-12)
            scale = float(np.abs(want_H).max())
            assert np.abs(H - want_H).max() <= 1e-9 * scale
            assert np.abs(g - want_g).max() <= 1e-9 * max(float(np.abs(want_g).max()), 1e-12) + 1e-12
            assert np.array_equal(H, H.T)


def test_heading_probe_is_the_two_searches(setup):
    fe, scans, rng = setup
    checked = 0
    for px, py, truth in scans:
        for stride in (1, 3, 10):
            pose = truth + rng.normal(0.0, [0.02, 0.02, 0.1])
            best, score, here = heading_probe(fe.lik, fe.Ac, fe.bc, px, py, stride, pose, fe.heading_window,
                                               fe.heading_step)
            sx, sy = np.ascontiguousarray(px[::stride]), np.ascontiguousarray(py[::stride])
            want_best, want_score = correlative_search(fe.lik, fe.Ac, fe.bc, sx, sy, pose, 0.0, 1.0, fe.heading_window,
                                            fe.heading_step, 1)
            _, want_here = correlative_search(fe.lik, fe.Ac, fe.bc, sx, sy, pose, 0.0, 1.0, 0.0, 1.0, 1)
            assert best.tobytes() == want_best[0].tobytes()
            assert score == want_score[0] and here == want_here[0]
            checked += 1
    assert checked == 3 * len(scans)
