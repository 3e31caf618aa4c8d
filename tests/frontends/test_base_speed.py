"""The shared scan preprocessing and guess check, written for speed, give what the plain formulas give.

:class:`ScanPreprocessor` caches what depends on the scan layout and transforms only the valid
beams; :func:`check_guess` works on one point in scalar maths.  Both must return the same
numbers, bit for bit, as the straightforward array code (the reference below, as they were
written before): the front-ends' fixes and everything downstream stay identical.
"""

from __future__ import annotations

import numpy as np
import pytest

from fgloc.frontends.base import PreprocessOptions, ScanPreprocessor, check_guess
from fgloc.geometry import YAW, exp_along, transform_points, wrap_angle
from fgloc.geometry import log as se2_log
from fgloc.maps import OccupancyMap
from fgloc.types import LaserScan


class ReferencePreprocessor:
    """The preprocessing as plain array code over the whole sweep (no caches)."""

    def __init__(self, mount: np.ndarray, options: PreprocessOptions) -> None:
        self.mount, self.opt = mount, options
        self.last_stamp: float | None = None
        self.last_twist: tuple[float, np.ndarray] | None = None

    def __call__(self, scan: LaserScan, odom_delta: np.ndarray | None) -> np.ndarray | None:
        opt = self.opt
        ranges = np.asarray(scan.ranges, dtype=float)
        stamp = float(scan.stamp)
        a0, da = float(scan.angle_min), float(scan.angle_increment)
        rmin, rmax, t_inc = float(scan.range_min), float(scan.range_max), float(scan.time_increment)
        prev, self.last_stamp = self.last_stamp, stamp
        n = len(ranges)
        if not np.isfinite(rmin):
            rmin = 0.0
        if not (np.isfinite(rmax) and rmax > 0):
            rmax = np.inf
        with np.errstate(invalid="ignore"):
            valid = np.isfinite(ranges) & (ranges > 0) & (ranges >= rmin) & (ranges <= rmax)
        idx = np.flatnonzero(valid)
        if len(idx) < opt.min_valid_beams:
            return None
        if opt.max_beams and len(idx) > opt.max_beams:
            idx = idx[::int(np.ceil(len(idx) / opt.max_beams))]
        r = ranges[idx]
        ang = a0 + da * idx
        pts = transform_points(self.mount, np.column_stack([r * np.cos(ang), r * np.sin(ang)]))
        prev_twist, self.last_twist = self.last_twist, None
        if odom_delta is not None:
            od = np.asarray(odom_delta, dtype=float)
            interval = (stamp - prev) if prev is not None else float(scan.scan_time)
            if np.all(np.isfinite(od)) and 0 < interval <= opt.max_deskew_interval_s:
                twist = se2_log(od) / interval
                mid = stamp - 0.5 * interval
                self.last_twist = (mid, twist)
                if opt.deskew and t_inc != 0:
                    if opt.deskew_extrapolate and prev_twist is not None and \
                            0 < mid - prev_twist[0] <= opt.max_deskew_interval_s:
                        slope = (twist - prev_twist[1]) / (mid - prev_twist[0])
                        twist = twist + slope * (stamp + 0.5 * (n - 1) * t_inc - mid)
                    offs = exp_along(twist, np.arange(n, dtype=float) * t_inc)[idx]
                    c, s = np.cos(offs[:, YAW]), np.sin(offs[:, YAW])
                    pts = np.column_stack([offs[:, 0] + c * pts[:, 0] - s * pts[:, 1],
                                           offs[:, 1] + s * pts[:, 0] + c * pts[:, 1]])
        return np.ascontiguousarray(pts)


