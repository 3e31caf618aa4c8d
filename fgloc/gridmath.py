"""Compiled grid primitives shared by the front-ends, the mapper and the map: one home each.

* :func:`bilinear` / :func:`bilinear_grad`: bilinear interpolation of a field sampled at
  integer grid coordinates (``field[row, col]`` at continuous ``(u, v) = (col, row)``),
  value only or value and ``(d/du, d/dv)``; a point outside ``[0, w-1] x [0, h-1]``
  gets ``outside`` (and a zero gradient).  Callers convert metres to grid units; for a
  field whose samples sit at cell centres that is ``u = (x - x0) / res - 0.5``.
* :func:`bilinear_grad_world`: the same for an axis-aligned grid given by its lower-left
  corner ``(x0, y0)`` and resolution, samples at cell centres, gradient in field units
  per metre.
* :func:`dda_init` / :func:`dda_next`: one grid ray traversal (Amanatides & Woo 1987):
  from continuous grid coordinates ``(x, y)`` along ``(dx, dy)`` cell by cell; ``t`` is
  the ray parameter at which the ray enters the returned cell (in units of
  ``|(dx, dy)|``: cells for a unit direction, the fraction of the segment for
  ``(dx, dy) = end - start``).
* :func:`raycast_grid`: the range to the first blocked cell for many rays.
* :func:`add_normal` / :func:`mirror_upper`: Gauss-Newton normal matrices ``H += w J^T J``
  over ``[x, y, yaw]``, accumulated in the upper triangle, then mirrored.
* :func:`run_step`: counts the "runs" of a scan's endpoints (neighbours closer than
  ``RUN_GAP_M``, at most ``RUN_LENGTH_M`` long: one stretch of wall whose map error all its
  beams share), for the matchers' covariances.

``njit`` is numba's (without numba, a no-op: the one copy of that fallback).
All functions are numba ``njit(cache=True)`` and are meant to be called from other
compiled kernels (numba inlines them); they are also callable from Python.
Note for developers: numba's on-disk cache of a kernel that calls these is keyed on the
*caller's* source file, so after editing this module clear the ``__pycache__/*.nbi``
files (or touch the callers) before measuring.
"""

from __future__ import annotations

import math

import numpy as np

try:  # numba is a declared dependency; the fallback keeps imports working without it
    from numba import njit
except ImportError:  # pragma: no cover
    def njit(*args, **kwargs):  # type: ignore[no-redef]
        def deco(f):
            return f
        return deco if not (args and callable(args[0])) else args[0]

__all__ = ["RUN_GAP_M", "RUN_LENGTH_M", "add_normal", "bilinear", "bilinear_grad", "bilinear_grad_world", "dda_init",
           "dda_next", "mirror_upper", "njit", "raycast_grid", "run_step"]

#: endpoints closer than RUN_GAP_M in scan order, over at most RUN_LENGTH_M, form one "run": a
#: stretch of one wall whose map error (raster, wall thickness) all its beams share
RUN_GAP_M = 0.3
RUN_LENGTH_M = 1.0


@njit(cache=True, inline="always")
def _cell(h, w, u, v):  # pragma: no cover - compiled
    """The grid cell holding ``(u, v) = (col, row)`` (samples at integers): its lower-left sample
    ``(x0, y0)`` and the fractions ``(fx, fy)`` in it; ``x0 = -1`` outside ``[0, w-1] x [0, h-1]``."""
    if not (u >= 0.0 and v >= 0.0 and u <= w - 1.0 and v <= h - 1.0):
        return -1, -1, 0.0, 0.0
    x0 = int(u)
    y0 = int(v)
    if x0 > w - 2:
        x0 = w - 2
    if y0 > h - 2:
        y0 = h - 2
    return x0, y0, u - x0, v - y0


@njit(cache=True, fastmath=True)
def bilinear(field, u, v, outside):  # pragma: no cover - compiled
    """Bilinear value of ``field`` at continuous ``(u, v) = (col, row)``, samples at integers."""
    h, w = field.shape
    x0, y0, fx, fy = _cell(h, w, u, v)
    if x0 < 0:
        return outside
    a = field[y0, x0] + fx * (field[y0, x0 + 1] - field[y0, x0])
    c = field[y0 + 1, x0] + fx * (field[y0 + 1, x0 + 1] - field[y0 + 1, x0])
    return a + fy * (c - a)


@njit(cache=True, fastmath=True)
def bilinear_grad(field, u, v, outside):  # pragma: no cover - compiled
    """Bilinear value and ``(d/du, d/dv)`` of ``field`` at ``(u, v) = (col, row)``; ``(outside, 0, 0)`` off it."""
    h, w = field.shape
    x0, y0, fx, fy = _cell(h, w, u, v)
    if x0 < 0:
        return outside, 0.0, 0.0
    d00 = field[y0, x0]
    d10 = field[y0, x0 + 1]
    d01 = field[y0 + 1, x0]
    d11 = field[y0 + 1, x0 + 1]
    a = d10 - d00
    c = d11 - d01
    val = d00 + fx * a + fy * (d01 - d00 + fx * (c - a))
    du = a + fy * (c - a)
    dv = (d01 - d00) + fx * (d11 - d10 - d01 + d00)
    return val, du, dv


