"""The native matcher's covariance: the map-registration floor (issue 13 item 4).

A scan cannot see how well its map is registered in the map frame (a SLAM map's passes disagree
by centimetres; every fix moves with the map).  The floor is the map's declared ``accuracy_m``
(0 for the simulator's and these synthetic maps: the world is the map; undeclared: 0; a SLAM map
declares about half a cell); stretched along the scan's weakly constrained direction, over the points' moment arm in
heading.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from fgloc.errors import ConfigError
from fgloc.frontends.base import registration_sigma
from fgloc.frontends.native import NativeMatcher, registration_floor
from fgloc.maps import OccupancyMap

from .synth import MOUNT, make_map, make_scan


def test_floor_isotropic_corridor_and_heading():
    # an isotropic scan: sigma^2 on x and y; heading sigma^2 / lever^2 (lever^2 = H_yaw / mean(H_xx, H_yy))
    H = np.diag([100.0, 100.0, 100.0 * 4.0**2])
    F = registration_floor(H, 0.02)
    assert F[:2, :2] == pytest.approx(0.02**2 * np.eye(2))
    assert F[2, 2] == pytest.approx(0.02**2 / 16.0)
    # a corridor along x: the along-track floor is larger than the cross-track one, rotated with it
    c, s = math.cos(0.3), math.sin(0.3)
    R = np.array([[c, -s], [s, c]])
    Hc = np.zeros((3, 3))
    Hc[:2, :2] = R @ np.diag([2.0, 198.0]) @ R.T
    Hc[2, 2] = 100.0
    Fc = R.T @ registration_floor(Hc, 0.02)[:2, :2] @ R
    assert Fc[0, 0] == pytest.approx(0.02**2 * math.sqrt(100 / 2.0), rel=1e-6)
    assert Fc[1, 1] == pytest.approx(0.02**2 * math.sqrt(100 / 198.0), rel=1e-6)
    assert abs(Fc[0, 1]) < 1e-12
    assert np.all(registration_floor(H, 0.0) == 0)
    assert np.all(registration_floor(np.zeros((3, 3)), 0.02) == 0)


@pytest.fixture(scope="module")
def scan_and_maps():
    m0 = make_map()  # declares accuracy_m = 0: the scans are ray cast on it
    undeclared = OccupancyMap(m0.data, m0.resolution, m0.origin)
    declared = OccupancyMap(m0.data, m0.resolution, m0.origin, accuracy_m=0.03)
    pose = np.array([3.0, 3.0, 0.4])
    return make_scan(m0, pose, np.random.default_rng(3)), pose, m0, undeclared, declared


def _cov(m, scan, pose, **over):
    # the scans are ray cast on the grid: beams end on the cells' faces (surface depth 0)
    r = NativeMatcher(m, MOUNT, surface_depth_cells=0.0, **over).match(scan, pose + np.array([0.03, -0.02, 0.01]))
    assert r.ok, r.reason
    assert np.hypot(*(r.pose[:2] - pose[:2])) < 0.005
    return r.cov


def test_fix_covariance_takes_the_maps_accuracy(scan_and_maps):
    scan, pose, m0, undeclared, declared = scan_and_maps
    c0 = _cov(m0, scan, pose)
    # the world is the map: only the scan's own evidence (a few mm)
    assert math.sqrt(np.linalg.eigvalsh(c0[:2, :2]).max()) < 0.01
    # undeclared: no floor; half a cell (2.5 cm) configured: the floor is its part beyond the raster's
    # (5 cm cells: 2.04 cm), at least that along the weakest direction, >= 2.04 cm / 2^(1/4) across
    assert _cov(undeclared, scan, pose) == pytest.approx(c0)
    cu = _cov(undeclared, scan, pose, map_accuracy_m=0.025)
    s = registration_sigma(0.025, m0.resolution)
    ev = np.linalg.eigvalsh(cu[:2, :2])
    assert ev.max() >= s**2 and ev.min() >= s**2 / math.sqrt(2) * 0.999
    assert cu[2, 2] > c0[2, 2]
    # a declared accuracy is used as it is; a configured number overrides the map's
    cd = _cov(declared, scan, pose)
    assert np.linalg.eigvalsh(cd[:2, :2]).max() >= registration_sigma(0.03, m0.resolution) ** 2
    assert _cov(declared, scan, pose, map_accuracy_m=0.0) == pytest.approx(c0)
    assert _cov(m0, scan, pose, map_accuracy_m=0.025) == pytest.approx(cu)
    with pytest.raises(ConfigError):
        NativeMatcher(m0, MOUNT, map_accuracy_m="sometimes")


def test_the_rasters_part_of_the_accuracy_is_no_floor(scan_and_maps):
    """``accuracy_m`` counts the raster (a wall known to its cell, ``res / sqrt(12)``; ``fgloc map``
    adds it to the passes' registration in quadrature).  Each wall sits differently in its cells, so
    the scan's residuals see that part and the per-run covariance carries it (the simulator's maps,
    their world rasterized: NEES ~2.6 with no floor); the floor is the rest, the passes' registration."""
    assert registration_sigma(0.025, 0.05) == pytest.approx(math.sqrt(0.025**2 - 0.05**2 / 12))
    assert registration_sigma(0.0222, 0.05) == pytest.approx(0.01687, abs=1e-5)
    assert registration_sigma(0.03, 0.0) == 0.03
    assert registration_sigma(0.01, 0.05) == 0.0 and registration_sigma(0.0, 0.05) == 0.0
    scan, pose, m0, _, _ = scan_and_maps
    raster = OccupancyMap(m0.data, m0.resolution, m0.origin, accuracy_m=m0.resolution / math.sqrt(12))
    assert _cov(raster, scan, pose) == pytest.approx(_cov(m0, scan, pose))
