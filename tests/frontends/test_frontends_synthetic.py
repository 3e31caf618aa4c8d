"""Native and KISS front-ends on a synthetic map (exact ray casting): accuracy, de-skew, rejections."""

from __future__ import annotations

import numpy as np
import pytest

from fgloc.frontends import MatchResult, make_frontend
from fgloc.frontends.native import surface_distance_field
from fgloc.geometry import wrap_angle
from fgloc.maps import OccupancyMap
from fgloc.types import LaserScan

from .synth import MOUNT, free_poses, make_map, make_moving_scan, make_scan

NAMES = ["native", "kiss"]
# the synthetic scans are ray cast on the grid itself: a beam ends on the face of the first occupied cell
FACES = {"surface_depth_cells": 0.0}


@pytest.fixture(scope="module")
def world():
    return make_map()


@pytest.fixture(scope="module")
def matchers(world):
    return {n: make_frontend(n, world, MOUNT, FACES) for n in NAMES}


def _err(res: MatchResult, truth: np.ndarray) -> tuple[float, float]:
    assert res.pose is not None
    e = res.pose - truth
    return float(np.hypot(e[0], e[1])), abs(float(np.degrees(wrap_angle(e[2]))))


@pytest.mark.parametrize("name", NAMES)
def test_converges_from_30cm_10deg(world, matchers, name):
    rng = np.random.default_rng(11)
    poses = free_poses(world, 40, rng)
    good = 0
    for p in poses:
        scan = make_scan(world, p, rng)
        a = rng.uniform(0, 2 * np.pi)
        guess = p + np.array([0.3 * np.cos(a), 0.3 * np.sin(a), np.radians(10) * rng.choice([-1, 1])])
        res = matchers[name].match(scan, guess)
        assert res.ok, res.reason
        dpos, dyaw = _err(res, p)
        good += dpos < 0.02 and dyaw < 0.3
        assert 0.0 <= res.quality <= 1.0
        assert res.cov is not None and np.all(np.linalg.eigvalsh(res.cov) > 0)
    assert good / len(poses) >= 0.95


@pytest.mark.parametrize("name", NAMES)
def test_deskew_removes_motion_distortion(world, name):
    rng = np.random.default_rng(5)
    twist, dt = np.array([0.8, 0.0, 1.0]), 0.04
    errs = {}
    for deskew in (False, True):
        fe = make_frontend(name, world, MOUNT, {**FACES, "preprocess": {"deskew": deskew}})
        e = []
        for p in free_poses(world, 12, rng, clearance=0.8):
            fe.reset()
            fe.match(make_moving_scan(world, p, twist, rng, stamp=9.96), p)
            res = fe.match(make_moving_scan(world, p, twist, rng, stamp=10.0), p + [0.05, -0.05, 0.02],
                           odom_delta=twist * dt)
            e.append(_err(res, p)[1])
        errs[deskew] = np.median(e)
    assert errs[False] > 0.3  # 1 rad/s over a 30 ms sweep skews the scan by ~0.8 deg
    assert errs[True] < 0.05


def test_surface_field_is_zero_on_wall_faces(world):
    f = surface_distance_field(world, upsample=2, max_dist_m=1.0)
    k, res = 2, world.resolution
    # the room's bottom wall: occupied rows up to y = 0.6 m in grid units (origin y = -2) -> face at y = -1.4
    col = int(round(5.0 / res)) * k
    row_face = int(round(0.6 / res)) * k  # first free fine row above the face
    # bilinear value at the face (between fine centres row_face - 1 and row_face)
    face_val = 0.5 * (f[row_face - 1, col] + f[row_face, col])
    assert abs(face_val) < 1e-9
    assert f[row_face + 10, col] == pytest.approx(10.5 * res / k)


def _bad_scans(n: int = 541) -> dict[str, LaserScan]:
    base = dict(stamp=1.0, angle_min=-2.35, angle_increment=0.0087, range_min=0.05, range_max=20.0)
    good = np.full(n, 3.0, dtype=np.float32)
    nan = np.full(n, np.nan, dtype=np.float32)
    inf = np.full(n, np.inf, dtype=np.float32)
    ninf = np.full(n, -np.inf, dtype=np.float32)
    zero = np.zeros(n, dtype=np.float32)
    few = nan.copy()
    few[:9] = 3.0
    mixed = np.where(np.arange(n) % 3 == 0, np.nan, np.where(np.arange(n) % 3 == 1, np.inf, 0.0)).astype(np.float32)
    return {
        "nan": LaserScan(ranges=nan, **base),
        "inf": LaserScan(ranges=inf, **base),
        "-inf": LaserScan(ranges=ninf, **base),
        "zero": LaserScan(ranges=zero, **base),
        "mixed": LaserScan(ranges=mixed, **base),
        "nine_valid": LaserScan(ranges=few, **base),
        "empty": LaserScan(ranges=np.zeros(0, dtype=np.float32), **base),
        "nan_angles": LaserScan(ranges=good, **{**base, "angle_increment": float("nan")}),
        "beyond_max": LaserScan(ranges=np.full(n, 25.0, dtype=np.float32), **base),
    }


