"""AMCL's in-place and compiled filter steps against the numpy expressions they replace, bit for bit."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fgloc.frontends.amcl import AMCL, sample_motion, systematic_resample
from fgloc.frontends.base import on_grid
from fgloc.geometry import wrap_angle
from fgloc.maps import OccupancyMap


def _numpy_resample(weights: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    c = np.cumsum(weights)
    c /= c[-1]
    u = (rng.random() + np.arange(n)) / n
    return np.minimum(np.searchsorted(c, u, side="right"), len(weights) - 1).astype(np.int64)


def _numpy_omni(particles: np.ndarray, delta: np.ndarray, alphas: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    a1, a2, a3, a4, a5 = (float(a) for a in alphas)
    n = len(particles)
    dx, dy, dth = float(delta[0]), float(delta[1]), float(wrap_angle(delta[2]))
    trans = math.hypot(dx, dy)
    out = particles.copy()
    yaw = particles[:, 2]
    bearing = math.atan2(dy, dx) if trans > 0 else 0.0
    sd_t = math.sqrt(a3 * trans**2 + a1 * dth**2)
    sd_r = math.sqrt(a4 * dth**2 + a2 * trans**2)
    sd_s = math.sqrt(a1 * dth**2 + a5 * trans**2)
    t_hat = trans + rng.normal(0.0, 1.0, n) * sd_t
    r_hat = dth + rng.normal(0.0, 1.0, n) * sd_r
    s_hat = rng.normal(0.0, 1.0, n) * sd_s
    b = yaw + bearing
    cb, sb = np.cos(b), np.sin(b)
    out[:, 0] += t_hat * cb + s_hat * sb
    out[:, 1] += t_hat * sb - s_hat * cb
    out[:, 2] = wrap_angle(yaw + r_hat)
    return out


@pytest.mark.filterwarnings("ignore:invalid value encountered in divide:RuntimeWarning")  # all-zero weights: 0 / 0
@pytest.mark.parametrize("n_w, n", [(1, 5), (7, 7), (500, 2000), (2000, 500), (3000, 3000)])
def test_systematic_resample_equals_searchsorted(n_w: int, n: int) -> None:
    gen = np.random.default_rng(n_w + n)
    for kind in ("random", "peaked", "zeros", "sparse"):
        w = gen.random(n_w)
        if kind == "peaked":
            w = np.exp(-50.0 * w)
        elif kind == "zeros":
            w = np.zeros(n_w)  # 0 / 0: every index 0, as numpy's search of NaNs gives
        elif kind == "sparse":
            w[gen.random(n_w) < 0.9] = 0.0
        seed = int(gen.integers(1 << 30))
        got = systematic_resample(w, n, np.random.default_rng(seed))
        want = _numpy_resample(w, n, np.random.default_rng(seed))
        assert got.dtype == np.int64 and np.array_equal(got, want), kind


@pytest.mark.filterwarnings("ignore:invalid value encountered in divide:RuntimeWarning")  # all-zero weights: 0 / 0
def test_systematic_resample_nan_tail_as_numpy() -> None:
    w = np.array([0.2, 0.3, np.inf, 0.1, 0.4])  # the cumulative sum ends in inf: inf / inf NaNs after zeros
    got = systematic_resample(w, 9, np.random.default_rng(3))
    assert np.array_equal(got, _numpy_resample(w, 9, np.random.default_rng(3)))


@pytest.mark.parametrize("delta", [[0.1, 0.02, 0.05], [0.0, 0.0, 0.3], [-0.2, 0.1, -3.0], [0.0, 0.0, 0.0]])
def test_omni_motion_equals_numpy_expressions(delta: list[float]) -> None:
    gen = np.random.default_rng(11)
    p = np.column_stack([gen.uniform(-5, 5, 700), gen.uniform(-5, 5, 700), gen.uniform(-np.pi, np.pi, 700)])
    alphas = np.array([0.05, 0.1, 0.2, 0.05, 0.3])
    got = sample_motion(p, np.array(delta), "omni", alphas, np.random.default_rng(5))
    want = _numpy_omni(p, np.array(delta), alphas, np.random.default_rng(5))
    assert np.array_equal(got, want)
    assert np.all(got[:, 2] >= -np.pi) and np.all(got[:, 2] < np.pi)


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # the 1e300 and non-finite points: overflow, cast
def test_on_grid_is_in_bounds_of_one_point() -> None:
    gen = np.random.default_rng(2)
    for yaw in (0.0, 0.3, -2.0):
        m = OccupancyMap(np.zeros((30, 50), dtype=np.int16), 0.1, np.array([-1.0, 0.5, yaw]))
        pts = gen.uniform(-4.0, 6.0, (400, 2))
        pts[:8] = [[np.nan, 0.0], [0.0, np.inf], [-np.inf, 1.0], [1e300, 0.0], [-1.0, 0.5], [3.9999, 2.0],
                   [-1e-300, 0.5], [4.0, 3.5]]
        want = m.in_bounds(np.nan_to_num(pts, nan=1e308, posinf=1e308, neginf=-1e308))
        want[:3] = False  # not finite: off the grid
        got = np.array([on_grid(m, float(x), float(y)) is not None for x, y in pts])
        assert np.array_equal(got, want)


def test_filter_on_a_corridor_keeps_the_cluster_mean_without_the_gather() -> None:
    data = np.zeros((40, 80), dtype=np.int16)
    data[0, :] = data[-1, :] = data[:, 0] = data[:, -1] = 100
    data[20, 10:30] = 100
    m = OccupancyMap(data, 0.1)
    amcl = AMCL(m, None, max_particles=600, min_particles=200)
    amcl.reset(np.array([5.0, 1.0, 0.0]), np.diag([0.01, 0.01, 0.01]))
    mask = np.ones(len(amcl.particles), bool)
    mean, cov = amcl._cluster_mean_cov(mask)
    from fgloc.frontends.amcl import weighted_mean_cov

    want = weighted_mean_cov(amcl.particles[mask], amcl.weights[mask])
    assert np.array_equal(mean, want[0]) and np.array_equal(cov, want[1])
    mask[::3] = False
    mean, cov = amcl._cluster_mean_cov(mask)
    want = weighted_mean_cov(amcl.particles[mask], amcl.weights[mask])
    assert np.array_equal(mean, want[0]) and np.array_equal(cov, want[1])


def test_bin_keys_equal_numpy_floor() -> None:
    from fgloc.frontends.amcl import bin_keys

    gen = np.random.default_rng(4)
    p = np.column_stack([gen.uniform(-30, 30, 999), gen.uniform(-30, 30, 999), gen.uniform(-np.pi, np.pi, 999)])
    p[:4] = [[0.0, -0.0, 0.5], [-0.5, 0.5, -np.pi], [1e-300, -1e-300, 0.17453292519943295], [-1.0, 1.0, 3.14]]
    size = np.array([0.5, 0.5, np.radians(10.0)])
    assert np.array_equal(bin_keys(p, size), np.floor(p / size).astype(np.int64))


def test_kld_count_reads_the_drawn_candidates_in_order() -> None:
    """The stopping rule over ``bins[draws[order[j]]]`` against the rule written out in Python."""
    from fgloc.frontends.amcl import kld_count

    def reference(keys: np.ndarray, pf_err: float, pf_z: float, n_min: int, cap: int) -> tuple[int, int]:
        seen: set[tuple[int, ...]] = set()
        for j in range(cap):
            seen.add(tuple(int(v) for v in keys[j]))
            k = len(seen)
            if k <= 1:
                lim = cap
            else:
                km1 = k - 1.0
                bb = 2.0 / (9.0 * km1)
                x = 1.0 - bb + math.sqrt(bb) * pf_z
                lim = min(max(int(math.ceil(km1 / (2.0 * pf_err) * x * x * x)), n_min), cap)
            if j + 1 > lim:
                return j + 1, k
        return cap, len(seen)

    gen = np.random.default_rng(9)
    for spread, n_particles, cap, n_min in ((3, 700, 2000, 500), (40, 3000, 2000, 100), (1, 50, 300, 20)):
        bins = gen.integers(-spread, spread + 1, (n_particles, 3))
        draws = gen.integers(0, n_particles, cap)
        order = gen.permutation(cap)
        got = kld_count(bins, draws, order, 0.05, 0.99, n_min, cap)
        assert tuple(int(v) for v in got) == reference(bins[draws[order]], 0.05, 0.99, n_min, cap)
