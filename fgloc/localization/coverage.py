"""How much of a scan the map can speak for at a pose: the robot may be where the map has nothing.

A building partly mapped, a wing added since the map was made, a SLAM map built from other passes:
the robot drives through space the map leaves *unknown*.  There the front-end rightly finds no fix,
but "no fix" is then no evidence that the pose is wrong, and the localizer must not declare itself
lost and jump to the best-looking place elsewhere in the map (on the MIT-CSAIL segment of
``tools/eval_frontends_real.py``, 56 % covered by the map of the other passes, such jumps put the
estimate 33-36 m off).  :func:`unmapped_share` tells the two apart: the share of the scan's beams
that, cast from the pose, end in the map's unknown space (or off its grid) without crossing an
occupied cell.  Such a beam neither agrees nor disagrees with the map.  A beam that crossed a
mapped wall to get there contradicts the map (a wrong pose looking through walls), and one that
ends on free or occupied cells is judged by the map as usual.  A kidnapped robot's scan, cast from
where it was, mostly crosses mapped walls or ends on mapped cells; a robot in an unmapped wing,
at its (right) dead-reckoned pose, sees mostly unknown space.

Core maths only: no I/O.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from fgloc.geometry import compose_values
from fgloc.gridmath import raycast_grid
from fgloc.maps import OccupancyMap
from fgloc.types import LaserScan, StaticTransform

#: the beams are marched in steps of this many cells (a crossed wall is at least one cell thick)
MARCH_STEP_CELLS = 0.5
#: a scan whose beams, cast from the pose, mostly end in the map's unknown space (crossing no mapped wall) is
#: one the map cannot judge
UNMAPPED_SHARE = 0.5
#: a beam whose ray-cast range is within this of the measured one in log (10 %) fits the map (range_fit)
RANGE_FIT_LOG = 0.1


def _laser_in_map(laser_mount: StaticTransform, pose: np.ndarray) -> tuple[float, float, float]:
    """The laser's position and heading in the map frame at the ``base_link`` pose ``pose`` (the heading
    not wrapped: the beams' angles are taken from it)."""
    m = np.asarray(laser_mount.pose, dtype=float)
    p = np.asarray(pose, dtype=float).reshape(3)
    ox, oy, _ = compose_values(p, m)
    return ox, oy, float(p[2]) + float(m[2])


def unmapped_share(occ_map: OccupancyMap, laser_mount: StaticTransform, scan: LaserScan,
                   pose: np.ndarray) -> float:
    """Share (0..1) of ``scan``'s valid beams that, cast from the ``base_link`` pose ``pose`` (map
    frame), end in the map's unknown space or off its grid without crossing an occupied cell: beams
    the map cannot speak for (see the module docstring).  0 for a scan without valid beams."""
    pts = scan.points()
    n = len(pts)
    if n == 0:
        return 0.0
    ox, oy, yaw = _laser_in_map(laser_mount, pose)
    c, s = math.cos(yaw), math.sin(yaw)
    qx = ox + c * pts[:, 0] - s * pts[:, 1]
    qy = oy + s * pts[:, 0] + c * pts[:, 1]
    h, w = occ_map.data.shape
    g = occ_map.world_to_grid_continuous(np.column_stack([qx, qy]))  # (col, row)
    u1, v1 = g[:, 0], g[:, 1]
    i1, j1 = np.floor(v1).astype(np.int64), np.floor(u1).astype(np.int64)
    on = (i1 >= 0) & (i1 < h) & (j1 >= 0) & (j1 < w)
    end_unknown = ~on
    end_unknown[on] = occ_map.data[i1[on], j1[on]] < 0
    k = np.nonzero(end_unknown)[0]
    if len(k) == 0:
        return 0.0
    u0, v0 = occ_map.world_to_grid_continuous([[ox, oy]])[0]
    du, dv = u1[k] - u0, v1[k] - v0
    steps = int(math.ceil(float(np.max(np.maximum(np.abs(du), np.abs(dv)))) / MARCH_STEP_CELLS)) + 1
    f = np.linspace(0.0, 1.0, steps)[None, :]
    ii = np.floor(v0 + f * dv[:, None]).astype(np.int64)
    jj = np.floor(u0 + f * du[:, None]).astype(np.int64)
    inside = (ii >= 0) & (ii < h) & (jj >= 0) & (jj < w)
    crossed = np.zeros(ii.shape, dtype=bool)
    crossed[inside] = occ_map.occupied_mask(occ_map.data[ii[inside], jj[inside]])
    clear = ~crossed.any(axis=1)
    return float(np.count_nonzero(clear)) / n