@pytest.mark.parametrize("name", NAMES)
def test_bad_scans_give_no_fix_with_reason(world, matchers, name):
    guess = np.array([3.0, 2.0, 0.0])
    for label, scan in _bad_scans().items():
        res = matchers[name].match(scan, guess)
        assert not res.ok and res.pose is None and res.reason, label
    res = matchers[name].match(_bad_scans()["nine_valid"], guess)
    assert "9 valid beams" in res.reason


@pytest.mark.parametrize("name", NAMES)
def test_bad_guesses_give_no_fix_with_reason(world, matchers, name):
    scan = make_scan(world, np.array([3.0, 2.0, 0.3]))
    cases = {
        "off the map": np.array([100.0, 2.0, 0.0]),
        "unknown space": np.array([-0.8, -1.8, 0.0]),  # outside the room's walls
        "not finite": np.array([np.nan, 2.0, 0.0]),
        "[x, y, yaw]": np.array([1.0, 2.0]),
    }
    for why, g in cases.items():
        res = matchers[name].match(scan, g)
        assert not res.ok and why in res.reason, (why, res.reason)
    # odd odom_delta never raises either
    res = matchers[name].match(scan, np.array([3.0, 2.0, 0.3]), odom_delta=np.array([np.nan, 0, 0]))
    assert res.ok


@pytest.mark.parametrize("name", NAMES)
def test_scan_from_elsewhere_is_rejected(world, matchers, name):
    # a scan of a round room (every range 2 m) does not fit the rectangular room
    n = 541
    scan = LaserScan(0.0, -2.35, 4.7 / (n - 1), 0.05, 20.0, np.full(n, 2.0, dtype=np.float32))
    res = matchers[name].match(scan, np.array([8.0, 6.0, 0.0]))
    assert not res.ok and res.reason


def test_native_rejects_degenerate_corridor():
    data = np.full((40, 1600), -1, dtype=np.int16)
    data[10, :] = 100
    data[30, :] = 100
    data[11:30, :] = 0
    corridor = OccupancyMap(data, 0.05)
    fe = make_frontend("native", corridor, MOUNT, {**FACES, "search": "never"})
    scan = make_scan(corridor, np.array([40.0, 1.0, 0.0]), range_max=10.0)
    res = fe.match(scan, np.array([40.05, 1.0, 0.0]))
    assert not res.ok and "degenerate" in res.reason


def test_native_learns_the_surface_depth(world):
    """auto: starts at the cell centres (0.5), learns that this world's beams end on the faces (0)."""
    fe = make_frontend("native", world, MOUNT, {"surface_depth_cells": "auto"})
    assert fe.depth_m == pytest.approx(0.5 * world.resolution)  # type: ignore[attr-defined]
    rng = np.random.default_rng(4)
    errs = []
    for p in free_poses(world, 30, rng):
        res = fe.match(make_scan(world, p, rng), p + np.array([0.03, -0.02, 0.01]))
        errs.append(_err(res, p)[0])
    assert fe.depth_m < 0.1 * world.resolution  # type: ignore[attr-defined]
    assert np.median(errs[10:]) < 0.002


def _door_corridor(period_m: float | None) -> OccupancyMap:
    """An 80 m corridor (1 m wide) with 0.6 m door recesses every ``period_m`` (None: one recess)."""
    res = 0.05
    data = np.full((60, 1600), -1, dtype=np.int16)
    data[20, :] = 100
    data[41, :] = 100
    data[21:41, :] = 0
    xs = np.arange(2.0, 78.0, period_m) if period_m else np.array([40.3])
    for x in xs:
        c0, c1 = int(round(x / res)), int(round((x + 0.6) / res))
        data[41, c0:c1] = 0          # the recess opens the wall...
        data[42:46, c0:c1] = 0
        data[46, c0 - 1:c1 + 1] = 100  # ...to a door 0.25 m behind it
        data[41:47, c0 - 1] = 100
        data[41:47, c1] = 100
    return OccupancyMap(data, res)


def test_native_covariance_spans_a_corridor_alias():
    """Doors every 1.5 m: the scan fits the corridor 1.5 m further on almost as well; the fix's
    covariance along the corridor must say so (a corridor alias, not a 1 cm fix).  With one unique
    recess the same corridor gives a tight fix."""
    rng = np.random.default_rng(2)
    pose = np.array([40.0, 1.5, 0.0])
    sds = {}
    for period in (1.5, None):
        m = _door_corridor(period)
        fe = make_frontend("native", m, MOUNT, FACES)
        scan = make_scan(m, pose, rng, range_max=4.0)
        res = fe.match(scan, pose + np.array([0.03, 0.01, 0.005]))
        assert res.ok, res.reason
        assert _err(res, pose)[0] < 0.02
        sds[period] = float(np.sqrt(res.cov[0, 0]))
    assert sds[1.5] > 0.3          # spans the neighbouring door
    assert sds[None] < 0.05