@njit(cache=True, fastmath=True)
def bilinear_grad_world(field, x0, y0, res, outside, x, y):  # pragma: no cover - compiled
    """:func:`bilinear_grad` of a field sampled at cell centres of an axis-aligned grid.

    ``(x0, y0)``: the grid's lower-left corner (m), ``res`` m/cell; returns the value and
    its gradient per metre ``(d/dx, d/dy)`` at the map-frame point ``(x, y)``.
    """
    d, gu, gv = bilinear_grad(field, (x - x0) / res - 0.5, (y - y0) / res - 0.5, outside)
    return d, gu / res, gv / res


@njit(cache=True)
def dda_init(x, y, dx, dy):  # pragma: no cover - compiled
    """Start a grid traversal at continuous ``(x, y)`` (cell ``(floor(y), floor(x))``) along ``(dx, dy)``.

    Returns ``(cx, cy, step_x, step_y, t_max_x, t_max_y, t_delta_x, t_delta_y)``.
    """
    cx, step_x, t_max_x, t_delta_x = _dda_axis(x, dx)
    cy, step_y, t_max_y, t_delta_y = _dda_axis(y, dy)
    return cx, cy, step_x, step_y, t_max_x, t_max_y, t_delta_x, t_delta_y


@njit(cache=True, inline="always")
def _dda_axis(x, dx):  # pragma: no cover - compiled
    """One axis of :func:`dda_init`: the cell ``floor(x)``, the step, the ray parameter of the first
    cell border and the parameter between borders (``inf`` for a ray parallel to the axis)."""
    c = int(np.floor(x))
    step = 1 if dx > 0 else -1
    if dx == 0.0:
        return c, step, np.inf, np.inf
    t_delta = abs(1.0 / dx)
    return c, step, ((c + 1 - x) if dx > 0 else (x - c)) * t_delta, t_delta


@njit(cache=True)
def dda_next(cx, cy, step_x, step_y, t_max_x, t_max_y, t_delta_x, t_delta_y):  # pragma: no cover - compiled
    """Step to the next cell; returns ``(cx, cy, t_max_x, t_max_y, t)``, ``t`` where the ray enters it."""
    if t_max_x < t_max_y:
        return cx + step_x, cy, t_max_x + t_delta_x, t_max_y, t_max_x
    return cx, cy + step_y, t_max_x, t_max_y + t_delta_y, t_max_y


@njit(cache=True)
def raycast_grid(blocked, gx, gy, dx, dy, max_cells):  # pragma: no cover - compiled
    """Range (cells) along unit directions ``(dx, dy)`` from ``(gx, gy)`` to the first ``blocked`` cell.

    ``+inf`` when nothing is hit within ``max_cells`` or the ray leaves the grid; 0 for a
    ray starting in a blocked cell.
    """
    h, w = blocked.shape
    n = gx.shape[0]
    out = np.empty(n)
    for k in range(n):
        x, y = gx[k], gy[k]
        out[k] = np.inf
        if not (0.0 <= x < w and 0.0 <= y < h):
            continue
        cx, cy, sx, sy, tmx, tmy, tdx, tdy = dda_init(x, y, dx[k], dy[k])
        if blocked[cy, cx]:
            out[k] = 0.0
            continue
        while True:
            cx, cy, tmx, tmy, t = dda_next(cx, cy, sx, sy, tmx, tmy, tdx, tdy)
            if t > max_cells:
                break
            if cx < 0 or cy < 0 or cx >= w or cy >= h:
                break
            if blocked[cy, cx]:
                out[k] = t
                break
    return out


@njit(cache=True, inline="always")
def run_step(x, y, last_x, last_y, run_len):  # pragma: no cover - compiled
    """The next endpoint ``(x, y)`` of a scan after ``(last_x, last_y)`` in a run ``run_len`` long:
    ``(1, 0.0)`` when it starts a new run (farther than ``RUN_GAP_M``, or the run would exceed
    ``RUN_LENGTH_M``), else ``(0, the run's new length)``.  Start with ``last_x = last_y = 1e300``."""
    step = math.hypot(x - last_x, y - last_y)
    if step > RUN_GAP_M or run_len + step > RUN_LENGTH_M:
        return 1, 0.0
    return 0, run_len + step


@njit(cache=True, inline="always")
def add_normal(H, w, j0, j1, j2):  # pragma: no cover - compiled
    """``H += w J^T J`` in the upper triangle of the 3x3 ``H``, for one Jacobian row ``J = [j0, j1, j2]``."""
    w0 = w * j0
    w1 = w * j1
    w2 = w * j2
    H[0, 0] += w0 * j0
    H[0, 1] += w0 * j1
    H[0, 2] += w0 * j2
    H[1, 1] += w1 * j1
    H[1, 2] += w1 * j2
    H[2, 2] += w2 * j2


@njit(cache=True, inline="always")
def mirror_upper(H):  # pragma: no cover - compiled
    """Copy the upper triangle of the 3x3 ``H`` to the lower one."""
    H[1, 0] = H[0, 1]
    H[2, 0] = H[0, 2]
    H[2, 1] = H[1, 2]
