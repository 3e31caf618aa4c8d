"""The native 2-D scan-to-map matcher: correlative search + robust Gauss-Newton on a distance field.

Pipeline for one scan (points already de-skewed in ``base_link``, see :mod:`.base`):

1. **Refine from the guess**: Levenberg-Marquardt on point-to-distance-field
   residuals ``r_i = D(R p_i + t)``, ``D`` the bilinear-interpolated, *surface
   corrected* distance field of the map (below), with an annealed robust kernel
   (Huber or Cauchy; scale shrinking over ``kernel_schedule_m``) and analytic
   Jacobians ``dr/d[x, y, yaw] = grad D^T [I | dR/dyaw p]``.  Compiled with numba.
   Points whose field gradient points away from the laser (the back face of a thin
   wall, which the beam could not have reached) are ignored (``backface_cos``).
2. **Correlative search** (``search: auto`` when the refinement looks wrong, ``always``,
   or ``never``): every pose on a grid over the window ``+-search_window_m`` /
   ``+-search_window_deg`` around the guess is scored on a Gaussian likelihood field
   ``exp(-D^2 / 2 sigma^2)`` with a subsample of the points; the best
   ``search_candidates`` (distinct) poses are refined as in 1 and the lowest-cost wins.
3. **Checks**: too few inliers, degenerate Hessian, a jump from the guess beyond
   ``max_jump_m`` / ``max_jump_deg`` -> no fix with a reason.
4. **Covariance**: ``S s^2 (sum w / runs) (J^T W J)^-1 S + spread + diag(cov_floor)`` with
   ``s^2 = sum w r^2 / (sum w - 3)`` the weighted residual variance.  The plain Hessian
   covariance ``s^2 (J^T W J)^-1`` assumes independent beams; but the beams that hit one
   stretch of wall share that stretch's map error (raster, wall thickness, a wall that
   moved), so the independent units are *runs*: the used points in scan order, cut where
   neighbours are more than ``gridmath.RUN_GAP_M`` apart or a run exceeds ``RUN_LENGTH_M``; the
   variance is multiplied by the beams per run.  No constant is fitted: NEES 2.6 on the
   simulated paper run (was 2.7 with per-axis factors 5.3 / 9.5 calibrated on it).
   ``spread``: refined candidates of the correlative search that explain the scan nearly
   as well widen the covariance to cover them (weights ``exp(-dcost / (s^2 sum w / runs))``).
   ``S = diag(sqrt(kxy), sqrt(kxy), sqrt(kyaw))``, ``cov_inflation = [kxy, kyaw]`` (1, 1):
   optional user factors.
   **Map registration floor** (:func:`registration_floor`): a map whose walls sit off in the map
   frame moves every fix with them, and the residuals cannot tell (they fit the shifted map).  On a
   SLAM map built from other passes (Radish intel / fr079 / aces segments vs the SLAM trajectory)
   the fixes were 2-3 cm off where the scan evidence says 6 mm: NEES 38-80.  So the map's accuracy
   (``map_accuracy_m``: the map YAML's ``accuracy_m``, which ``fgloc map`` writes from its
   self-check: the r.m.s. offset at which the passes register, and the raster, 3.3 cm on ACES; a
   map that declares none: no floor, ``base.map_accuracy``) less the raster's part
   (``base.registration_sigma``: a wall known to its cell differs from wall to wall, the residuals
   see it and the per-run term above carries it; the simulator's maps, their world rasterized, need
   no floor) is added, stretched along the scan's weak direction, over the points' moment arm in
   heading (``tools/eval_frontends_real.py``: see the README's real-map table); the simulator's map
   declares 0, its fixes keep NEES ~2.4-2.9.  With the floor the smoother weighs the CARMEN odometry more, whose
   pose-derived twist noise (``pipeline.pose_delta_*``) is tighter than that odometry: see the
   README's real-map table for the heading it costs.
5. **Heading check**: after the refinement from the guess, the likelihood-field score over
   heading (``+-heading_check_deg``) at the refined position; a peak elsewhere is refined too and
   the lower cost wins.  A guess several degrees off (intel's bursts of scan stamps) otherwise
   stays in a local minimum near its heading: fixes > 2 deg off on the intel segment 33 -> 9.

Where is the wall?  ``OccupancyMap.distance_field`` is the distance to the nearest
occupied cell *centre*.  The matcher's field is a signed distance to the occupied
cells' *faces* (the EDT of the occupancy grid upsampled ``field_upsample`` times,
minus half a fine cell; negative inside obstacles), shifted by
``surface_depth_cells``: 0 puts the surface on the faces (a map whose scans were
ray cast on the grid itself: a beam ends on the face of the first occupied cell),
0.5 (default) on the centres of the boundary cells (SLAM maps and rasterized worlds:
a cell is occupied because beam endpoints fall inside it, on average at its centre
line).  Either way the optimum is unbiased for that convention.

``quality`` is the inlier fraction (|r| < ``inlier_dist_m``) of the used points.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from fgloc.config.schema import section, setting, with_overrides
from fgloc.errors import ConfigError
from fgloc.geometry import YAW, wrap_scalar
from fgloc.gridmath import add_normal, bilinear_grad, mirror_upper, njit, run_step
from fgloc.maps import OccupancyMap
from fgloc.types import LaserScan, StaticTransform

from .base import (
    FixAcceptance,
    FloatArray,
    FrontendBase,
    MatchResult,
    PreprocessOptions,
    map_accuracy,
    no_fix,
    registration_floor,
    registration_sigma,
)

LOSS_HUBER = 0
LOSS_CAUCHY = 1

#: aliases (corridors with doors at regular spacing, shelf rows) are looked for this far along
#: the fix's least constrained direction, in steps of ALIAS_STEP_M; local maxima of the
#: likelihood-field score reaching ALIAS_SCORE_RATIO of the fix's are refined as candidates
ALIAS_RANGE_M = 2.0
ALIAS_STEP_M = 0.1
ALIAS_SCORE_RATIO = 0.7
ALIAS_STEPS = int(round(ALIAS_RANGE_M / ALIAS_STEP_M))


# ----------------------------------------------------------------- numba kernels
@njit(cache=True, fastmath=True)
def rho_weight(r, c, loss, outlier):  # pragma: no cover - compiled
    """Robust cost and IRLS weight of a residual."""
    a = abs(r)
    if a > outlier:
        if loss == 0:
            return c * (outlier - 0.5 * c), 0.0
        u = outlier / c
        return 0.5 * c * c * math.log(1.0 + u * u), 0.0
    if loss == 0:
        if a <= c:
            return 0.5 * r * r, 1.0
        return c * (a - 0.5 * c), c / a
    u = r / c
    q = u * u
    return 0.5 * c * c * math.log(1.0 + q), 1.0 / (1.0 + q)


@njit(cache=True, fastmath=True)
def point_residual(field, A, b, far, pose, cs, sn, x, y, lx, ly, backcos, off):  # pragma: no cover - compiled
    """Residual, map-frame field gradient and whether the point faces the sensor.

    ``(lx, ly)`` is the laser origin in base_link: a point whose field gradient points
    away from the laser (``cos > backcos``) lies on the back face of a wall that the
    beam could not have reached, and is not used.
    """
    qx = pose[0] + cs * x - sn * y
    qy = pose[1] + sn * x + cs * y
    u = A[0, 0] * qx + A[0, 1] * qy + b[0]
    v = A[1, 0] * qx + A[1, 1] * qy + b[1]
    r, du, dv = bilinear_grad(field, u, v, far)
    r += off
    gx = du * A[0, 0] + dv * A[1, 0]
    gy = du * A[0, 1] + dv * A[1, 1]
    bx = cs * (x - lx) - sn * (y - ly)
    by = sn * (x - lx) + cs * (y - ly)
    dot = gx * bx + gy * by
    if backcos >= 0.0:
        if dot <= 0.0:
            return r, gx, gy, True
        # cos = dot / (|g| |b|) > backcos  <=>  dot^2 > backcos^2 |g|^2 |b|^2 (for dot > 0): no sqrt
        return r, gx, gy, not (dot * dot > backcos * backcos * (gx * gx + gy * gy) * (bx * bx + by * by))
    nrm = math.sqrt((gx * gx + gy * gy) * (bx * bx + by * by))
    return r, gx, gy, not (nrm > 0.0 and dot > backcos * nrm)


@njit(cache=True, fastmath=True)
def lm_system(field, A, b, far, px, py, pose, c, loss, outlier, lx, ly, backcos, off, H, g):  # pragma: no cover
    """Fill H = J^T W J, g = J^T W r at ``pose``; return the robust cost (as :func:`rho_weight` sums it).

    The residuals of :func:`point_residual`, with the pose and the map-to-grid transform composed into
    one affine map per call (base_link point -> fine-grid coordinates) and the bilinear lookup
    inline: the LM's inner loop, 2x faster than calling :func:`point_residual` per point (same maths;
    results differ in the last bits).  The Cauchy cost ``c^2/2 sum log(1 + q)`` is summed as the
    log of running products over blocks of 64 points (each factor <= 1 + (outlier/c)^2, no
    overflow): one log per block instead of one per point.

    Two loops over the points: the field lookups first (value and gradient per point, a short
    loop body whose memory accesses overlap), then the back-face test, the robust weights and the
    sums in point order.  The same operations as one loop over both (the same bits: compared pass
    by pass on the office and paper runs' refinements), 15 % less time per pass.
    """
    cs = math.cos(pose[2])
    sn = math.sin(pose[2])
    # base_link point (x, y) -> fine-grid (u, v) = A (R(yaw) p + t) + b
    a00 = A[0, 0] * cs + A[0, 1] * sn
    a01 = A[0, 1] * cs - A[0, 0] * sn
    a02 = A[0, 0] * pose[0] + A[0, 1] * pose[1] + b[0]
    a10 = A[1, 0] * cs + A[1, 1] * sn
    a11 = A[1, 1] * cs - A[1, 0] * sn
    a12 = A[1, 0] * pose[0] + A[1, 1] * pose[1] + b[1]
    h, w = field.shape
    umax = w - 1.0
    vmax = h - 1.0
    n = px.shape[0]
    rs = np.empty(n)
    dus = np.empty(n)
    dvs = np.empty(n)
    for k in range(n):
        x = px[k]
        y = py[k]
        u = a00 * x + a01 * y + a02
        v = a10 * x + a11 * y + a12
        if u >= 0.0 and v >= 0.0 and u <= umax and v <= vmax:  # gridmath.bilinear_grad, inline
            x0 = int(u)
            y0 = int(v)
            if x0 > w - 2:
                x0 = w - 2
            if y0 > h - 2:
                y0 = h - 2
            fx = u - x0
            fy = v - y0
            d00 = field[y0, x0]
            d10 = field[y0, x0 + 1]
            d01 = field[y0 + 1, x0]
            d11 = field[y0 + 1, x0 + 1]
            ea = d10 - d00
            ec = d11 - d01
            r = d00 + fx * ea + fy * (d01 - d00 + fx * (ec - ea)) + off
            du = ea + fy * (ec - ea)
            dv = (d01 - d00) + fx * (d11 - d10 - d01 + d00)
        else:
            r = far + off
            du = 0.0
            dv = 0.0
        rs[k] = r
        dus[k] = du
        dvs[k] = dv
    h00 = h01 = h02 = h11 = h12 = h22 = 0.0
    g0 = g1 = g2 = 0.0
    cost = 0.0
    rho_out, _w = rho_weight(2.0 * outlier + 1.0, c, loss, outlier)
    inv_c2 = 1.0 / (c * c)
    bc2 = backcos * backcos
    prod = 1.0
    n_prod = 0
    for k in range(n):
        x = px[k]
        y = py[k]
        r = rs[k]
        du = dus[k]
        dv = dvs[k]
        gx = du * A[0, 0] + dv * A[1, 0]
        gy = du * A[0, 1] + dv * A[1, 1]
        # back face (as point_residual): the gradient pointing away from the laser
        bx = cs * (x - lx) - sn * (y - ly)
        by = sn * (x - lx) + cs * (y - ly)
        dot = gx * bx + gy * by
        if backcos >= 0.0:
            front = dot <= 0.0 or not (dot * dot > bc2 * (gx * gx + gy * gy) * (bx * bx + by * by))
        else:
            nrm = math.sqrt((gx * gx + gy * gy) * (bx * bx + by * by))
            front = not (nrm > 0.0 and dot > backcos * nrm)
        if not front:
            r = far  # a back-facing point counts at field_max_dist (real maps need it)
        if abs(r) > outlier:
            cost += rho_out
            continue
        if loss == 1:
            q1 = 1.0 + r * r * inv_c2
            prod *= q1
            n_prod += 1
            if n_prod == 64:
                cost += 0.5 * c * c * math.log(prod)
                prod = 1.0
                n_prod = 0
            wt = 1.0 / q1
        else:
            rho, wt = rho_weight(r, c, loss, outlier)
            cost += rho
        j2 = gx * (-sn * x - cs * y) + gy * (cs * x - sn * y)
        wx = wt * gx
        wy = wt * gy
        w2 = wt * j2
        g0 += wx * r
        g1 += wy * r
        g2 += w2 * r
        h00 += wx * gx
        h01 += wx * gy
        h02 += wx * j2
        h11 += wy * gy
        h12 += wy * j2
        h22 += w2 * j2
    if n_prod > 0:
        cost += 0.5 * c * c * math.log(prod)
    H[0, 0] = h00
    H[0, 1] = H[1, 0] = h01
    H[0, 2] = H[2, 0] = h02
    H[1, 1] = h11
    H[1, 2] = H[2, 1] = h12
    H[2, 2] = h22
    g[0] = g0
    g[1] = g1
    g[2] = g2
    return cost


@njit(cache=True, fastmath=True)
def _solve3(M, g, d):  # pragma: no cover - compiled
    """``d = -M^-1 g`` for a symmetric 3x3 ``M`` (Cramer's rule); False when singular."""
    c00 = M[1, 1] * M[2, 2] - M[1, 2] * M[2, 1]
    c01 = M[1, 2] * M[2, 0] - M[1, 0] * M[2, 2]
    c02 = M[1, 0] * M[2, 1] - M[1, 1] * M[2, 0]
    det = M[0, 0] * c00 + M[0, 1] * c01 + M[0, 2] * c02
    if not (abs(det) > 1e-300):
        return False
    c11 = M[0, 0] * M[2, 2] - M[0, 2] * M[2, 0]
    c12 = M[0, 2] * M[1, 0] - M[0, 0] * M[1, 2]
    c22 = M[0, 0] * M[1, 1] - M[0, 1] * M[1, 0]
    inv = 1.0 / det
    d[0] = -(c00 * g[0] + c01 * g[1] + c02 * g[2]) * inv
    d[1] = -(c01 * g[0] + c11 * g[1] + c12 * g[2]) * inv
    d[2] = -(c02 * g[0] + c12 * g[1] + c22 * g[2]) * inv
    return True


@njit(cache=True, fastmath=True)
def _refine(field, A, b, far, px, py, pose0, scales, outliers, loss, max_iter, tol, lx, ly, backcos, off):  # noqa: E501  # pragma: no cover
    """Levenberg-Marquardt over the annealing stages.

    Returns ``(pose, iterations, cost)``, the cost robust under the last stage's kernel.
    One pass over the points per trial step: the normal equations at the trial pose are
    built with its cost and kept when the step is accepted.

    A stage has converged when the step (``|dx| + |dy| + |dyaw|``) is below ``tol``: a step
    that small is not tried (no pass over the points).  Tried, it was the stage's last step
    either way: accepted, the stage stopped on it; rejected (the cost does not fall by a step
    that short: the bilinear field's kinks, rounding), the damping grew tenfold and the nearly
    equal step was tried again, up to 8 passes for nothing.  22 % of the passes on the office
    run with every scan matched.
    """
    pose = pose0.copy()
    H = np.zeros((3, 3))
    g = np.zeros(3)
    Ht = np.zeros((3, 3))
    gt = np.zeros(3)
    trial = np.zeros(3)
    M = np.zeros((3, 3))
    d = np.zeros(3)
    it_total = 0
    cost = 0.0
    for s in range(scales.shape[0]):
        c = scales[s]
        out = outliers[s]
        lam = 1e-4
        cost = lm_system(field, A, b, far, px, py, pose, c, loss, out, lx, ly, backcos, off, H, g)
        for _it in range(max_iter):
            it_total += 1
            improved = False
            converged = False
            for _try in range(8):
                for i in range(3):
                    for j in range(3):
                        M[i, j] = H[i, j]
                    M[i, i] += lam * (H[i, i] + 1e-9)
                if not _solve3(M, g, d):
                    lam *= 10.0
                    continue
                if math.sqrt(d[0] * d[0] + d[1] * d[1]) + abs(d[2]) < tol:
                    converged = True
                    break
                trial[0] = pose[0] + d[0]
                trial[1] = pose[1] + d[1]
                trial[2] = pose[2] + d[2]
                tc = lm_system(field, A, b, far, px, py, trial, c, loss, out, lx, ly, backcos, off, Ht, gt)
                if tc <= cost:
                    for i in range(3):
                        pose[i] = trial[i]
                        g[i] = gt[i]
                        for j in range(3):
                            H[i, j] = Ht[i, j]
                    cost = tc
                    lam = max(lam * 0.1, 1e-7)
                    improved = True
                    break
                lam *= 10.0
            if converged or not improved:   # (a step that was tried is at least tol long)
                break
    return pose, it_total, cost


@njit(cache=True, fastmath=True)
def _beam_clear(cls, Ac, bc, ox, oy, qx, qy):  # pragma: no cover - compiled
    """1 when the beam from ``(ox, oy)`` to ``(qx, qy)`` (map frame) crosses no occupied cell of
    ``cls`` (0 free, 1 occupied, 2 unknown; off the grid: unknown), marched in half-cell steps; else 0."""
    h, w = cls.shape
    u0 = Ac[0, 0] * ox + Ac[0, 1] * oy + bc[0] + 0.5
    v0 = Ac[1, 0] * ox + Ac[1, 1] * oy + bc[1] + 0.5
    u1 = Ac[0, 0] * qx + Ac[0, 1] * qy + bc[0] + 0.5
    v1 = Ac[1, 0] * qx + Ac[1, 1] * qy + bc[1] + 0.5
    n = int(2.0 * max(abs(u1 - u0), abs(v1 - v0))) + 1
    for i in range(n):
        f = i / n
        u = u0 + f * (u1 - u0)
        v = v0 + f * (v1 - v0)
        if u >= 0.0 and v >= 0.0 and u < w and v < h and cls[int(v), int(u)] == 1:
            return 0
    return 1


@njit(cache=True, fastmath=True)
def _stats(field, A, b, far, px, py, pose, c, loss, outlier, inlier, lx, ly, backcos, off, unk, Ac, bc):  # noqa: E501  # pragma: no cover
    """Final H (J^T W J), sum w r^2, sum w, inliers, used points, sum of inlier residuals, runs,
    and the non-inlier points the map cannot say anything about: their beam ends in the map's unknown
    space without crossing an occupied cell (``unk``: map cells, 0 free, 1 occupied, 2 unknown;
    ``Ac``, ``bc``: map frame -> cell coordinates).  A beam that crossed a mapped wall to get there
    contradicts the map (a wrong pose) and is not one of them.

    Runs: the used points taken in scan order, cut where two neighbours are more than
    ``gridmath.RUN_GAP_M`` apart or a run would exceed ``RUN_LENGTH_M``: stretches of one wall whose
    map error (raster, thickness, a wall drawn where it is not) all their beams share.
    """
    H = np.zeros((3, 3))
    cs = math.cos(pose[2])
    sn = math.sin(pose[2])
    wr2 = 0.0
    sw = 0.0
    n_in = 0
    n_used = 0
    sr = 0.0
    n_runs = 0
    run_len = 0.0
    lastx = 1e300
    lasty = 1e300
    n_unk = 0
    hu, wu = unk.shape
    for k in range(px.shape[0]):
        r, gx, gy, front = point_residual(field, A, b, far, pose, cs, sn, px[k], py[k], lx, ly, backcos, off)
        if not (front and abs(r) < inlier):
            qx = pose[0] + cs * px[k] - sn * py[k]
            qy = pose[1] + sn * px[k] + cs * py[k]
            u = Ac[0, 0] * qx + Ac[0, 1] * qy + bc[0] + 0.5
            v = Ac[1, 0] * qx + Ac[1, 1] * qy + bc[1] + 0.5
            if not (u >= 0.0 and v >= 0.0 and u < wu and v < hu) or unk[int(v), int(u)] == 2:
                n_unk += _beam_clear(unk, Ac, bc, pose[0] + cs * lx - sn * ly, pose[1] + sn * lx + cs * ly, qx, qy)
        if not front:
            continue
        rho, w = rho_weight(r, c, loss, outlier)
        if abs(r) < inlier:
            n_in += 1
            sr += r
        if w == 0.0:
            continue
        n_used += 1
        new_run, run_len = run_step(px[k], py[k], lastx, lasty, run_len)
        n_runs += new_run
        lastx = px[k]
        lasty = py[k]
        j0 = gx
        j1 = gy
        j2 = gx * (-sn * px[k] - cs * py[k]) + gy * (cs * px[k] - sn * py[k])
        add_normal(H, w, j0, j1, j2)
        wr2 += w * r * r
        sw += w
    mirror_upper(H)
    return H, wr2, sw, n_in, n_used, sr, n_runs, n_unk


@njit(cache=True, fastmath=True, inline="always")
def _likelihood_sum(lik, A, b, tx, ty, rx, ry, m):  # pragma: no cover - compiled
    """Sum of the likelihood grid's cells (nearest) under the map-frame points ``(tx + rx[k], ty + ry[k])``,
    ``k < m``; ``A``, ``b``: map frame -> grid coordinates; a point off the grid adds 0."""
    h, w = lik.shape
    acc = 0.0
    for k in range(m):
        qx = tx + rx[k]
        qy = ty + ry[k]
        u = A[0, 0] * qx + A[0, 1] * qy + b[0] + 0.5
        v = A[1, 0] * qx + A[1, 1] * qy + b[1] + 0.5
        if u >= 0.0 and v >= 0.0 and u < w and v < h:
            acc += lik[int(v), int(u)]
    return acc


@njit(cache=True, fastmath=True)
def _alias_starts(lik, A, b, px, py, stride, pose, c00, c01, c11, step, n, ratio):  # pragma: no cover
    """Start poses at the (at most 2 best) other local maxima of the likelihood-field score along
    the least constrained direction of the position covariance ``[[c00, c01], [c01, c11]]``.

    The score (mean likelihood of every ``stride``-th point) is profiled at shifts ``k step``,
    ``k = -n..n``; maxima more than 0.25 m away that reach ``ratio`` of the score at 0 count.
    Returns ``(m, 3)`` poses, ``m <= 2``.
    """
    # principal axis of the 2x2 covariance (largest eigenvalue)
    tr = 0.5 * (c00 + c11)
    det = c00 * c11 - c01 * c01
    lam = tr + math.sqrt(max(tr * tr - det, 0.0))
    if abs(c01) > 1e-300:
        ux, uy = lam - c11, c01
    elif c00 >= c11:
        ux, uy = 1.0, 0.0
    else:
        ux, uy = 0.0, 1.0
    nrm = math.hypot(ux, uy)
    ux /= nrm
    uy /= nrm
    cs = math.cos(pose[2])
    sn = math.sin(pose[2])
    m = (px.shape[0] + stride - 1) // stride
    rx = np.empty(m)
    ry = np.empty(m)
    for k in range(m):
        rx[k] = cs * px[k * stride] - sn * py[k * stride]
        ry[k] = sn * px[k * stride] + cs * py[k * stride]
    prof = np.zeros(2 * n + 1)
    for kk in range(2 * n + 1):
        tx = pose[0] + (kk - n) * step * ux
        ty = pose[1] + (kk - n) * step * uy
        prof[kk] = _likelihood_sum(lik, A, b, tx, ty, rx, ry, m) / max(m, 1)
    best_k = np.full(2, -1)
    for kk in range(1, 2 * n):
        if abs(kk - n) * step <= 0.25 or prof[kk] < ratio * prof[n]:
            continue
        if prof[kk] < prof[kk - 1] or prof[kk] < prof[kk + 1]:
            continue
        if best_k[0] < 0 or prof[kk] > prof[best_k[0]]:
            best_k[1] = best_k[0]
            best_k[0] = kk
        elif best_k[1] < 0 or prof[kk] > prof[best_k[1]]:
            best_k[1] = kk
    cnt = 0
    for j in range(2):
        if best_k[j] >= 0:
            cnt += 1
    out = np.zeros((cnt, 3))
    for j in range(cnt):
        sft = (best_k[j] - n) * step
        out[j, 0] = pose[0] + sft * ux
        out[j, 1] = pose[1] + sft * uy
        out[j, 2] = pose[2]
    return out


@njit(cache=True, fastmath=True)
def correlative_search(lik, A, b, px, py, guess, lin_win, lin_step, ang_win, ang_step, n_best):  # pragma: no cover
    """Exhaustive correlative search; returns the ``n_best`` poses (rows) and their mean scores."""
    nl = int(math.floor(lin_win / lin_step + 1e-9))
    na = int(math.floor(ang_win / ang_step + 1e-9))
    best_pose = np.zeros((n_best, 3))
    best_score = np.full(n_best, -1.0)
    n = px.shape[0]
    rx = np.empty(n)
    ry = np.empty(n)
    for ia in range(-na, na + 1):
        th = guess[2] + ia * ang_step
        cs = math.cos(th)
        sn = math.sin(th)
        for k in range(n):
            rx[k] = cs * px[k] - sn * py[k]
            ry[k] = sn * px[k] + cs * py[k]
        for ix in range(-nl, nl + 1):
            tx = guess[0] + ix * lin_step
            for iy in range(-nl, nl + 1):
                ty = guess[1] + iy * lin_step
                s = _likelihood_sum(lik, A, b, tx, ty, rx, ry, n) / n
                # insert into the (small, sorted descending) best list
                if s > best_score[n_best - 1]:
                    j = n_best - 1
                    while j > 0 and best_score[j - 1] < s:
                        best_score[j] = best_score[j - 1]
                        best_pose[j] = best_pose[j - 1]
                        j -= 1
                    best_score[j] = s
                    best_pose[j, 0] = tx
                    best_pose[j, 1] = ty
                    best_pose[j, 2] = th
    return best_pose, best_score


@njit(cache=True, fastmath=True)
def heading_probe(lik, A, b, px, py, stride, pose, win, step):  # pragma: no cover - compiled
    """The heading check's two scores in one call: every ``stride``-th point, :func:`correlative_search` over
    heading only (``+-win`` in ``step``) at ``pose``'s position, and at ``pose`` itself.  Returns the
    best pose (3,), its score and the score at ``pose``."""
    m = (px.shape[0] + stride - 1) // stride
    sx = np.empty(m)
    sy = np.empty(m)
    for k in range(m):
        sx[k] = px[k * stride]
        sy[k] = py[k * stride]
    best, score = correlative_search(lik, A, b, sx, sy, pose, 0.0, 1.0, win, step, 1)
    _, here = correlative_search(lik, A, b, sx, sy, pose, 0.0, 1.0, 0.0, 1.0, 1)
    return best[0].copy(), score[0], here[0]


@njit(cache=True)
def _wrap_exact(a):  # pragma: no cover - compiled
    """:func:`fgloc.geometry.wrap_scalar`, compiled without fastmath (the same bits: fmod is exact, and
    fastmath could fold the ``+ 2 pi`` and ``- pi`` into one rounding)."""
    w = np.fmod(a + math.pi, 2.0 * math.pi)
    if w < 0:
        w += 2.0 * math.pi
    return w - math.pi


@njit(cache=True, fastmath=True)
def _track(field, A, b, far, px, py, guess, scales, outliers, loss, max_iter, tol, lx, ly, backcos, off,  # noqa: E501
           lik, Ac, bc, hstride, hwin, hstep, max_jump_m, max_jump, inlier, unk):  # pragma: no cover - compiled
    """A tracked scan in one call: :func:`_refine` from ``guess``, the heading check, :func:`_stats` at
    the pose kept and its :func:`_conditioning`.  Returns the pose, its robust cost, :func:`_stats`' tuple
    and :func:`_conditioning`'s.

    The heading check (``hwin > 0``): a refinement that kept a wrong heading (a guess several degrees
    off: a burst of scan stamps the odometry cannot place) is a local minimum the likelihood field
    shows: the score profile over heading at the refined position (``+-hwin`` in ``hstep``, every
    ``hstride``-th point) peaking elsewhere than at the refined heading.  Then the refinement is run
    from that peak too, and the lower robust cost wins (within ``max_jump_m`` / ``max_jump`` rad of
    ``guess``)."""
    pose, _, cost = _refine(field, A, b, far, px, py, guess, scales, outliers, loss, max_iter, tol, lx, ly,
                            backcos, off)
    if hwin > 0.0:
        best, score, here = heading_probe(lik, Ac, bc, px, py, hstride, pose, hwin, hstep)
        if not abs(_wrap_exact(best[2] - pose[2])) < 1.5 * hstep and score > here:
            pose2, _, cost2 = _refine(field, A, b, far, px, py, best, scales, outliers, loss, max_iter, tol, lx,
                                      ly, backcos, off)
            if (cost2 < cost and math.hypot(pose2[0] - guess[0], pose2[1] - guess[1]) <= max_jump_m
                    and abs(_wrap_exact(pose2[2] - guess[2])) <= max_jump):
                pose = pose2
                cost = cost2
    m = scales.shape[0] - 1
    H, wr2, sw, n_in, n_used, sr, n_runs, n_unk = _stats(field, A, b, far, px, py, pose, scales[m], loss,
                                                         outliers[m], inlier, lx, ly, backcos, off, unk, Ac, bc)
    ev0, ev2, Hinv = _conditioning(H, px, py)
    return pose, cost, (H, wr2, sw, n_in, n_used, sr, n_runs, n_unk), (ev0, ev2, Hinv)


@njit(cache=True, fastmath=True)
def _alias_refines(lik, Ac, bc, stride, pose, c00, c01, c11, step, n, ratio, field, A, b, far, px, py,  # noqa: E501
                   scales, outliers, loss, max_iter, tol, lx, ly, backcos, off):  # pragma: no cover - compiled
    """:func:`_alias_starts` and :func:`_refine` from each: ``(m, 3)`` poses and their ``m`` costs."""
    starts = _alias_starts(lik, Ac, bc, px, py, stride, pose, c00, c01, c11, step, n, ratio)
    m = starts.shape[0]
    poses = np.empty((m, 3))
    costs = np.empty(m)
    for j in range(m):
        p, _, c = _refine(field, A, b, far, px, py, starts[j], scales, outliers, loss, max_iter, tol, lx, ly,
                          backcos, off)
        poses[j, 0] = p[0]
        poses[j, 1] = p[1]
        poses[j, 2] = p[2]
        costs[j] = c
    return poses, costs


@njit(cache=True)
def _fix_cov(px, py, best, best_cost, wr2, sw, n_runs, Hinv, rposes, rcosts, sxy, syaw, lik, Ac, bc, stride, step, n,  # noqa: E501
             ratio, field, A, b, far, ascales, aoutliers, loss, max_iter, tol, lx, ly, backcos, off, floor,
             finish):  # pragma: no cover - compiled
    """An accepted fix's covariance (the module's step 4): ``S s^2 (sum w / runs) H^-1 S`` (``sxy``,
    ``syaw``: ``S``'s diagonal, diagonal: elementwise), widened by the spread of the refined
    candidates ``rposes`` (costs ``rcosts``) and of the aliases (:func:`_alias_refines` from the
    second annealing stage on: ``ascales``, ``aoutliers``) that explain the scan nearly as well;
    with ``finish`` the ``floor`` matrix added and the result symmetrized.  Returns the covariance
    and ``s^2``.  No fastmath: each operation rounded as numpy's array code rounds it."""
    sigma2 = wr2 / max(sw - 3.0, 1.0)
    per_run = sw / max(n_runs, 1)
    k = sigma2 * per_run
    cov = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            cov[i, j] = k * Hinv[i, j]
    if not (sxy == 1.0 and syaw == 1.0):
        S = np.array([sxy, sxy, syaw])
        for i in range(3):
            for j in range(3):
                cov[i, j] = (S[i] * cov[i, j]) * S[j]
    temp = max(k, 1e-12)
    aposes, acosts = _alias_refines(lik, Ac, bc, stride, best, cov[0, 0], cov[0, 1], cov[1, 1], step, n, ratio,
                                    field, A, b, far, px, py, ascales, aoutliers, loss, max_iter, tol, lx, ly,
                                    backcos, off)
    spread = np.zeros((3, 3))
    widened = False
    wsum = 1.0
    d = np.empty(3)
    m0 = rposes.shape[0]
    for j in range(m0 + aposes.shape[0]):
        if j < m0:
            for i in range(3):
                d[i] = rposes[j, i] - best[i]
            ccost = rcosts[j]
        else:
            for i in range(3):
                d[i] = aposes[j - m0, i] - best[i]
            ccost = acosts[j - m0]
        d[2] = _wrap_exact(d[2])
        if math.hypot(d[0], d[1]) < 1e-3 and abs(d[2]) < 1e-4:
            continue
        dc = ccost - best_cost
        wc = math.exp(-(dc if dc > 0.0 else 0.0) / temp)
        if wc > 1e-4:
            widened = True
            for i in range(3):
                for i2 in range(3):
                    spread[i, i2] += wc * (d[i] * d[i2])
            wsum += wc
    if widened:
        for i in range(3):
            for j in range(3):
                cov[i, j] = cov[i, j] + spread[i, j] / wsum
    if finish:
        c = np.empty((3, 3))
        for i in range(3):
            for j in range(3):
                c[i, j] = cov[i, j] + floor[i, j]
        for i in range(3):
            for j in range(3):
                cov[i, j] = 0.5 * (c[i, j] + c[j, i])
    return cov, sigma2


@njit(cache=True)
def _track_fix(field, A, b, far, px, py, guess, scales, outliers, loss, max_iter, tol, lx, ly, backcos, off,  # noqa: E501
               lik, Ac, bc, hstride, hwin, hstep, max_jump_m, max_jump, inlier, unk, trigger, min_inliers,
               min_fraction, min_eigen_ratio, sxy, syaw, astride, astep, an, aratio, ascales, aoutliers, floor,
               finish):  # pragma: no cover - compiled
    """A tracked scan to its fix in one call: :func:`_track`, then, when its pose is within the jump
    limits of ``guess`` and at least ``trigger`` of the points are inliers (no correlative search
    wanted), the acceptance tests of :meth:`NativeMatcher._match` and :func:`_fix_cov`.

    Returns :func:`_track`'s four values, whether the fix was accepted here, the accepted pose (yaw
    wrapped), the unknown-space points counted (0 when the laser stands off the map's free space),
    the covariance and ``s^2``.  Not accepted here: :meth:`NativeMatcher._match` goes on from
    :func:`_track`'s values (a search, or a no-fix with its reason)."""
    pose, cost, stats, cond = _track(field, A, b, far, px, py, guess, scales, outliers, loss, max_iter, tol, lx,
                                     ly, backcos, off, lik, Ac, bc, hstride, hwin, hstep, max_jump_m, max_jump,
                                     inlier, unk)
    fpose = pose.copy()
    no_cov = np.empty((3, 3))
    n = px.shape[0]
    H, wr2, sw, n_in, n_used, sr, n_runs, n_unk = stats
    ev0, ev2, Hinv = cond
    if not (math.hypot(pose[0] - guess[0], pose[1] - guess[1]) <= max_jump_m
            and abs(_wrap_exact(pose[2] - guess[2])) <= max_jump and n_in / n >= trigger):
        return pose, cost, stats, cond, False, fpose, n_unk, no_cov, 0.0
    fpose[2] = _wrap_exact(fpose[2])
    if n_unk > 0:  # NativeMatcher._laser_on_free
        c = math.cos(fpose[2])
        s = math.sin(fpose[2])
        ox = fpose[0] + c * lx - s * ly
        oy = fpose[1] + s * lx + c * ly
        u = Ac[0, 0] * ox + Ac[0, 1] * oy + bc[0] + 0.5
        v = Ac[1, 0] * ox + Ac[1, 1] * oy + bc[1] + 0.5
        h, w = unk.shape
        if not (0.0 <= u and u < w and 0.0 <= v and v < h and unk[int(v), int(u)] == 0):
            n_unk = 0
    nn = max(n - n_unk, (n + 1) // 2)
    if n_in < min_inliers or n_in / nn < min_fraction:
        return pose, cost, stats, cond, False, fpose, n_unk, no_cov, 0.0
    if (math.hypot(fpose[0] - guess[0], fpose[1] - guess[1]) > max_jump_m
            or abs(_wrap_exact(fpose[2] - guess[2])) > max_jump):
        return pose, cost, stats, cond, False, fpose, n_unk, no_cov, 0.0
    if not (math.isfinite(ev0) and math.isfinite(ev2) and ev0 > min_eigen_ratio * ev2 and ev2 > 0):
        return pose, cost, stats, cond, False, fpose, n_unk, no_cov, 0.0
    rposes = np.empty((1, 3))
    rposes[0, 0] = pose[0]
    rposes[0, 1] = pose[1]
    rposes[0, 2] = pose[2]
    rcosts = np.full(1, cost)
    cov, sigma2 = _fix_cov(px, py, pose, cost, wr2, sw, n_runs, Hinv, rposes, rcosts, sxy, syaw, lik, Ac, bc, astride,
                           astep, an, aratio, field, A, b, far, ascales, aoutliers, loss, max_iter, tol, lx, ly,
                           backcos, off, floor, finish)
    return pose, cost, stats, cond, True, fpose, n_unk, cov, sigma2


@njit(cache=True, fastmath=True)
def _conditioning(H, px, py):  # pragma: no cover - compiled
    """Smallest and largest eigenvalue of ``S H S`` (yaw scaled by the RMS point range, metres per
    radian) and ``H^-1`` (NaN when singular)."""
    n = px.shape[0]
    s2 = 0.0
    for k in range(n):
        s2 += px[k] * px[k] + py[k] * py[k]
    lever = math.sqrt(s2 / n) if n > 0 else 1.0
    if not lever > 0.0:
        lever = 1.0
    S = np.array([1.0, 1.0, 1.0 / lever])
    M = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            M[i, j] = S[i] * H[i, j] * S[j]
    Hinv = np.full((3, 3), np.nan)
    if not np.all(np.isfinite(M)):
        return np.nan, np.nan, Hinv
    ev = np.linalg.eigvalsh(M)
    c00 = H[1, 1] * H[2, 2] - H[1, 2] * H[2, 1]
    c01 = H[1, 2] * H[2, 0] - H[1, 0] * H[2, 2]
    c02 = H[1, 0] * H[2, 1] - H[1, 1] * H[2, 0]
    det = H[0, 0] * c00 + H[0, 1] * c01 + H[0, 2] * c02
    if abs(det) > 1e-300:
        inv = 1.0 / det
        Hinv[0, 0] = c00 * inv
        Hinv[0, 1] = Hinv[1, 0] = c01 * inv
        Hinv[0, 2] = Hinv[2, 0] = c02 * inv
        Hinv[1, 1] = (H[0, 0] * H[2, 2] - H[0, 2] * H[2, 0]) * inv
        Hinv[1, 2] = Hinv[2, 1] = (H[0, 2] * H[1, 0] - H[0, 0] * H[1, 2]) * inv
        Hinv[2, 2] = (H[0, 0] * H[1, 1] - H[0, 1] * H[1, 0]) * inv
    return ev[0], ev[2], Hinv


@njit(cache=True)
def edt_squared(feature):  # pragma: no cover - compiled
    """Squared Euclidean distance (in cells, exact integers as floats) from every cell of the 2-D
    boolean grid ``feature`` to the nearest True cell (0 on them); at least one cell must be True.

    ``scipy.ndimage.distance_transform_edt(~feature) ** 2``, bit for bit (its distances are the
    square roots of the same integers), 3-4x faster: the separable transform of Felzenszwalb and
    Huttenlocher (2012) (:func:`_edt`).  The matcher builds two such fields per map at start-up."""
    return _edt(feature, np.inf)


@njit(cache=True)
def edt_squared_below(feature, bound2):  # pragma: no cover - compiled
    """:func:`edt_squared` where it is below ``bound2``; elsewhere some value of at least ``bound2`` (a
    field clipped at a distance needs no more, and the transform skips the cells that far from
    ``feature`` along a column)."""
    return _edt(feature, bound2)


@njit(cache=True)
def _edt(feature, bound2):  # pragma: no cover - compiled
    """The squared distance transform of :func:`edt_squared`, exact below ``bound2`` (at least ``bound2``
    elsewhere).

    First along the columns, row by row (each row's cells in memory order): the distance to the nearest
    True cell above or below; then along each row the lower envelope of the parabolas
    ``(j - q)^2 + f(q)``, ``f`` the squared column distances (those of at least ``bound2`` left out:
    the envelope there is at least that).  The envelope's breakpoints are kept as fractions of exact
    integers and compared by cross-multiplication (products below 2^53: exact), so the envelope and
    every distance are exact, whichever order the passes run in."""
    h, w = feature.shape
    big = float(h + w) * float(h + w) + 1.0  # a column without a True cell (more than any distance)
    g = np.empty((h, w))
    for j in range(w):
        g[0, j] = 0.0 if feature[0, j] else big
    for i in range(1, h):
        for j in range(w):
            g[i, j] = 0.0 if feature[i, j] else g[i - 1, j] + 1.0
    for i in range(h - 2, -1, -1):
        for j in range(w):
            d = g[i + 1, j] + 1.0
            if d < g[i, j]:
                g[i, j] = d
    for i in range(h):
        for j in range(w):
            d = g[i, j]
            g[i, j] = d * d if d < big else big
    skip = bound2 if bound2 < big else big
    v = np.empty(w, dtype=np.int64)
    zn = np.empty(w + 1)  # breakpoint k at zn[k] / zd[k] (zd > 0)
    zd = np.empty(w + 1)
    f = np.empty(w)
    for i in range(h):
        k = -1
        for q in range(w):
            fq = g[i, q]
            if fq >= skip:
                continue
            if k < 0:
                k = 0
                v[0] = q
                f[0] = fq
                continue
            vk = v[k]
            num = (fq + q * q) - (f[k] + vk * vk)
            den = 2.0 * (q - vk)
            while k > 0 and num * zd[k] <= zn[k] * den:
                k -= 1
                vk = v[k]
                num = (fq + q * q) - (f[k] + vk * vk)
                den = 2.0 * (q - vk)
            k += 1
            v[k] = q
            f[k] = fq
            zn[k] = num
            zd[k] = den
        if k < 0:  # every parabola of the row left out: all at least bound2
            for q in range(w):
                g[i, q] = big
            continue
        m = 0
        for q in range(w):
            while m < k and zn[m + 1] < q * zd[m + 1]:
                m += 1
            dq = q - v[m]
            g[i, q] = dq * dq + f[m]
    return g


@njit(cache=True)
def signed_field(occ, dist_m, out, cell_m, depth_m, max_m):  # pragma: no cover - compiled
    """:func:`surface_distance_field`'s last steps in one pass, into ``out`` (may be ``dist_m``):
    ``dist_m - cell_m / 2`` off the obstacles (``dist_m``: the distance to the nearest occupied cell
    centre), minus the distance to the nearest free cell less half a cell on them, plus ``depth_m``,
    clipped to ``[-max_m, max_m]``; each operation rounded as numpy's array code rounds it.  At least
    one cell must be free.

    A wall cell's squared distance to the nearest free cell (exact integers, :func:`edt_squared` of the
    free cells) is the smallest ``(i - q)^2 + g[q]`` over the rows ``q`` of its column, ``g`` the squared
    distance along row ``q`` to its nearest free cell (0 on a free cell): taken outwards from its own row
    until ``(i - q)^2`` reaches the best so far.  A wall is a few cells thick: a few rows per wall cell,
    and nothing to do for the free cells, most of a map (the transform of the free cells visits each
    cell several times)."""
    h, w = occ.shape
    half = 0.5 * cell_m
    none = float(h + w) * float(h + w) + 1.0  # no free cell in the row (more than any distance)
    g = np.empty((h, w))
    for i in range(h):
        last = -1
        for j in range(w):
            if not occ[i, j]:
                last = j
                g[i, j] = 0.0
            else:
                g[i, j] = float(j - last) if last >= 0 else -1.0
        last = -1
        for j in range(w - 1, -1, -1):
            if not occ[i, j]:
                last = j
            elif last >= 0 and (g[i, j] < 0.0 or last - j < g[i, j]):
                g[i, j] = float(last - j)
            if occ[i, j]:
                g[i, j] = g[i, j] * g[i, j] if g[i, j] >= 0.0 else none
    for i in range(h):
        for j in range(w):
            if not occ[i, j]:
                v = (dist_m[i, j] - half) + depth_m
            else:
                best = g[i, j]
                t = 1
                while float(t * t) < best and (i - t >= 0 or i + t < h):
                    tt = float(t * t)
                    if i - t >= 0:
                        c = tt + g[i - t, j]
                        if c < best:
                            best = c
                    if i + t < h:
                        c = tt + g[i + t, j]
                        if c < best:
                            best = c
                    t += 1
                v = -(math.sqrt(best) * cell_m - half) + depth_m
            if v < -max_m:
                v = -max_m
            elif v > max_m:
                v = max_m
            out[i, j] = v


# ----------------------------------------------------------------- the matcher
def distance_m(feature: np.ndarray, cell_m: float, exact_below_m: float = math.inf) -> FloatArray:
    """Distance (m) from each cell centre to the nearest ``feature`` cell centre (at least one): the
    square root of :func:`edt_squared` times ``cell_m``, in place (``scipy.ndimage.distance_transform_edt
    (~feature) * cell_m`` bit for bit).  With ``exact_below_m`` (finite, > 0) only distances below it are
    exact, the others are at least it (:func:`edt_squared_below`)."""
    if math.isfinite(exact_below_m) and exact_below_m > 0:
        cells = math.ceil(exact_below_m / cell_m) + 1
        d = edt_squared_below(feature, float(cells * cells))
    else:
        d = edt_squared(feature)
    np.sqrt(d, out=d)
    d *= cell_m
    return d  # type: ignore[no-any-return]


def map_distance_field(occ_map: OccupancyMap) -> FloatArray:
    """``occ_map.distance_field`` (distance in m from each cell centre to the nearest occupied cell
    centre), given its value here when it has none yet: the square root of :func:`edt_squared` times
    the resolution, which is ``scipy.ndimage.distance_transform_edt(~occupied) * resolution`` bit for
    bit, without importing ``scipy.ndimage``.  The map's own property answers a map without obstacles.
    The matcher's coarse field is this field less half a cell, and the localizer's scan agreement and
    global search read the map's: one transform for all three."""
    if "distance_field" in vars(occ_map):
        return occ_map.distance_field
    occ = occ_map.occupied
    if not occ.any():
        return occ_map.distance_field
    d = distance_m(occ, occ_map.resolution)
    occ_map.distance_field = d
    return d


def surface_distance_field(
    occ_map: OccupancyMap, upsample: int = 2, max_dist_m: float = 2.0, surface_depth_m: float = 0.0
) -> FloatArray:
    """Signed distance (m) to the nearest occupied-cell *surface*, on a grid ``upsample`` times finer.

    Fine cell ``(i, j)`` has its centre at continuous map-grid coordinate
    ``((j + 0.5) / k, (i + 0.5) / k)``.  Outside obstacles: EDT to the nearest fine
    occupied cell centre minus half a fine cell (so the bilinear interpolation
    crosses zero on the cell face, where a beam ends); inside: minus the same
    distance to the nearest non-occupied cell, so a point inside a thick wall is
    pushed out instead of resting on a flat zero.  ``surface_depth_m`` moves the zero
    level that far into the obstacle (``res/2``: the surface runs through the centres of
    the boundary cells).  Clipped to ``[-max, max]``.
    """
    k = max(int(upsample), 1)
    occ = np.ascontiguousarray(occ_map.occupied)
    if k > 1:
        occ = np.repeat(np.repeat(occ, k, axis=0), k, axis=1)
    fine = occ_map.resolution / k
    if not occ.any():
        return np.full(occ.shape, float(max_dist_m))
    if occ.all():
        return np.clip(np.full(occ.shape, -float(max_dist_m)) + float(surface_depth_m), -max_dist_m, max_dist_m)
    if k == 1:  # the map's own distance field (made here if it has none): the same values
        dist = map_distance_field(occ_map)
        out = np.empty(occ.shape)
    else:
        # a free cell at least max - depth + half a cell from the walls is clipped to max: only the
        # distances below that (and two cells more) need to be exact
        dist = out = distance_m(occ, fine, float(max_dist_m) - float(surface_depth_m) + 2.0 * fine)
    signed_field(occ, dist, out, fine, float(surface_depth_m), float(max_dist_m))
    return out


@dataclass(frozen=True)
class NativeConfig:
    """``frontends.native``: the native matcher (defaults here and only here)."""

    preprocess: PreprocessOptions = section(PreprocessOptions, "scan preprocessing shared by the front-ends")
    field_upsample: int = setting(2, "distance field this many times finer than the map", min=1)
    surface_depth_cells: float | Literal["auto"] = setting(
        "auto", "where the wall surface lies behind a boundary cell's face, in cells: 0.5 = cell centres (SLAM "
        "maps, rasterized worlds), 0 = faces; auto = start at 0.5 and learn it from good fixes")
    depth_window: int = setting(100, "auto depth: running mean over this many fixes", min=1)
    depth_min_quality: float = setting(0.8, "auto depth: fixes at least this good count", min=0, max=1)
    field_max_dist_m: float = setting(1.0, "distance field clipped at +-this", gt=0)
    loss: str = setting("cauchy", "robust loss of the Levenberg-Marquardt refinement", choices=("huber", "cauchy"))
    kernel_schedule_m: tuple[float, ...] = setting((0.3, 0.1, 0.03), "kernel scale per annealing stage", gt=0)
    outlier_schedule_m: tuple[float, ...] = setting((1.0, 0.5, 0.2), "outlier cut-off per stage", gt=0)
    max_iterations: int = setting(15, "iterations per stage", min=1)
    tolerance: float = setting(1e-4, "per stage: stop when |dx| + |dy| + |dyaw| < this (m + rad)", gt=0)
    backface_cos: float = setting(0.1, "ignore points on wall faces turned away from the laser")
    inlier_dist_m: float = setting(0.1, "|residual| below this is an inlier; quality = inlier fraction", gt=0)
    min_inliers: int = setting(30, "fewer inliers -> no fix", min=0)
    min_inlier_fraction: float = setting(0.4, "smaller inlier fraction -> no fix", min=0, max=1)
    max_jump_m: float = setting(1.0, "farther from the guess -> no fix", gt=0)
    max_jump_deg: float = setting(30.0, "more heading change from the guess -> no fix", gt=0)
    min_eigen_ratio: float = setting(1e-3, "smallest/largest Hessian eigenvalue below this -> no fix (degenerate)",
                                     min=0)
    search: str = setting("auto", "correlative search: auto = only when the refinement from the guess is poor",
                          choices=("auto", "always", "never"))
    search_trigger_inlier_fraction: float = setting(0.6, "auto search: below this inlier fraction", min=0, max=1)
    search_window_m: float = setting(0.5, "search window half-width", gt=0)
    search_window_deg: float = setting(15.0, "search window half-width in heading", gt=0)
    search_lin_step_m: float = setting(0.1, "search grid step", gt=0)
    search_ang_step_deg: float = setting(2.0, "search heading step", gt=0)
    search_sigma_m: float = setting(0.1, "Gaussian likelihood field used for scoring", gt=0)
    search_max_points: int = setting(120, "points used for scoring (uniform stride)", min=1)
    search_candidates: int = setting(3, "best poses refined; the lowest robust cost wins", min=1)
    heading_check_deg: float = setting(
        10.0, "after the refinement from the guess: a likelihood-field score peak this far in heading "
        "(+-) from the refined heading is refined too, the lower cost wins (0 = off)", min=0)
    cov_inflation: tuple[float, ...] = setting(
        (1.0, 1.0), "[kxy, kyaw]: extra factors on the covariance model's variances (see the module docstring); "
        "1 = the model as derived", gt=0)
    cov_floor: tuple[float, float, float] = setting((1e-8, 1e-8, 1e-9), "m^2, m^2, rad^2 added", min=0)
    map_accuracy_m: float | Literal["auto"] = setting(
        "auto", "how well the map places its walls in the map frame (1 sigma, m), a floor no scan can see "
        "below: auto = the map's declared accuracy_m (its YAML; fgloc map writes what its self-check measured), "
        "else 0")


class NativeMatcher(FrontendBase):
    """Correlative search + robust LM on the surface distance field (see the module docstring)."""

    name = "native"

    def __init__(
        self,
        occ_map: OccupancyMap,
        laser_mount: StaticTransform | None = None,
        config: NativeConfig | None = None,
        **overrides: Any,
    ):
        conf = with_overrides(NativeConfig, config, overrides)
        self.config = conf
        super().__init__(occ_map, laser_mount, conf.preprocess)
        if conf.loss not in ("huber", "cauchy"):
            raise ConfigError(f"frontends config [native]: loss must be huber or cauchy, got {conf.loss!r}")
        if conf.search not in ("auto", "always", "never"):
            raise ConfigError(f"frontends config [native]: search must be auto, always or never, got {conf.search!r}")
        if len(conf.kernel_schedule_m) == 0 or len(conf.kernel_schedule_m) != len(conf.outlier_schedule_m):
            raise ConfigError(
                "frontends config [native]: kernel_schedule_m and outlier_schedule_m need equal, >0 lengths"
            )
        self.loss = LOSS_HUBER if conf.loss == "huber" else LOSS_CAUCHY
        self.scales = np.asarray(conf.kernel_schedule_m, dtype=float)
        self.outliers = np.asarray(conf.outlier_schedule_m, dtype=float)
        self.max_iterations = int(conf.max_iterations)
        self.tolerance = float(conf.tolerance)
        self.accept = FixAcceptance(self.name, conf)
        self.search = conf.search
        self.search_trigger = float(conf.search_trigger_inlier_fraction)
        self.search_window_m = float(conf.search_window_m)
        self.search_window = math.radians(conf.search_window_deg)
        self.search_lin_step = float(conf.search_lin_step_m)
        self.search_ang_step = math.radians(conf.search_ang_step_deg)
        self.search_max_points = int(conf.search_max_points)
        self.heading_window = math.radians(conf.heading_check_deg)
        self.heading_step = 0.5 * self.search_ang_step
        self.search_candidates = max(int(conf.search_candidates), 1)
        self.far = float(conf.field_max_dist_m)
        self.depth_min_quality = float(conf.depth_min_quality)
        self.map_accuracy_m = map_accuracy(occ_map, conf.map_accuracy_m, "native")
        self.floor_sigma_m = registration_sigma(self.map_accuracy_m, occ_map.resolution)
        self._lb = (float(self.pre.mount[0]), float(self.pre.mount[1]), float(conf.backface_cos))
        first = 1 if len(self.scales) > 1 else 0  # aliases: from the second annealing stage on (_fix_cov)
        self._alias_scales = np.ascontiguousarray(self.scales[first:])
        self._alias_outliers = np.ascontiguousarray(self.outliers[first:])
        kxy, kyaw = self.accept.cov_inflation
        self._cov_scale = (math.sqrt(kxy), math.sqrt(kyaw))

        k = max(int(conf.field_upsample), 1)
        # the field is zero on the faces; the surface depth is added per residual (adaptive in auto mode)
        self.auto_depth = isinstance(conf.surface_depth_cells, str)
        if self.auto_depth and conf.surface_depth_cells != "auto":
            raise ConfigError(f"frontends config [native]: surface_depth_cells must be a number or auto, "
                              f"got {conf.surface_depth_cells!r}")
        depth = 0.5 * occ_map.resolution if self.auto_depth else float(conf.surface_depth_cells) * occ_map.resolution
        self.depth_m = depth
        self._depth_updates = 0
        self.depth_window = int(conf.depth_window)
        self.field = np.ascontiguousarray(surface_distance_field(occ_map, k, self.far, 0.0), dtype=np.float64)
        # map-frame point -> fine-grid continuous coordinate with cell centres at integers
        c, s = math.cos(occ_map.origin[2]), math.sin(occ_map.origin[2])
        scale = k / occ_map.resolution
        self.A = np.array([[c, s], [-s, c]]) * scale
        self.b = -self.A @ occ_map.origin[:2] - 0.5
        # coarse likelihood field at map resolution for the correlative search
        dfc = np.abs(surface_distance_field(occ_map, 1, 3.0 * conf.search_sigma_m + occ_map.resolution, depth))
        self.lik = np.ascontiguousarray(np.exp(-0.5 * (dfc / float(conf.search_sigma_m)) ** 2))
        self.Ac = np.array([[c, s], [-s, c]]) / occ_map.resolution
        cls = np.zeros(occ_map.data.shape, dtype=np.uint8)  # 0 free, 1 occupied, 2 unknown
        cls[occ_map.occupied] = 1
        cls[occ_map.unknown] = 2
        self.cells = np.ascontiguousarray(cls)
        self.bc = -self.Ac @ occ_map.origin[:2] - 0.5


    # -------------------------------------------------------------- matching
    def _refine_from(self, px: FloatArray, py: FloatArray, start: FloatArray, first_stage: int = 0
                     ) -> tuple[FloatArray, float]:
        """LM from ``start`` over the annealing stages from ``first_stage`` on; the pose and its
        robust cost under the last stage's kernel."""
        pose, _, cost = _refine(
            self.field, self.A, self.b, self.far, px, py, np.asarray(start, dtype=float),
            self.scales[first_stage:], self.outliers[first_stage:], self.loss, self.max_iterations, self.tolerance,
            *self._lb, self.depth_m,
        )
        return pose, float(cost)

    def _laser_on_free(self, pose: FloatArray) -> bool:
        """Whether the laser at ``pose`` stands on a free cell of the map (the cells' convention of
        :func:`_beam_clear`).  A prediction gone metres off (intel's 240 m/s pose-delta twist put
        one 16.8 m away) stands in unknown space or in a wall."""
        lx, ly = self._lb[0], self._lb[1]
        c, s = math.cos(float(pose[2])), math.sin(float(pose[2]))
        ox = float(pose[0]) + c * lx - s * ly
        oy = float(pose[1]) + s * lx + c * ly
        u = self.Ac[0, 0] * ox + self.Ac[0, 1] * oy + self.bc[0] + 0.5
        v = self.Ac[1, 0] * ox + self.Ac[1, 1] * oy + self.bc[1] + 0.5
        h, w = self.cells.shape
        return bool(0.0 <= u < w and 0.0 <= v < h and self.cells[int(v), int(u)] == 0)

    def _stats_at(self, px: FloatArray, py: FloatArray, pose: FloatArray) -> tuple[Any, ...]:
        c, out = self.scales[-1], self.outliers[-1]
        return _stats(self.field, self.A, self.b, self.far, px, py, pose, c, self.loss, out,  # type: ignore[no-any-return]
                      self.accept.inlier_dist, *self._lb, self.depth_m, self.cells, self.Ac, self.bc)

    def _fix_cov(self, px: FloatArray, py: FloatArray, best: FloatArray, best_cost: float, stats: tuple[Any, ...],
                 Hinv: FloatArray, refined: list[tuple[FloatArray, float]]) -> tuple[FloatArray, float]:
        """The covariance of the fix ``best`` (see :func:`_fix_cov`) and ``s^2``: registration floor and
        ``cov_floor`` added.

        The aliases (other local maxima of the likelihood-field score along the fix's least
        constrained direction, ``ALIAS_RANGE_M``: a corridor's doors, a row of shelves) are refined
        from the second annealing stage on (when there are several): the first stage's wide kernel
        (outliers out to ``outlier_schedule_m[0]``, 1 m) pulls a start 0.25-2 m off back into the
        fix's own basin, which is no alias (on the office run with every scan matched, 156 of the 167
        alias refinements that weighed in ended within 4 mm of the fix); from the second stage the
        candidate settles where it is and is weighed by how well the scan fits there (aliases 0.2-0.9
        m off that weighed in: 10 from the first stage, 11 from the second), in 27 passes over the
        points instead of 37."""
        rposes = np.array([p for p, _ in refined], dtype=float).reshape(-1, 3)
        rcosts = np.array([c for _, c in refined], dtype=float)
        cov, sigma2 = _fix_cov(
            px, py, best, best_cost, stats[1], stats[2], int(stats[6]), Hinv, rposes, rcosts, *self._cov_scale,
            self.lik, self.Ac, self.bc, self._alias_stride(len(px)), ALIAS_STEP_M, ALIAS_STEPS, ALIAS_SCORE_RATIO,
            self.field, self.A, self.b, self.far, self._alias_scales, self._alias_outliers, self.loss,
            self.max_iterations, self.tolerance, *self._lb, self.depth_m, self.accept.cov_floor,
            self.floor_sigma_m <= 0,
        )
        if self.floor_sigma_m > 0:
            cov = self.accept.finish(cov + registration_floor(stats[0], self.floor_sigma_m))
        return cov, float(sigma2)

    def _alias_stride(self, n: int) -> int:
        """Every how many points of ``n`` the alias profile scores (``search_max_points`` at most)."""
        return max(1, int(math.ceil(n / max(self.search_max_points, 1))))

    def _fixed(self, pose: FloatArray, cov: FloatArray, sigma2: float, n_in: int, n: int, sum_r: float,
               info: dict[str, Any]) -> MatchResult:
        """The accepted fix; the auto surface depth follows it."""
        quality = n_in / n
        info["sigma_m"] = math.sqrt(sigma2)
        info["surface_depth_m"] = self.depth_m
        if self.auto_depth and quality >= self.depth_min_quality and n_in > 0:
            # the mean signed inlier residual says how far the walls are from where the map puts
            # them; a running mean over good fixes (a map property, kept across reset())
            self._depth_updates += 1
            est = self.depth_m - sum_r / n_in
            self.depth_m += (est - self.depth_m) / min(self._depth_updates, self.depth_window)
            self.depth_m = min(max(self.depth_m, 0.0), float(self.map.resolution))  # np.clip's value
        info["time_s"] = time.perf_counter() - info["time_s"]
        return MatchResult(True, pose, cov, quality=float(quality), reason="", n_inliers=n_in, info=info)

    def _match(self, points: FloatArray, guess: FloatArray, scan: LaserScan) -> MatchResult:
        t0 = time.perf_counter()
        px = np.ascontiguousarray(points[:, 0])
        py = np.ascontiguousarray(points[:, 1])
        n = len(px)
        searched = False
        best: FloatArray | None = None
        best_cost = np.inf
        best_stats: tuple[Any, ...] | None = None  # _stats at ``best`` when already computed
        best_cond: tuple[Any, ...] | None = None  # and its _conditioning
        need_search = self.search == "always"
        refined: list[tuple[FloatArray, float]] = []  # refined poses within the jump limit, with costs
        if self.search != "always":
            # the tracked scan: refined from the guess and, when no search is wanted and the fix
            # passes every test below, its covariance, all in one compiled call
            hstride = max(1, int(math.ceil(2 * n / max(self.search_max_points, 1))))
            a = self.accept
            pose, cost, stats, cond, done, fpose, n_unk, cov, sigma2 = _track_fix(
                self.field, self.A, self.b, self.far, px, py, guess, self.scales, self.outliers, self.loss,
                self.max_iterations, self.tolerance, *self._lb, self.depth_m, self.lik, self.Ac, self.bc, hstride,
                self.heading_window, self.heading_step, a.max_jump_m, a.max_jump, a.inlier_dist, self.cells,
                self.search_trigger if self.search == "auto" else -1.0, a.min_inliers, a.min_inlier_fraction,
                a.min_eigen_ratio, *self._cov_scale, self._alias_stride(n), ALIAS_STEP_M, ALIAS_STEPS,
                ALIAS_SCORE_RATIO, self._alias_scales, self._alias_outliers, a.cov_floor, self.floor_sigma_m <= 0,
            )
            if done:
                if self.floor_sigma_m > 0:
                    cov = a.finish(cov + registration_floor(stats[0], self.floor_sigma_m))
                info = {"searched": False, "time_s": t0, "n_points": n, "n_unknown": int(n_unk)}
                return self._fixed(fpose, cov, sigma2, int(stats[3]), n, stats[5], info)
            jump_ok = self.accept.within_jump(pose, guess)
            if jump_ok:
                refined.append((pose, cost))
            if jump_ok or self.search == "never":
                best, best_cost, best_stats, best_cond = pose, cost, stats, cond
            need_search = self.search == "auto" and not (jump_ok and stats[3] / n >= self.search_trigger)
        if need_search:
            searched = True
            stride = max(1, int(math.ceil(n / max(self.search_max_points, 1))))
            sx, sy = np.ascontiguousarray(px[::stride]), np.ascontiguousarray(py[::stride])
            cands, scores = correlative_search(
                self.lik, self.Ac, self.bc, sx, sy, guess, self.search_window_m, self.search_lin_step,
                self.search_window, self.search_ang_step, self.search_candidates,
            )
            for cand, sc in zip(cands, scores, strict=True):
                if sc <= 0:
                    continue
                pose, cost = self._refine_from(px, py, cand)
                if self.accept.within_jump(pose, guess):
                    refined.append((pose, cost))
                    if cost < best_cost:
                        best, best_cost, best_stats, best_cond = pose, cost, None, None
        if best is None:
            return no_fix(
                f"native: no pose within {self.accept.max_jump_m:.2f} m / {math.degrees(self.accept.max_jump):.0f} deg "
                "of the guess explains the scan"
            )
        if best_stats is None:
            best_stats = self._stats_at(px, py, best)
        pose = best.copy()
        pose[YAW] = wrap_scalar(pose[YAW])
        H, wr2, sw, n_in, n_used, sum_r, n_runs, n_unk = best_stats
        n_in = int(n_in)
        quality = n_in / n
        if n_unk and not self._laser_on_free(pose):
            n_unk = 0  # a laser outside the mapped free space is not looking into an unseen room
        info = {"searched": searched, "time_s": time.perf_counter() - t0, "n_points": n, "n_unknown": int(n_unk)}
        # the inlier fraction among the points the map can speak for: one ending in unknown space
        # (a room the map's passes never saw into) neither agrees nor disagrees, when the laser
        # itself stands on the map's free space; at least half the points count (a pose looking off
        # the map is not rescued)
        rejected = self.accept.too_few_inliers(n_in, max(n - int(n_unk), (n + 1) // 2), **info)
        if rejected is None:
            rejected = self.accept.jumped(pose, guess, n_in, quality, **info)
        if rejected is not None:
            return rejected
        # degeneracy: eigenvalues of H with yaw scaled by a typical range (metres per radian)
        ev0, ev2, Hinv = _conditioning(H, px, py) if best_cond is None else best_cond
        if not (math.isfinite(ev0) and math.isfinite(ev2) and ev0 > self.accept.min_eigen_ratio * ev2 and ev2 > 0):
            return no_fix(
                f"native: degenerate geometry (Hessian eigenvalue ratio {ev0 / max(ev2, 1e-300):.1e})",
                n_inliers=n_in, quality=quality, **info,
            )
        # beams of one run share its map error (sw / runs beams per independent error); distinct
        # refined candidates that explain the scan almost as well (a world changed since the map:
        # moved furniture offers a second alignment) widen it to their spread
        cov, sigma2 = self._fix_cov(px, py, best, best_cost, best_stats, Hinv, refined)
        info["time_s"] = t0
        return self._fixed(pose, cov, sigma2, n_in, n, sum_r, info)


def warmup() -> None:
    """Compile the numba kernels (cached on disk) on a tiny map."""
    data = np.zeros((40, 40), dtype=np.int16)
    data[0, :] = data[-1, :] = data[:, 0] = data[:, -1] = 100
    m = OccupancyMap(data, 0.1)
    matcher = NativeMatcher(m, None, search="always")
    ang = np.linspace(-np.pi, np.pi, 200, endpoint=False)
    r = m.raycast(np.array([2.0, 2.0]), ang, 10.0)
    scan = LaserScan(0.0, -np.pi, 2 * np.pi / 200, 0.05, 10.0, r.astype(np.float32))
    matcher.match(scan, np.array([2.0, 2.0, 0.0]))
    matcher.search = "auto"
    matcher.match(scan, np.array([2.0, 2.0, 0.0]))


__all__ = ["NativeMatcher", "distance_m", "edt_squared", "edt_squared_below", "map_distance_field",
           "registration_floor", "signed_field", "surface_distance_field", "warmup"]