def _scans(rng: np.random.Generator, count: int, n: int, rmin: float, rmax: float, a0: float = -2.35,
           t_inc: float = 5.56e-5, t0: float = 100.0, bad: bool = True) -> list[LaserScan]:
    da = 2 * abs(a0) / (n - 1)
    out = []
    for k in range(count):
        r = rng.uniform(0.2, 1.2 * rmax if np.isfinite(rmax) and rmax > 0 else 40.0, n)
        if bad:
            pick = rng.integers(0, n, n // 8)
            edge = rmax if np.isfinite(rmax) and rmax > 0 else 7.0
            r[pick] = rng.choice([np.nan, np.inf, -np.inf, 0.0, -1.0, rmin, edge], len(pick))
        out.append(LaserScan(stamp=t0 + 0.04 * k + rng.uniform(-0.004, 0.004), angle_min=a0, angle_increment=da,
                             range_min=rmin, range_max=rmax, ranges=r.astype(np.float32), time_increment=t_inc,
                             scan_time=0.04, frame_id="laser"))
    return out


@pytest.mark.parametrize("options", [
    PreprocessOptions(),
    PreprocessOptions(deskew_extrapolate=False),
    PreprocessOptions(max_beams=180),
    PreprocessOptions(deskew=False),
])
@pytest.mark.parametrize("limits", [(0.1, 30.0), (0.0, 30.0), (float("nan"), float("inf")), (0.5, -1.0)])
def test_preprocessing_is_bit_identical_to_the_plain_formulas(options, limits):
    rng = np.random.default_rng(7)
    mount = np.array([0.27, -0.03, 0.05])
    fast, ref = ScanPreprocessor(mount, options), ReferencePreprocessor(mount, options)
    # two layouts in turn (the cache must follow the scan), a still robot, a turning one
    scans = _scans(rng, 30, 541, *limits) + _scans(rng, 10, 360, *limits, a0=-np.pi, t_inc=-1e-4, t0=102.0) + \
        _scans(rng, 10, 541, *limits, t0=103.0, bad=False)
    compared = 0
    for k, scan in enumerate(scans):
        turn = [0.0, 1e-13, 0.03, -0.2][k % 4]
        delta = None if k % 11 == 3 else np.array([0.02, 0.001, turn]) * rng.uniform(0.5, 1.5)
        got, why = fast(scan, delta)
        want = ref(scan, delta)
        if want is None:
            assert got is None and "valid beams" in why
            continue
        assert got is not None and got.shape == want.shape and got.flags["C_CONTIGUOUS"]
        assert got.tobytes() == want.tobytes(), f"scan {k}: max difference {np.max(np.abs(got - want))}"
        compared += 1
    assert compared >= 40


def test_bad_scans_are_reasons_not_errors():
    pre = ScanPreprocessor(None)
    ok = dict(stamp=1.0, angle_min=-1.0, angle_increment=0.01, range_min=0.1, range_max=10.0)
    assert pre(LaserScan(ranges=np.zeros(0), **ok))[1] == "empty scan"
    assert "not finite" in pre(LaserScan(ranges=np.ones(50), **{**ok, "angle_min": np.nan}))[1]
    assert "only 0 valid beams" in pre(LaserScan(ranges=np.full(50, np.nan), **ok))[1]
    pts, why = pre(LaserScan(ranges=np.full(50, 2.0), **ok), np.array([np.nan, 0.0, 0.0]))
    assert why == "" and pts.shape == (50, 2)  # a non-finite odometry delta: not de-skewed
    np.testing.assert_allclose(np.hypot(pts[:, 0], pts[:, 1]), 2.0)


def _world_cell(occ: OccupancyMap, x: float, y: float) -> tuple[bool, int, int]:
    rc = occ.world_to_grid(np.array([[x, y]]))[0]
    return bool(occ.in_bounds(np.array([[x, y]]))[0]), int(rc[0]), int(rc[1])


@pytest.mark.parametrize("origin_yaw", [0.0, 0.3])
def test_check_guess_agrees_with_the_maps_own_transform(origin_yaw):
    rng = np.random.default_rng(3)
    data = np.zeros((40, 60), dtype=np.int16)
    data[:, :5] = -1     # unknown band with free space near its right edge
    data[10:30, 20:22] = 100
    occ = OccupancyMap(data, 0.05, np.array([-1.3, 0.7, origin_yaw]))
    x0, x1, y0, y1 = occ.extent
    span = max(x1 - x0, y1 - y0)
    n_ok = 0
    for x, y, yaw in zip(rng.uniform(x0 - span, x1 + span, 3000), rng.uniform(y0 - span, y1 + span, 3000),
                         rng.uniform(-9, 9, 3000), strict=True):
        inside, i, j = _world_cell(occ, x, y)
        got, why = check_guess(occ, np.array([x, y, yaw]))
        if not inside:
            assert got is None and "off the map" in why
            continue
        if data[i, j] < 0 and why:
            assert "unknown space" in why
            continue
        assert why == "" and got is not None
        assert got.tobytes() == np.array([x, y, wrap_angle(yaw)]).tobytes()
        n_ok += 1
    assert n_ok > 100
    assert check_guess(occ, np.array([np.nan, 0.0, 0.0]))[1] == "guess is not finite"
    assert "shape" in check_guess(occ, np.array([1.0, 2.0]))[1]
    assert "off the map" in check_guess(occ, np.array([1e300, 0.0, 0.0]))[1]
    g = np.array([0.5, 1.0, 7.0])
    check_guess(occ, g)
    assert g[2] == 7.0  # the caller's guess is not modified