def range_residuals(occ_map: OccupancyMap, laser_mount: StaticTransform, scan: LaserScan, pose: np.ndarray,
                    max_beams: int = 64, min_beams: int = 10, blocked: NDArray[np.bool_] | None = None
                    ) -> NDArray[np.float64] | None:
    """The map's ranges against the laser's at the ``base_link`` pose ``pose``: over at most ``max_beams`` of
    ``scan``'s returns (evenly spread) that end on a wall within ``range_max``, ``log(cast / measured)`` with
    ``cast`` the range ray-cast in the map from the laser to its first occupied cell (beams whose cast leaves the
    grid or ``range_max`` are not counted); None with fewer than ``min_beams`` beams.  ``blocked``: the map's
    occupied grid (C-contiguous), when the caller keeps it (made anew otherwise: most of the cost on a large
    map)."""
    r = np.asarray(scan.ranges, dtype=float)
    with np.errstate(invalid="ignore"):
        hit = np.isfinite(r) & (r >= max(scan.range_min, 0.0)) & (r < 0.99 * scan.range_max) & (r > 0)
    idx = np.nonzero(hit)[0]
    if len(idx) < min_beams:
        return None
    if len(idx) > max_beams:
        idx = idx[np.linspace(0, len(idx) - 1, max_beams).round().astype(np.int64)]
    ox, oy, yaw = _laser_in_map(laser_mount, pose)
    ang = yaw + scan.angle_min + scan.angle_increment * idx.astype(float)
    if blocked is None:
        blocked = np.ascontiguousarray(occ_map.occupied)
    g = occ_map.world_to_grid_continuous([[ox, oy]])[0]
    local = ang - float(occ_map.origin[2])
    n = len(local)
    cast = raycast_grid(blocked, np.full(n, float(g[0])), np.full(n, float(g[1])), np.cos(local), np.sin(local),
                        float(scan.range_max) / occ_map.resolution) * occ_map.resolution
    keep = np.isfinite(cast) & (cast > 0) & (cast < 0.99 * scan.range_max)
    if np.count_nonzero(keep) < min_beams:
        return None
    return np.log(cast[keep] / r[idx][keep])


def range_fit(occ_map: OccupancyMap, laser_mount: StaticTransform, scan: LaserScan, pose: np.ndarray,
              max_beams: int = 64, min_beams: int = 10, blocked: NDArray[np.bool_] | None = None
              ) -> tuple[float, float]:
    """How the map's ranges compare with the laser's at the ``base_link`` pose ``pose`` (:func:`range_residuals`
    ``log(cast / measured)``): its median and the share of the beams within :data:`RANGE_FIT_LOG` of 0 (NaN, NaN
    with fewer than ``min_beams`` beams).  On the map of this building at the right pose most beams fit (people,
    glass, moved furniture move some beams, not most); on a map whose cells are read at another size few do,
    wherever the pose."""
    lr = range_residuals(occ_map, laser_mount, scan, pose, max_beams, min_beams, blocked)
    if lr is None:
        return math.nan, math.nan
    return float(np.median(lr)), float(np.mean(np.abs(lr) < RANGE_FIT_LOG))


def beyond_walls(lr: NDArray[np.float64]) -> float:
    """The share of beams whose measured range ends beyond the map's wall by more than :data:`RANGE_FIT_LOG`
    (of :func:`range_residuals`' ``lr``): the laser saw through where the map has a wall.  What the map lacks
    (people, pallets, moved furniture) shortens beams; only a wall the building does not have there (an open
    door, furniture gone, or a map whose walls are elsewhere: mirrored, of another version) lengthens them."""
    return float(np.mean(lr < -RANGE_FIT_LOG)) if len(lr) else math.nan


__all__ = ["MARCH_STEP_CELLS", "UNMAPPED_SHARE", "RANGE_FIT_LOG", "beyond_walls", "range_fit", "range_residuals",
           "unmapped_share"]
