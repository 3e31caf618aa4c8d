"""AMCL: adaptive Monte Carlo localization on an occupancy map (nav2_amcl semantics).

A particle filter over ``base_link`` poses ``[x_m, y_m, yaw_rad]`` in ``map``:

* **motion model** (nav2 ``DifferentialMotionModel`` / ``OmniMotionModel``): the odometry
  motion since the last filter update (base frame) is sampled per particle with noise
  ``alpha1`` (rot from rot), ``alpha2`` (rot from trans), ``alpha3`` (trans from trans),
  ``alpha4`` (trans from rot), ``alpha5`` (strafe from trans, omni only);
* **sensor model**: likelihood field.  Beam endpoints (evenly subsampled to at most
  ``laser_max_beams`` valid beams, de-skewed by the shared preprocessor) are projected
  per particle; ``z`` = distance to the nearest wall *surface* (``|f|``, ``f`` the bilinear
  signed field of :func:`wall_surface_field`: zero on the wall cells' faces, or
  ``surface_depth_cells`` behind them; clipped to ``laser_likelihood_max_dist``; endpoints off
  the grid get the maximum);
  ``pz = z_hit exp(-z^2 / 2 sigma_hit^2) + z_rand / range_max``.  ``laser_model_type``
  ``likelihood_field`` combines beams as nav2 does, ``w = 1 + sum pz^3``;
  ``likelihood_field_prob`` multiplies them, ``w = prod pz`` (log space), tempered by
  ``beam_correlation`` (log-likelihood divided by it: neighbouring beams are not
  independent).  Per REP 117 +inf (no return), -inf (too close), NaN and zero ranges are
  dropped (max-range readings ignored, as nav2 does);
* **KLD-adaptive resampling** (Fox 2003, as nav2 ``pf_resample_limit``: ``pf_z`` is used
  directly as the normal quantile, as nav2 does) with low-variance (systematic) resampling
  every ``resample_interval`` updates, histogram bins ``kld_bin_xy`` x ``kld_bin_yaw``;
* **augmented MCL recovery**: running averages ``w_slow``/``w_fast`` of the mean raw
  weight (``recovery_alpha_slow``/``recovery_alpha_fast``, 0 = off); with probability
  ``max(0, 1 - w_fast/w_slow)`` a resampled particle is replaced by a random free-space pose;
* **update thresholds** ``update_min_d`` / ``update_min_a``: the filter updates only
  after that much odometry motion (the first scan after a reset always updates);
* **no odometry** (``odom_delta`` None after the first scan: a log of scans alone): the motion is
  unknown, so the cloud is spread by a random walk of ``unknown_motion_sigma`` (m/s, rad/s) times
  the time since its last update, and it updates once that time lets the robot have moved
  ``update_min_d`` at that speed;
* **global localization** (``reset(None)``): ``global_particles`` poses uniform over the
  map's free cells.  The filter stays in its global phase (KLD cap ``global_particles``, floor
  ``max_particles``, the wider ``global_sigma_hit``: sparse particles are rarely within
  ``sigma_hit`` of the truth and a narrow model kills the right hypothesis early) until the
  posterior is one mode the tracking filter can hold: its occupied KLD bins need at most
  ``max_particles`` and one connected cluster of them holds ``converged_cluster_weight``.

Convergence is judged on the filter's own evidence, not on a width in metres (nav2's
defaults keep a 0.3-0.6 m wide cloud whose estimate is good): particles are clustered
by connected KLD bins (as nav2's ``pf_cluster_stats``); a fix needs the heaviest cluster to
hold ``converged_cluster_weight`` of the weight, and reports that cluster's weighted mean
(circular for yaw) -- ``estimate: refined`` moves it to the maximum of the configured
sensor model on the same scan (a few Gauss-Newton steps; kept within 3 sigma of the
cluster: the filter's mean lags behind a weak sensor model) -- with the cluster's
covariance, ``cov = cov_scale * cov_cluster + diag(cov_floor)``, however wide: the back-end
weighs the fix by it.  "No fix" (with a reason) during the global phase, when no cluster
dominates, when no update ran (thresholds not met, unless ``fix_without_update``), on bad
scans and when an uninitialised filter gets a guess off the map.  Never raises on bad input.

All per-particle work is vectorized numpy or compiled numba; no Python loop over particles.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from fgloc.config.schema import parse, setting, to_dict, with_overrides
from fgloc.errors import ConfigError
from fgloc.geometry import compose1, wrap_angle, wrap_scalar
from fgloc.gridmath import add_normal, bilinear, bilinear_grad, mirror_upper, njit, run_step
from fgloc.maps import OccupancyMap
from fgloc.types import LaserScan, StaticTransform

from .base import MatchResult, PreprocessOptions, ScanPreprocessor, check_guess, no_fix, on_grid
from .native import distance_m, map_distance_field, signed_field

FloatArray = NDArray[np.float64]
#: EM rounds of the refinement with the measured sigma at most (``refine_scale: measured``)
REFINE_SCALE_ROUNDS = 6



# ------------------------------------------------------------------ compiled kernels
@njit(cache=True, fastmath=True)
def _weights_kernel(px, py, pyaw, bx, by, field, depth, ox, oy, inv_res, zmax, table, inv_step):  # pragma: no cover
    """Per-particle sum over beams of ``table(z)``, ``z`` the field at the beam endpoint.

    ``field + depth`` is the signed surface distance at cell centres (bilinear), ``z`` its absolute
    value; endpoints off the grid get ``zmax``.  ``table``: the per-beam term of the sensor model sampled every
    ``1 / inv_step`` metres of ``z`` (see :func:`beam_term_table`), linearly interpolated.
    """
    n = px.shape[0]
    m = bx.shape[0]
    last = table.shape[0] - 2
    out = np.empty(n)
    for i in range(n):
        c = math.cos(pyaw[i])
        s = math.sin(pyaw[i])
        # particle pose in grid units, cell centres at integers
        gx0 = (px[i] - ox) * inv_res - 0.5
        gy0 = (py[i] - oy) * inv_res - 0.5
        cr = c * inv_res
        sr = s * inv_res
        acc = 0.0
        for j in range(m):
            z = abs(bilinear(field, gx0 + cr * bx[j] - sr * by[j], gy0 + sr * bx[j] + cr * by[j], zmax - depth)
                    + depth)
            t = z * inv_step
            k = int(t)
            if k > last:
                k = last
            acc += table[k] + (t - k) * (table[k + 1] - table[k])
        out[i] = acc
    return out


def beam_term_table(model: int, z_hit: float, z_rand_mult: float, sigma: float, zmax: float
                    ) -> tuple[FloatArray, float]:
    """The sensor model's per-beam term as a table over the endpoint distance ``z in [0, zmax]``.

    ``pz = z_hit exp(-z^2 / 2 sigma^2) + z_rand_mult``; model 0 (nav2 ``likelihood_field``)
    sums ``pz^3``, model 1 (``likelihood_field_prob``) sums ``log max(pz, 1e-30)``.  Step
    ``sigma / 100``: linear interpolation is then within ~2.5e-5 of the exact term per beam
    (``h^2/8 max|f''|``, ``|f''| <= 2 / sigma^2`` for the log), far below what separates
    particles, and replaces an ``exp`` and a ``log`` per beam and particle (2/3 of the
    update's time).  Returns ``(table, 1 / step)``.
    """
    step = max(sigma / 100.0, zmax / 100_000.0, 1e-9)
    z = np.arange(int(math.ceil(zmax / step)) + 2, dtype=float) * step
    pz = z_hit * np.exp(-0.5 * (z / sigma) ** 2) + z_rand_mult
    term = pz**3 if model == 0 else np.log(np.maximum(pz, 1e-30))
    return np.ascontiguousarray(term), 1.0 / step


@njit(cache=True)
def kld_count(bins, draws, order, pf_err, pf_z, n_min, cap):  # pragma: no cover - compiled
    """nav2 ``pf_update_resample``'s stopping rule over candidates in visiting order.

    Candidate ``j`` is particle ``draws[order[j]]``, its histogram bin ``bins[draws[order[j]]]``
    (``bins (N, 3)``), read as the count goes (most of the ``cap`` candidates are never visited).
    Returns ``(n, k)``: the first count ``n`` that exceeds the KLD limit for the ``k`` distinct bins
    among the first ``n`` candidates (``cap`` when never), and ``k``.  Distinct bins are counted with
    an open-addressing hash set.
    """
    size = 1
    while size < 2 * cap:
        size *= 2
    mask = size - 1
    used = np.zeros(size, dtype=np.bool_)
    tab = np.empty((size, 3), dtype=np.int64)
    k = 0
    n = cap
    for j in range(cap):
        i = draws[order[j]]
        a, b, c = bins[i, 0], bins[i, 1], bins[i, 2]
        h = (a * 73856093) ^ (b * 19349663) ^ (c * 83492791)
        slot = h & mask
        while True:
            if not used[slot]:
                used[slot] = True
                tab[slot, 0] = a
                tab[slot, 1] = b
                tab[slot, 2] = c
                k += 1
                break
            if tab[slot, 0] == a and tab[slot, 1] == b and tab[slot, 2] == c:
                break
            slot = (slot + 1) & mask
        # kld_limit(k) for the bins seen so far
        if k <= 1:
            lim = cap
        else:
            km1 = k - 1.0
            bb = 2.0 / (9.0 * km1)
            x = 1.0 - bb + math.sqrt(bb) * pf_z
            lim = int(math.ceil(km1 / (2.0 * pf_err) * x * x * x))
            if lim < n_min:
                lim = n_min
            if lim > cap:
                lim = cap
        if j + 1 > lim:
            n = j + 1
            break
    return n, k


@njit(cache=True)
def bin_keys(p, size):  # pragma: no cover - compiled
    """``floor(p / size).astype(int64)`` for particles ``p (N, 3)`` and bin sizes ``size (3,)``."""
    n = p.shape[0]
    out = np.empty((n, 3), dtype=np.int64)
    for i in range(n):
        for k in range(3):
            out[i, k] = np.int64(math.floor(p[i, k] / size[k]))
    return out


@njit(cache=True)
def bin_clusters(keys, weights, n_yaw):  # pragma: no cover - compiled
    """Connected clusters of occupied histogram bins (nav2 ``pf_cluster_stats``).

    ``keys (N, 3)``: each particle's bin ``(ix, iy, iyaw)`` with ``iyaw`` in ``[0, n_yaw)``
    (heading wraps around); bins touching in any of the 26 directions join one cluster.
    Returns ``(label per particle, total weight per label)``; labels are ``0 .. K-1``.
    """
    n = keys.shape[0]
    size = 1
    while size < 2 * n:
        size *= 2
    mask = size - 1
    slot_bin = np.full(size, -1, dtype=np.int64)
    bins = np.empty((n, 3), dtype=np.int64)
    of = np.empty(n, dtype=np.int64)
    nb = 0
    for i in range(n):
        a, b, c = keys[i, 0], keys[i, 1], keys[i, 2]
        sl = ((a * 73856093) ^ (b * 19349663) ^ (c * 83492791)) & mask
        while True:
            j = slot_bin[sl]
            if j < 0:
                slot_bin[sl] = nb
                bins[nb, 0] = a
                bins[nb, 1] = b
                bins[nb, 2] = c
                of[i] = nb
                nb += 1
                break
            if bins[j, 0] == a and bins[j, 1] == b and bins[j, 2] == c:
                of[i] = j
                break
            sl = (sl + 1) & mask
    parent = np.arange(nb)
    for j in range(nb):
        for da in range(-1, 2):
            for db in range(-1, 2):
                for dc in range(-1, 2):
                    if da == 0 and db == 0 and dc == 0:
                        continue
                    a = bins[j, 0] + da
                    b = bins[j, 1] + db
                    c = (bins[j, 2] + dc) % n_yaw
                    sl = ((a * 73856093) ^ (b * 19349663) ^ (c * 83492791)) & mask
                    while slot_bin[sl] >= 0:
                        k = slot_bin[sl]
                        if bins[k, 0] == a and bins[k, 1] == b and bins[k, 2] == c:
                            ra = j
                            while parent[ra] != ra:
                                ra = parent[ra]
                            rb = k
                            while parent[rb] != rb:
                                rb = parent[rb]
                            if ra != rb:
                                parent[max(ra, rb)] = min(ra, rb)
                            break
                        sl = (sl + 1) & mask
    root_label = np.full(nb, -1, dtype=np.int64)
    n_lab = 0
    for j in range(nb):
        r = j
        while parent[r] != r:
            r = parent[r]
        if root_label[r] < 0:
            root_label[r] = n_lab
            n_lab += 1
        root_label[j] = root_label[r]
    labels = np.empty(n, dtype=np.int64)
    wsum = np.zeros(n_lab)
    for i in range(n):
        labels[i] = root_label[of[i]]
        wsum[labels[i]] += weights[i]
    return labels, wsum


@njit(cache=True, fastmath=True)
def _refine_kernel(field, depth, ox, oy, inv_res, zmax, bx, by, pose0, z_hit, z_rand_mult, sigma, model,
                   max_iter):  # pragma: no cover - compiled
    """Maximise the sensor model's score of one scan over the pose, from ``pose0``.

    Score: ``sum pz^3`` (model 0, nav2 likelihood_field) or ``sum log pz`` (model 1), ``z``
    ``|field + depth|`` (bilinear) at each endpoint.  Iteratively reweighted Gauss-Newton (the
    score is a sum of ``-rho(z)`` with IRLS weight ``rho'(z) / z``; endpoints off the grid or at
    the field's clip distance carry no gradient).  Returns ``(pose, H, sum w z^2, sum w, runs,
    sum w f)``: ``H`` the final weighted normal matrix (0 rows when no beam contributed), ``f``
    the signed ``field + depth`` (negative: the endpoint behind the modelled surface).
    """
    pose = pose0.copy()
    H = np.zeros((3, 3))
    g = np.zeros(3)
    inv_s2 = 1.0 / (sigma * sigma)
    wr2 = 0.0
    sw = 0.0
    swf = 0.0
    n_runs = 0
    for _it in range(max_iter):
        wr2 = 0.0
        sw = 0.0
        swf = 0.0
        n_runs = 0
        run_len = 0.0
        lastx = 1e300
        lasty = 1e300
        c = math.cos(pose[2])
        s = math.sin(pose[2])
        for a in range(3):
            g[a] = 0.0
            for b in range(3):
                H[a, b] = 0.0
        for j in range(bx.shape[0]):
            qx = pose[0] + c * bx[j] - s * by[j]
            qy = pose[1] + s * bx[j] + c * by[j]
            z, du, dv = bilinear_grad(field, (qx - ox) * inv_res - 0.5, (qy - oy) * inv_res - 0.5, zmax - depth)
            z += depth
            f = z
            if z < 0.0:  # behind the surface: the distance is |field + depth|, its gradient points out
                z, du, dv = -z, -du, -dv
            if not (z < zmax):
                continue
            e = math.exp(-0.5 * z * z * inv_s2)
            pz = z_hit * e + z_rand_mult
            if model == 0:
                w = 3.0 * pz * pz * z_hit * e * inv_s2
            else:
                w = z_hit * e * inv_s2 / max(pz, 1e-30)
            gx = du * inv_res
            gy = dv * inv_res
            j2 = gx * (-s * bx[j] - c * by[j]) + gy * (c * bx[j] - s * by[j])
            g[0] += w * gx * z
            g[1] += w * gy * z
            g[2] += w * j2 * z
            wr2 += w * z * z
            sw += w
            swf += w * f
            # runs of neighbouring endpoints (one wall stretch <= RUN_LENGTH_M): their map errors are shared
            new_run, run_len = run_step(bx[j], by[j], lastx, lasty, run_len)
            n_runs += new_run
            lastx = bx[j]
            lasty = by[j]
            add_normal(H, w, gx, gy, j2)
        mirror_upper(H)
        M = H.copy()
        for a in range(3):
            M[a, a] += 1e-9 + 1e-3 * H[a, a]
        if abs(np.linalg.det(M)) < 1e-300:
            break
        d = np.linalg.solve(M, -g)
        pose += d
        if abs(d[0]) + abs(d[1]) + abs(d[2]) < 1e-6:
            break
    return pose, H, wr2, sw, n_runs, swf


# ------------------------------------------------------------------ motion models
def diffuse(particles: FloatArray, dt_s: float, sigma: tuple[float, ...], rng: np.random.Generator) -> FloatArray:
    """``particles (N, 3)`` spread by a random walk of ``sigma`` (m/s, rad/s) over ``dt_s`` (the motion
    of a robot without odometry is unknown). Returns a new array."""
    n = len(particles)
    out = particles.copy()
    out[:, :2] += rng.normal(0.0, float(sigma[0]) * dt_s, (n, 2))
    out[:, 2] = wrap_angle(out[:, 2] + rng.normal(0.0, float(sigma[1]) * dt_s, n))
    return out


def sample_motion(particles: FloatArray, delta: FloatArray, model: str, alphas: FloatArray,
                  rng: np.random.Generator) -> FloatArray:
    """Propagate ``particles (N, 3)`` by the base-frame odometry ``delta`` with nav2's noise.

    ``model``: ``differential`` (rot1-trans-rot2) or ``omni`` (trans, strafe, rot).
    ``alphas``: ``[alpha1..alpha5]``.  Returns a new array.
    """
    a1, a2, a3, a4, a5 = (float(a) for a in alphas)
    n = len(particles)
    dx, dy, dth = float(delta[0]), float(delta[1]), float(wrap_angle(delta[2]))
    trans = math.hypot(dx, dy)
    out = particles.copy()
    yaw = particles[:, 2]
    if model == "omni":
        bearing = math.atan2(dy, dx) if trans > 0 else 0.0
        sd_t = math.sqrt(a3 * trans**2 + a1 * dth**2)
        sd_r = math.sqrt(a4 * dth**2 + a2 * trans**2)
        sd_s = math.sqrt(a1 * dth**2 + a5 * trans**2)
        # in place, each operation as the expressions trans + z sd_t, ..., x + (t cb + s sb), y + (t sb - s cb),
        # wrap(yaw + r) round it (a sum or product in either order is the same number)
        t_hat = rng.normal(0.0, 1.0, n)
        t_hat *= sd_t
        t_hat += trans
        r_hat = rng.normal(0.0, 1.0, n)
        r_hat *= sd_r
        r_hat += dth
        s_hat = rng.normal(0.0, 1.0, n)
        s_hat *= sd_s
        b = yaw + bearing
        cb, sb = np.cos(b), np.sin(b)
        tmp = t_hat * sb
        t_hat *= cb
        sb *= s_hat
        t_hat += sb
        out[:, 0] += t_hat
        s_hat *= cb
        tmp -= s_hat
        out[:, 1] += tmp
        r_hat += yaw
        out[:, 2] = _wrap_in_place(r_hat)
        return out
    rot1 = 0.0 if trans < 0.01 else math.atan2(dy, dx)
    rot2 = float(wrap_angle(dth - rot1))
    # nav2: noise from the smaller of the forward and backward rotation (reversing robots)
    r1n = min(abs(float(wrap_angle(rot1))), abs(float(wrap_angle(rot1 - math.pi))))
    r2n = min(abs(float(wrap_angle(rot2))), abs(float(wrap_angle(rot2 - math.pi))))
    r1_hat = rot1 - rng.normal(0.0, 1.0, n) * math.sqrt(a1 * r1n**2 + a2 * trans**2)
    t_hat = trans - rng.normal(0.0, 1.0, n) * math.sqrt(a3 * trans**2 + a4 * r1n**2 + a4 * r2n**2)
    r2_hat = rot2 - rng.normal(0.0, 1.0, n) * math.sqrt(a1 * r2n**2 + a2 * trans**2)
    out[:, 0] += t_hat * np.cos(yaw + r1_hat)
    out[:, 1] += t_hat * np.sin(yaw + r1_hat)
    out[:, 2] = wrap_angle(yaw + r1_hat + r2_hat)
    return out


def kld_limit(k: NDArray[Any] | int, pf_err: float, pf_z: float, n_min: int, n_max: int) -> NDArray[np.int64]:
    """nav2 ``pf_resample_limit``: particles needed for ``k`` occupied histogram bins."""
    kk = np.asarray(k, dtype=float)
    km1 = np.maximum(kk - 1.0, 1.0)
    b = 2.0 / (9.0 * km1)
    x = 1.0 - b + np.sqrt(b) * pf_z
    n = np.ceil(km1 / (2.0 * pf_err) * x**3)
    n = np.where(kk <= 1, n_max, n)
    return np.clip(n, n_min, n_max).astype(np.int64)


def systematic_resample(weights: FloatArray, n: int, rng: np.random.Generator) -> NDArray[np.int64]:
    """Low-variance (systematic) resampling: ``n`` indices drawn with one random offset."""
    return _systematic(_normalized_cdf(weights), n, rng.random())


def _normalized_cdf(weights: FloatArray) -> FloatArray:
    """The cumulative sum of ``weights`` divided by its last value (what :func:`systematic_resample` draws from)."""
    c = np.cumsum(weights)
    c /= c[-1]
    return c


@njit(cache=True)
def _systematic(cdf, n, offset):  # pragma: no cover - compiled
    """:func:`systematic_resample`'s ``n`` indices into the normalized ``cdf`` for the random ``offset`` in [0, 1):
    ``min(searchsorted(cdf, (k + offset) / n, side="right"), len(cdf) - 1)`` for ``k < n``, the keys rising, in
    one walk along ``cdf`` (a NaN in it, where the cumulative sum overflowed, compares as numpy's search
    orders it: above every number)."""
    m = cdf.shape[0]
    out = np.empty(n, dtype=np.int64)
    i = 0
    for k in range(n):
        u = (float(k) + offset) / n
        while i < m and cdf[i] <= u:
            i += 1
        out[k] = i if i < m - 1 else m - 1
    return out


def _wrap_in_place(a: FloatArray) -> FloatArray:
    """``a`` (a float array of its own) wrapped to ``[-pi, pi)`` in place: :func:`fgloc.geometry.wrap_angle`'s
    operations, without its temporaries."""
    a += np.pi
    np.remainder(a, 2.0 * np.pi, out=a)
    a -= np.pi
    return a


def wall_surface_field(walls: NDArray[np.bool_], resolution: float, max_dist: float, depth_m: float = 0.0,
                       distance: FloatArray | None = None) -> FloatArray:
    """Signed distance (m) from each cell centre to the wall surface: positive in free space, negative
    inside walls, clipped to ``[-max_dist, max_dist]``.

    Outside: the distance to the nearest wall cell centre minus half a cell; inside: minus the distance to
    the nearest non-wall cell centre less half a cell.  Bilinear interpolation between a wall cell and its
    free neighbour then crosses zero on the face between them (an unsigned field clipped at zero would put
    the minimum on the wall cell's centre, half a cell deep, and leave the inside of thick walls flat: beam
    endpoints pulled into the walls, the pose towards the walls the laser sees).  ``depth_m`` moves the
    surface that far into the walls (half a cell: through the boundary cells' centres).  ``distance``: the
    distance (m) from each cell centre to the nearest wall cell centre when the caller has it (the map's
    distance field, when the walls are its occupied cells).  The distances are the native matcher's exact
    transform (:func:`fgloc.frontends.native.distance_m`: scipy's ``distance_transform_edt`` bit for bit); the
    inside, the signs and the clip in one pass over the wall cells (:func:`fgloc.frontends.native.signed_field`:
    a wall is a few cells thick, the transform of the free cells would visit the whole grid).
    """
    w = np.ascontiguousarray(walls, dtype=bool)
    if not w.any():
        return np.full(w.shape, float(max_dist))
    if w.all():
        return np.full(w.shape, float(np.clip(-float(max_dist) + float(depth_m), -max_dist, max_dist)))
    dist = distance_m(w, resolution) if distance is None else np.ascontiguousarray(distance, dtype=float)
    out = np.empty(w.shape)
    signed_field(w, dist, out, float(resolution), float(depth_m), float(max_dist))
    return out


def weighted_mean_cov(p: FloatArray, w: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Weighted mean (circular for yaw) and 3x3 covariance of particles ``(N, 3)``."""
    w = w / w.sum()
    mean = np.empty(3)
    mean[:2] = w @ p[:, :2]
    mean[2] = math.atan2(float(w @ np.sin(p[:, 2])), float(w @ np.cos(p[:, 2])))
    d = p - mean
    d[:, 2] = wrap_angle(d[:, 2])
    cov = (d * w[:, None]).T @ d
    return mean, 0.5 * (cov + cov.T)


@dataclass(frozen=True)
class AMCLConfig:
    """``frontends.amcl``: the particle filter (nav2_amcl names and units: rad where nav2 has rad).

    The defaults are here and only here (nav2_amcl's where sensible; see the docs).
    """

    robot_model_type: str = setting("omni", "motion model: omni (nav2 OmniMotionModel, mecanum) | differential",
                                    choices=("omni", "differential"))
    alpha1: float = setting(0.05, "rotation noise from rotation (nav2 0.2 for all five)", min=0)
    alpha2: float = setting(0.05, "rotation noise from translation", min=0)
    alpha3: float = setting(0.05, "translation noise from translation", min=0)
    alpha4: float = setting(0.05, "translation noise from rotation", min=0)
    alpha5: float = setting(0.05, "strafe noise from translation (omni only)", min=0)
    laser_model_type: str = setting("likelihood_field_prob", "prod pz (log space, tempered); likelihood_field = "
                                    "nav2's 1 + sum pz^3", choices=("likelihood_field", "likelihood_field_prob"))
    z_hit: float = setting(0.5, "pz = z_hit exp(-z^2 / 2 sigma_hit^2) + z_rand / range_max", min=0)
    z_rand: float = setting(0.5, "see z_hit", min=0)
    sigma_hit: float = setting(0.05, "m (nav2 0.2)", gt=0)
    laser_max_beams: int = setting(60, "valid beams kept, evenly strided; +inf/-inf/NaN/0 dropped (REP 117)", min=1)
    laser_likelihood_max_dist: float = setting(2.0, "m, distance-field clip; endpoints off the grid get this", gt=0)
    laser_max_range: float = setting(-1.0, "m; <= 0: the scan's range_max (for z_rand)")
    beam_correlation: float = setting(8.0, "likelihood_field_prob: log-likelihood divided by this", gt=0)
    surface_depth_cells: float | Literal["auto"] = setting(
        "auto", "where the wall surface lies behind the wall cells' faces, in cells: 0 = on the faces (scans ray "
        "cast on the grid), 0.5 = through the boundary cells' centres (SLAM maps, rasterized worlds); auto = start "
        "at 0.5 and learn it from the refined fixes' signed residuals")
    depth_window: int = setting(100, "auto surface depth: running mean over this many refined fixes", min=1)
    field_walls: str = setting("occupied", "cells the likelihood field measures distance to (occupied+unknown_edge: "
                               "maps storing walls as grey pixels)", choices=("occupied", "occupied+unknown_edge"))
    min_particles: int = setting(500, "KLD sampling lower bound", min=1)
    max_particles: int = setting(2000, "KLD sampling upper bound", min=1)
    global_particles: int = setting(60000, "reset(None): uniform over free cells", min=1)
    global_sigma_hit: float = setting(0.2, "m: sigma_hit until the cloud is one blob", gt=0)
    pf_err: float = setting(0.05, "KLD error bound", gt=0)
    pf_z: float = setting(0.99, "KLD normal quantile, used directly as nav2 does", gt=0)
    kld_bin_xy: float = setting(0.5, "m", gt=0)
    kld_bin_yaw_deg: float = setting(10.0, "KLD histogram heading bin", gt=0)
    resample_interval: int = setting(1, "low-variance (systematic) resampling every N updates", min=1)
    recovery_alpha_slow: float = setting(0.0, "augmented MCL; 0 = off (nav2 default)", min=0)
    recovery_alpha_fast: float = setting(0.0, "augmented MCL; 0 = off", min=0)
    update_min_d: float = setting(0.1, "m of odometry motion before a filter update (nav2 0.25)", min=0)
    update_min_a: float = setting(0.2, "rad of odometry rotation before a filter update (nav2 units)", min=0)
    init_cov: tuple[float, float, float] = setting((0.25, 0.25, 0.0685), "reset(pose) without cov (m^2, m^2, rad^2)",
                                                   min=0)
    converged_cluster_weight: float = setting(
        0.9, "a fix needs this share of the weight in one connected cluster of the filter's own KLD bins "
        "(otherwise 'not converged'); the global phase also ends only when its bins need <= max_particles",
        gt=0, max=1)
    estimate: str = setting(
        "refined", "the fix: mean = weighted mean of the heaviest cluster (nav2); refined = that mean moved to "
        "the maximum of the configured sensor model on this scan (kept within 3 sigma of the cluster)",
        choices=("mean", "refined"))
    refine_scale: str = setting(
        "sigma_hit", "the refinement's sensor-model sigma: sigma_hit (the filter's) or measured = then refitted with "
        "the sigma this scan's inlier residuals show (maximum likelihood, at least the map raster's res/sqrt(12); "
        "likelihood_field_prob only): beams on furniture moved since mapping stop pulling the fix",
        choices=("sigma_hit", "measured"))
    fix_without_update: bool = setting(False, "thresholds not met -> no fix (true: the propagated estimate)")
    cov_scale: float = setting(0.25, "output cov = cov_scale * cluster cov + diag(cov_floor)", gt=0)
    cov_floor: tuple[float, float, float] = setting((0.0, 0.0, 0.0), "m^2, m^2, rad^2 added", min=0)
    min_valid_beams: int = setting(10, "fewer valid beams -> no fix", min=1)
    deskew: bool = setting(True, "per-beam de-skew from the odometry motion")
    unknown_motion_sigma: tuple[float, float] = setting(
        (1.0, 1.0), "without odometry (scans alone): the cloud's random walk between updates (m/s, rad/s); it "
        "updates every update_min_d / the first of them seconds", gt=0)
    seed: int = setting(0, "random seed of the filter")


class AMCL:
    """Adaptive Monte Carlo localization front-end (``name = "amcl"``); see the module docstring."""

    name = "amcl"
    is_particle_filter = True  # capabilities the localizer reads (see fgloc.frontends.base.FrontendBase)
    supports_global = True

    def __init__(
        self,
        occ_map: OccupancyMap,
        laser_mount: StaticTransform | None = None,
        config: AMCLConfig | None = None,
        **overrides: Any,
    ) -> None:
        conf = with_overrides(AMCLConfig, config, overrides)
        self.config = conf
        if conf.robot_model_type not in ("differential", "omni"):
            raise ConfigError(f"amcl: robot_model_type must be differential or omni, got {conf.robot_model_type!r}")
        if conf.laser_model_type not in ("likelihood_field", "likelihood_field_prob"):
            raise ConfigError(f"amcl: laser_model_type must be likelihood_field or likelihood_field_prob, "
                              f"got {conf.laser_model_type!r}")
        if not (0 < conf.min_particles <= conf.max_particles) or conf.global_particles < 1:
            raise ConfigError(f"amcl: need 0 < min_particles <= max_particles and global_particles > 0, got "
                              f"{conf.min_particles}, {conf.max_particles}, {conf.global_particles}")
        if min(conf.sigma_hit, conf.global_sigma_hit, conf.beam_correlation) <= 0 \
                or min(conf.laser_max_beams, conf.resample_interval) < 1:
            raise ConfigError("amcl: sigma_hit, global_sigma_hit, beam_correlation > 0, laser_max_beams >= 1, "
                              "resample_interval >= 1 required")
        if conf.pf_err <= 0 or conf.kld_bin_xy <= 0 or conf.kld_bin_yaw_deg <= 0:
            raise ConfigError("amcl: pf_err, kld_bin_xy and kld_bin_yaw_deg must be positive")
        self.map = occ_map
        self.laser_mount = laser_mount
        self.robot_model_type = conf.robot_model_type
        self.alphas = np.array([conf.alpha1, conf.alpha2, conf.alpha3, conf.alpha4, conf.alpha5], dtype=float)
        self.laser_model_type = conf.laser_model_type
        self.z_hit, self.z_rand, self.sigma_hit = float(conf.z_hit), float(conf.z_rand), float(conf.sigma_hit)
        self.laser_max_beams = int(conf.laser_max_beams)
        self.max_dist = float(conf.laser_likelihood_max_dist)
        self.laser_max_range = float(conf.laser_max_range)
        self.beam_correlation = float(conf.beam_correlation)
        self.min_particles, self.max_particles = int(conf.min_particles), int(conf.max_particles)
        self.global_particles = int(conf.global_particles)
        self.global_sigma_hit = float(conf.global_sigma_hit)
        self.pf_err, self.pf_z = float(conf.pf_err), float(conf.pf_z)
        self.kld_bin = np.array([conf.kld_bin_xy, conf.kld_bin_xy, np.radians(conf.kld_bin_yaw_deg)], dtype=float)
        self.resample_interval = int(conf.resample_interval)
        self.alpha_slow, self.alpha_fast = float(conf.recovery_alpha_slow), float(conf.recovery_alpha_fast)
        self.update_min_d, self.update_min_a = float(conf.update_min_d), float(conf.update_min_a)
        self.unknown_motion_sigma = tuple(float(v) for v in conf.unknown_motion_sigma)
        self.init_cov = np.diag(np.asarray(conf.init_cov, dtype=float).reshape(3))
        self.converged_cluster_weight = float(conf.converged_cluster_weight)
        self.estimate = conf.estimate
        self._n_yaw_bins = max(int(math.ceil(2.0 * math.pi / self.kld_bin[2] - 1e-9)), 1)
        self.fix_without_update = bool(conf.fix_without_update)
        self.cov_scale = float(conf.cov_scale)
        self.refine_scale = str(conf.refine_scale)
        self.cov_floor = np.diag(np.asarray(conf.cov_floor, dtype=float).reshape(3))
        self.rng = np.random.default_rng(conf.seed)
        self.pre = ScanPreprocessor(
            laser_mount, PreprocessOptions(max_beams=self.laser_max_beams, deskew=bool(conf.deskew),
                                           min_valid_beams=int(conf.min_valid_beams)))
        if conf.field_walls == "occupied":
            walls = np.asarray(occ_map.occupied, dtype=bool)
        elif conf.field_walls == "occupied+unknown_edge":
            from scipy.ndimage import binary_dilation

            walls = occ_map.occupied | (occ_map.unknown & binary_dilation(occ_map.free, np.ones((3, 3), bool)))
        else:
            raise ConfigError(f"amcl: field_walls must be occupied or occupied+unknown_edge, got {conf.field_walls!r}")
        self._field = wall_surface_field(walls, occ_map.resolution, self.max_dist, distance=(
            map_distance_field(occ_map) if conf.field_walls == "occupied" else None))
        self.auto_depth = isinstance(conf.surface_depth_cells, str)
        if self.auto_depth and conf.surface_depth_cells != "auto":
            raise ConfigError(f"amcl: surface_depth_cells must be a number of cells or auto, got "
                              f"{conf.surface_depth_cells!r}")
        #: m: the wall surface behind the wall cells' faces (learnt from the fixes in auto mode; a map
        #: property, kept across reset())
        self.depth_m = 0.5 * occ_map.resolution if self.auto_depth else \
            float(conf.surface_depth_cells) * occ_map.resolution  # type: ignore[arg-type]
        self.depth_window = int(conf.depth_window)
        self._depth_updates = 0
        self._free = occ_map.free_cell_centers()
        self._table_key: tuple[int, float, float] | None = None
        self._last_refine: tuple[Any, ...] | None = None
        self._refined_cov = np.eye(3)
        self._table = np.zeros(2)
        self._table_inv_step = 1.0
        self.particles = np.zeros((0, 3))
        self.weights = np.zeros(0)
        self.initialized = False
        self._global = False
        self._w_slow = 0.0
        self._w_fast = 0.0
        self._acc = np.zeros(3)
        self._blind_s = 0.0  # s since the last update with no odometry (unknown motion)
        self._scan_t: float | None = None  # the previous scan's stamp
        self._force_update = True
        self._n_updates = 0
        self.last_kld_k = 0
        # after the global phase: the last unconfirmed fix (pose, covariance), or None once confirmed
        self._settling: tuple[FloatArray, FloatArray] | None = None
        self._settle = False

    # ------------------------------------------------------------------ config
    @classmethod
    def from_config(cls, occ_map: OccupancyMap, laser_mount: StaticTransform | None,
                    config: AMCLConfig | Mapping[str, Any] | None = None) -> AMCL:
        """Build from the ``frontends.amcl`` section (typed, or a mapping checked like YAML)."""
        if config is None or isinstance(config, AMCLConfig):
            return cls(occ_map, laser_mount, config)
        return cls(occ_map, laser_mount, parse(AMCLConfig, config, where="frontends.amcl"))

    # ------------------------------------------------------------------ state
    def reset(self, pose: np.ndarray | None = None, cov: np.ndarray | None = None) -> None:
        """Re-initialise: Gaussian around ``pose`` (``cov`` or ``init_cov``), or ``None`` = global."""
        self.pre.reset()
        self._w_slow = self._w_fast = 0.0
        self._acc = np.zeros(3)
        self._blind_s = 0.0
        self._force_update = True
        self._n_updates = 0
        self._settling, self._settle = None, False
        if pose is None:
            self.particles = self._random_free(self.global_particles)
            self._global = True
        else:
            p = np.asarray(pose, dtype=float).reshape(3)
            c = self.init_cov if cov is None else np.asarray(cov, dtype=float).reshape(3, 3)
            n = self.max_particles
            self.particles = p + self.rng.multivariate_normal(np.zeros(3), c, n, method="eigh")
            self.particles[:, 2] = wrap_angle(self.particles[:, 2])
            self._global = False
        self.weights = np.full(len(self.particles), 1.0 / len(self.particles))
        self.initialized = True

    def _random_free(self, n: int) -> FloatArray:
        if len(self._free) == 0:
            raise ConfigError("amcl: the map has no free cells for global localization")
        idx = self.rng.integers(0, len(self._free), n)
        half = 0.5 * self.map.resolution
        out = np.empty((n, 3))
        out[:, :2] = self._free[idx] + self.rng.uniform(-half, half, (n, 2))
        out[:, 2] = self.rng.uniform(-np.pi, np.pi, n)
        return out

    # ------------------------------------------------------------------ filter steps
    def _likelihood(self, pts: FloatArray, range_max: float) -> FloatArray:
        rmax = self.laser_max_range if self.laser_max_range > 0 else range_max
        z_rand_mult = 1.0 / rmax if np.isfinite(rmax) and rmax > 0 else 0.0
        c, s = math.cos(self.map.origin[2]), math.sin(self.map.origin[2])
        p = self.particles
        if abs(s) > 1e-12:  # rotated map origin: express particles in the grid-aligned frame
            dx, dy = p[:, 0] - self.map.origin[0], p[:, 1] - self.map.origin[1]
            px, py, pyaw = c * dx + s * dy, -s * dx + c * dy, p[:, 2] - self.map.origin[2]
            ox = oy = 0.0
        else:
            px, py, pyaw = p[:, 0], p[:, 1], p[:, 2]
            ox, oy = float(self.map.origin[0]), float(self.map.origin[1])
        sigma = self.global_sigma_hit if self._global else self.sigma_hit
        model = 0 if self.laser_model_type == "likelihood_field" else 1
        key = (model, sigma, self.z_rand * z_rand_mult)
        if self._table_key != key:
            self._table, self._table_inv_step = beam_term_table(model, self.z_hit, key[2], sigma, self.max_dist)
            self._table_key = key
        acc = _weights_kernel(
            np.ascontiguousarray(px), np.ascontiguousarray(py), np.ascontiguousarray(pyaw),
            np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1]), self._field, self.depth_m,
            ox, oy, 1.0 / self.map.resolution, self.max_dist, self._table, self._table_inv_step)
        # nav2 likelihood_field: w = 1 + sum pz^3; likelihood_field_prob: tempered sum of log pz
        return acc + 1.0 if model == 0 else acc / self.beam_correlation

    def _bins(self, particles: FloatArray) -> NDArray[np.int64]:
        """Each particle's KLD histogram bin ``floor(p / kld_bin)`` (heading not wrapped)."""
        return bin_keys(np.ascontiguousarray(particles, dtype=float), self.kld_bin)  # type: ignore[no-any-return]

    def _resample(self, bins: NDArray[np.int64] | None = None) -> None:
        """KLD resampling; ``bins``: :meth:`_bins` of the particles when the caller has them."""
        cdf = _normalized_cdf(self.weights)
        cap = self.global_particles if self._global else self.max_particles
        cap = max(cap, self.min_particles)
        # KLD: draw cap candidates, visit them in random order and stop once the count
        # reaches the limit for the histogram bins seen so far (nav2 pf_update_resample)
        draws = _systematic(cdf, cap, self.rng.random())
        order = self.rng.permutation(cap)
        n_min = self.max_particles if self._global else self.min_particles
        n, k_n = kld_count(self._bins(self.particles) if bins is None else bins, draws, order, self.pf_err,
                            self.pf_z, n_min, cap)
        if n < n_min:  # (the limit is clipped to n_min, so this only guards the rule's contract)
            n = n_min
        self.last_kld_k = int(k_n)
        new = self.particles[_systematic(cdf, n, self.rng.random())]
        if self.alpha_slow > 0 and self.alpha_fast > 0 and self._w_slow > 0:
            p_rand = max(0.0, 1.0 - self._w_fast / self._w_slow)
            if p_rand > 0:
                inject = self.rng.random(n) < p_rand
                if inject.any():
                    new[inject] = self._random_free(int(inject.sum()))
                    self._w_slow = self._w_fast = 0.0  # nav2 resets the averages after injecting
        self.particles = new
        self.weights = np.full(n, 1.0 / n)
        if self._global:
            # the global phase ends once the posterior is one mode small enough for the tracking
            # filter: its histogram bins need at most max_particles (KLD) and one connected cluster
            # of them holds converged_cluster_weight of the particles
            need = int(kld_limit(self.last_kld_k, self.pf_err, self.pf_z, 1, 2**62))
            if need <= self.max_particles and self._cluster(self.particles, self.weights)[1] \
                    >= self.converged_cluster_weight:
                self._global = False
                self._settle = True

    # ------------------------------------------------------------------ front-end API
    def match(self, scan: LaserScan, guess: np.ndarray, odom_delta: np.ndarray | None = None) -> MatchResult:
        """One scan: motion update by ``odom_delta``, sensor update and resampling when due."""
        try:
            return self._match(scan, guess, odom_delta)
        except Exception as e:  # never raise on bad input: report it as a no-fix
            return no_fix(f"amcl: internal error ({e.__class__.__name__}: {e})")

    def _match(self, scan: LaserScan, guess: np.ndarray, odom_delta: np.ndarray | None) -> MatchResult:
        if not self.initialized:
            g, why = check_guess(self.map, guess)
            if g is None:
                return no_fix(f"amcl not initialised: {why}")
            self.reset(g)
        od = None
        if odom_delta is not None:
            od = np.asarray(odom_delta, dtype=float).reshape(-1)
            if od.shape != (3,) or not all(math.isfinite(v) for v in od.tolist()):
                return no_fix("odometry delta is not a finite [dx, dy, dyaw]")
            # the filter moves with the odometry even when the scan is unusable
            self._acc = compose1(self._acc, od)
        elif self._scan_t is not None and float(scan.stamp) > self._scan_t:
            self._blind_s += float(scan.stamp) - self._scan_t  # no odometry: motion unknown for this long
        self._scan_t = float(scan.stamp)
        pts, why = self.pre(scan, od)
        if pts is None:
            return no_fix(why)
        moved_d = math.hypot(self._acc[0], self._acc[1])
        moved_a = abs(float(self._acc[2]))
        blind = self._blind_s
        if not (self._force_update or moved_d >= self.update_min_d or moved_a >= self.update_min_a
                or blind * self.unknown_motion_sigma[0] >= self.update_min_d):
            if not self.fix_without_update:
                return no_fix(f"waiting for motion (update_min_d {self.update_min_d:g} m / update_min_a "
                              f"{self.update_min_a:g} rad not reached: moved {moved_d:.3f} m, {moved_a:.3f} rad since "
                              "the last update)", n_inliers=len(pts))
            mask, share = self._cluster(self.particles, self.weights)
            mean, cov = self._cluster_mean_cov(mask)
            return self._result(compose1(mean, self._acc), cov, share, len(pts), updated=False)
        moved = self._acc
        a0, a1, a2 = self._acc.tolist()
        if a0 != 0 or a1 != 0 or a2 != 0:
            self.particles = sample_motion(self.particles, self._acc, self.robot_model_type, self.alphas,
                                           self.rng)
        if blind > 0:
            self.particles = diffuse(self.particles, blind, self.unknown_motion_sigma, self.rng)
        self._acc = np.zeros(3)
        self._blind_s = 0.0
        self._force_update = False
        lik = self._likelihood(pts, float(scan.range_max))
        recovery = self.alpha_slow > 0 and self.alpha_fast > 0
        mean_lik = 0.0
        if self.laser_model_type == "likelihood_field":
            w_raw = self.weights * lik
            if recovery:
                mean_lik = float(np.mean(lik))
        else:
            mx = float(np.max(lik))
            w_raw = lik - mx
            np.exp(w_raw, out=w_raw)
            w_raw *= self.weights
            if recovery:
                mean_lik = float(np.mean(np.exp(lik / max(len(pts), 1))))  # per-beam geometric mean
        total = float(w_raw.sum())
        if not math.isfinite(total) or total <= 0:
            self.weights = np.full(len(self.particles), 1.0 / len(self.particles))
        else:
            w_raw /= total
            self.weights = w_raw
        if recovery:
            if self._w_slow == 0.0:
                self._w_slow = self._w_fast = mean_lik
            else:
                self._w_slow += self.alpha_slow * (mean_lik - self._w_slow)
                self._w_fast += self.alpha_fast * (mean_lik - self._w_fast)
        # the estimate: the heaviest connected cluster of the weighted cloud (nav2 publishes the same)
        bins = self._bins(self.particles)
        mask, share = self._cluster(self.particles, self.weights, bins)
        mean, cov = self._cluster_mean_cov(mask)
        was_global = self._global
        self._n_updates += 1
        if self._n_updates % self.resample_interval == 0:
            self._resample(bins)
        refined = False
        if self.estimate == "refined" and not self._global:
            # also on the update that ended the global phase: its cluster was weighed with global_sigma_hit
            if was_global:
                mask, share = self._cluster(self.particles, self.weights)
                mean, cov = self._cluster_mean_cov(mask)
            mean, refined = self._refine(mean, cov, pts, float(scan.range_max))
        res = self._result(mean, cov, share, len(pts), updated=True, refined=refined)
        if self._settle and res.ok:
            return self._confirmed(res, moved, blind)
        return res

    def _confirmed(self, res: MatchResult, moved: FloatArray, blind_s: float = 0.0) -> MatchResult:
        """After the global phase the cloud can still hold two nearby modes in one connected cluster (KLD bins
        apart): a fix is given once two consecutive ones (refined, with ``estimate: refined``) agree as the
        odometry says (chi-square, 3 dof, 99.7 %, over both fixes' covariances and the motion model's noise for
        the motion between them)."""
        assert res.pose is not None and res.cov is not None
        if self.estimate == "refined" and not res.info.get("refined"):  # the cloud's mean: too wide to confirm by
            self._settling = None
            return no_fix("not converged (after global localization: the scan fit was not kept)",
                          n_inliers=res.n_inliers, **res.info)
        prev, self._settling = self._settling, (np.array(res.pose, dtype=float), np.array(res.cov, dtype=float))
        if prev is None:
            return no_fix("not converged (the first fix after global localization, to be confirmed by the next)",
                          n_inliers=res.n_inliers, **res.info)
        a1, a2, a3, a4, _a5 = (float(a) for a in self.alphas)
        trans, rot = math.hypot(float(moved[0]), float(moved[1])), abs(float(wrap_angle(moved[2])))
        var_xy, var_yaw = a3 * trans**2 + a4 * rot**2, a1 * rot**2 + a2 * trans**2
        if blind_s > 0:  # no odometry: the random walk the cloud was spread by
            var_xy += (self.unknown_motion_sigma[0] * blind_s) ** 2
            var_yaw += (self.unknown_motion_sigma[1] * blind_s) ** 2
        d = res.pose - compose1(prev[0], moved)
        d[2] = wrap_angle(d[2])
        s = prev[1] + res.cov + np.diag([var_xy, var_xy, var_yaw]) + 1e-12 * np.eye(3)
        m2 = float(d @ np.linalg.solve(s, d))
        if not m2 <= 14.16:
            return no_fix(f"not converged (consecutive fixes after global localization disagree by "
                          f"{math.hypot(d[0], d[1]):.2f} m, {math.degrees(abs(d[2])):.1f} deg)",
                          n_inliers=res.n_inliers, **res.info)
        self._settling, self._settle = None, False
        return res

    def _cluster(self, particles: FloatArray, weights: FloatArray, bins: NDArray[np.int64] | None = None
                 ) -> tuple[NDArray[np.bool_], float]:
        """The particles of the heaviest connected cluster of KLD bins and its share of the weight;
        ``bins``: :meth:`_bins` of ``particles`` when the caller has them (left unchanged)."""
        keys = self._bins(particles) if bins is None else bins.copy()
        keys[:, 2] %= self._n_yaw_bins
        labels, wsum = bin_clusters(keys, weights, self._n_yaw_bins)
        best = int(np.argmax(wsum))
        total = float(wsum.sum())
        return labels == best, (float(wsum[best]) / total if total > 0 else 0.0)

    def _cluster_mean_cov(self, mask: NDArray[np.bool_]) -> tuple[FloatArray, FloatArray]:
        """:func:`weighted_mean_cov` of the particles in ``mask`` (all of them without a copy when it holds all)."""
        if mask.all():
            return weighted_mean_cov(self.particles, self.weights)
        return weighted_mean_cov(self.particles[mask], self.weights[mask])

    def _refine(self, mean: FloatArray, cov: FloatArray, pts: FloatArray, range_max: float
                ) -> tuple[FloatArray, bool]:
        """``mean`` moved to the maximum of the configured sensor model's score of this scan
        (:func:`_refine_kernel`); kept only within 3 sigma (chi2, 3 dof, 99.7 %) of the cluster."""
        rmax = self.laser_max_range if self.laser_max_range > 0 else range_max
        z_rand_mult = self.z_rand / rmax if math.isfinite(rmax) and rmax > 0 else 0.0
        o0, o1, o2 = self.map.origin.tolist()
        m0, m1, m2 = mean.tolist()
        c, s = math.cos(o2), math.sin(o2)
        dx, dy = m0 - o0, m1 - o1
        start = np.array([c * dx + s * dy, -s * dx + c * dy, m2 - o2])  # grid-aligned frame
        model = 0 if self.laser_model_type == "likelihood_field" else 1
        bx, by = np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1])
        p, H, wr2, sw, n_runs, swf = _refine_kernel(self._field, self.depth_m, 0.0, 0.0, 1.0 / self.map.resolution,
                                                    self.max_dist, bx, by, start, self.z_hit, z_rand_mult,
                                                    self.sigma_hit, model, 20)
        if self.refine_scale == "measured" and model == 1:  # EM needs the likelihood (prod pz) model
            p, H, wr2, sw, n_runs, swf = self._refit_measured(bx, by, z_rand_mult, model,
                                                              (p, H, wr2, sw, n_runs, swf))
        p0, p1, p2 = p.tolist()
        x, y, yaw = o0 + c * p0 - s * p1, o1 + s * p0 + c * p1, wrap_scalar(p2 + o2)
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(yaw)):
            return mean, False
        out = np.array([x, y, yaw])
        d = np.array([x - m0, y - m1, wrap_scalar(yaw - m2)])
        try:
            m2 = float(d @ np.linalg.solve(cov + 1e-12 * np.eye(3), d))
        except np.linalg.LinAlgError:
            return mean, False
        self._last_refine = (H, wr2, sw, c, s, n_runs)
        if m2 > 14.16 or n_runs < 1 or sw <= 3.0:
            return mean, False
        # its covariance from the scan itself: residual variance plus the map raster's
        # (uniform within a cell: res^2 / 12), shared by the beams of each run of neighbouring
        # endpoints (one wall stretch): (s^2 + res^2/12) (sum w / runs) H^-1, rotated to the map
        try:
            Hinv = np.linalg.inv(H)
        except np.linalg.LinAlgError:
            return mean, False
        var = wr2 / (sw - 3.0) + self.map.resolution ** 2 / 12.0
        rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        cov_r = var * (sw / n_runs) * (rot @ Hinv @ rot.T)
        if not (np.isfinite(cov_r).all() and (np.linalg.eigvalsh(0.5 * (cov_r + cov_r.T)) > 0).all()):
            return mean, False
        self._refined_cov = 0.5 * (cov_r + cov_r.T)
        if self.auto_depth:
            # the weighted mean signed residual says how far behind the modelled surface the beams end:
            # a running mean over the refined fixes (a property of the map)
            self._depth_updates += 1
            est = self.depth_m - swf / sw
            self.depth_m += (est - self.depth_m) / min(self._depth_updates, self.depth_window)
            self.depth_m = min(max(self.depth_m, 0.0), float(self.map.resolution))
        return out, True

    def _refit_measured(self, bx: FloatArray, by: FloatArray, z_rand_mult: float, model: int, fit: tuple
                        ) -> tuple:
        """The scan fit ``fit`` (with ``sigma_hit``) refitted by EM on the mixture's sigma: the inliers'
        weighted residual spread (at least the map raster's ``res / sqrt(12)``), approached by halving
        the sigma at most per round (annealed: a wide ``sigma_hit`` leaves the pose centimetres off, where
        the measured sigma alone would keep the wrong beams), then the pose again with it."""
        floor = self.map.resolution / math.sqrt(12.0)
        out = fit
        prev = self.sigma_hit
        for _ in range(REFINE_SCALE_ROUNDS):
            p, _H, wr2, sw, _n, _f = out
            if not (sw > 3.0 and np.isfinite(wr2)):
                break
            sigma = max(math.sqrt(wr2 / sw), floor, 0.5 * prev)
            if sigma >= prev:
                break
            prev = sigma
            out = _refine_kernel(self._field, self.depth_m, 0.0, 0.0, 1.0 / self.map.resolution, self.max_dist,
                                 bx, by, p, self.z_hit, z_rand_mult, sigma, model, 20)
        return out

    def _result(self, mean: FloatArray, cov: FloatArray, share: float, n_pts: int, updated: bool,
                refined: bool = False) -> MatchResult:
        sx = math.sqrt(max(float(np.linalg.eigvalsh(cov[:2, :2])[-1]), 0.0))
        sa = math.sqrt(max(float(cov[2, 2]), 0.0))
        # estimate / estimate_cov: the heaviest cluster's mean and covariance, also when it is no fix (what
        # nav2 publishes as amcl_pose from the first update on: the localizer starts from it, still lost)
        info: dict[str, Any] = {
                "particles": len(self.particles), "updated": updated, "std_xy": sx, "std_yaw": sa,
                "kld_bins": self.last_kld_k, "cluster_share": share, "refined": refined,
                "estimate": np.array(mean, dtype=float), "estimate_cov": np.array(cov, dtype=float)}
        if on_grid(self.map, float(mean[0]), float(mean[1])) is None:
            return no_fix(f"estimate ({mean[0]:.2f}, {mean[1]:.2f}) is off the map", n_inliers=n_pts, **info)
        if self._global:
            return no_fix(f"not converged (global localization: cloud std {sx:.2f} m, {math.degrees(sa):.0f} deg)",
                          n_inliers=n_pts, **info)
        if share < self.converged_cluster_weight:
            return no_fix(f"not converged ({100 * share:.0f} % of the weight in the heaviest cluster)",
                          n_inliers=n_pts, **info)
        # refined: the covariance of the scan fit (see _refine); else the cluster's, however
        # wide: the back-end weighs the fix by it
        out_cov = (self._refined_cov if refined else self.cov_scale * cov) + self.cov_floor
        return MatchResult(True, mean, out_cov, quality=float(share), n_inliers=n_pts, info=info)


#: the defaults as a plain mapping (derived from :class:`AMCLConfig`)
AMCL_DEFAULTS: dict[str, Any] = to_dict(AMCLConfig())
