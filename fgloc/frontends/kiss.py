"""KISS-ICP registration of a scan against the map (``kiss`` front-end).

The map's occupied cells become a *static* ``kiss_icp`` ``VoxelHashMap`` at ``z = 0``:
each face of an occupied cell that borders a free cell (the surfaces a beam can
hit) is densified into ``samples_per_face`` points, so the points lie where beam
endpoints lie, not half a cell behind them at the cell centres.  The scan
(de-skewed, ``base_link``, ``z = 0``) is aligned with kiss_icp's own point-to-point
registration (``kiss_icp.registration.Registration.align_points_to_map``, robust
Geman-McClure kernel) from the prior guess, first on a coarse voxel map with a
wide correspondence distance (robust to a guess ~0.5 m / 15 deg off), then on the
fine one.  The 6-DoF result is projected to SE(2) (x, y, yaw).

Covariance: the point-to-point Hessian at the solution, computed here from the
nearest-neighbour correspondences (a KD-tree over the same surface points):
``H = sum w J^T J`` with ``J = [I2 | dR/dyaw p]``, ``cov = S s^2 H^-1 S + diag(cov_floor)``,
``s^2`` the weighted residual variance per axis, ``S = diag(sqrt(kxy), sqrt(kxy),
sqrt(kyaw))`` from ``cov_inflation = [kxy, kyaw]``: beams are not independent, so the
inflation is calibrated (``fgloc config show``: frontends.kiss).  A doubtful optimum (inlier
fraction below ``retry_inlier_fraction``) is re-registered from starts around it and
the start with most inliers wins.
Fixes with too few inliers (correspondences closer than ``inlier_dist_m``), a
degenerate Hessian or a jump from the guess beyond ``max_jump_*`` are rejected.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from fgloc.config.schema import section, setting, with_overrides
from fgloc.errors import ConfigError
from fgloc.geometry import YAW, compose, from_matrix, to_matrix4, wrap_angle
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


def surface_points(
    occ_map: OccupancyMap, samples_per_face: int = 2, depth_cells: float = 0.0
) -> tuple[FloatArray, FloatArray]:
    """Points ``(N, 2)`` on the faces of occupied cells that border non-occupied (free or
    unknown) cells, and their outward unit normals ``(N, 2)`` (pointing out of the
    obstacle), both in the map frame.  Off-grid neighbours count as non-occupied.
    ``depth_cells`` moves the points that far into the cell (0.5: the cell centre line)."""
    occ = occ_map.occupied
    free = ~occ
    h, w = occ.shape
    k = max(int(samples_per_face), 1)
    offs = (np.arange(k) + 0.5) / k  # along the face, in cells
    cols: list[FloatArray] = []
    rows: list[FloatArray] = []
    normals: list[FloatArray] = []
    # (d_row, d_col) to the free neighbour; the face is half a cell from the centre that way
    for dr, dc in ((1, 0), (-1, 0), (0, 1), (0, -1)):
        nb_free = np.ones_like(occ)
        src_r = slice(max(dr, 0), h + min(dr, 0))
        dst_r = slice(max(-dr, 0), h + min(-dr, 0))
        src_c = slice(max(dc, 0), w + min(dc, 0))
        dst_c = slice(max(-dc, 0), w + min(-dc, 0))
        nb_free[dst_r, dst_c] = free[src_r, src_c]
        r_idx, c_idx = np.nonzero(occ & nb_free)
        if len(r_idx) == 0:
            continue
        # continuous grid coordinates (cell (r, c) spans [c, c+1) x [r, r+1))
        if dr != 0:
            y = r_idx + (1.0 if dr > 0 else 0.0)
            rows.append(np.repeat(y, k).astype(float))
            cols.append((c_idx[:, None] + offs[None, :]).reshape(-1))
        else:
            x = c_idx + (1.0 if dc > 0 else 0.0)
            cols.append(np.repeat(x, k).astype(float))
            rows.append((r_idx[:, None] + offs[None, :]).reshape(-1))
        normals.append(np.tile([float(dc), float(dr)], (len(r_idx) * k, 1)))
    if not cols:
        return np.zeros((0, 2)), np.zeros((0, 2))
    gx = np.concatenate(cols) * occ_map.resolution
    gy = np.concatenate(rows) * occ_map.resolution
    c, s = math.cos(occ_map.origin[2]), math.sin(occ_map.origin[2])
    pts = np.column_stack([occ_map.origin[0] + c * gx - s * gy, occ_map.origin[1] + s * gx + c * gy])
    ng = np.concatenate(normals)
    nrm = np.column_stack([c * ng[:, 0] - s * ng[:, 1], s * ng[:, 0] + c * ng[:, 1]])
    pts = pts - float(depth_cells) * occ_map.resolution * nrm
    return pts, nrm


@dataclass(frozen=True)
class KissConfig:
    """``frontends.kiss``: kiss_icp registration against the map (defaults here and only here)."""

    preprocess: PreprocessOptions = section(PreprocessOptions, "scan preprocessing shared by the front-ends")
    samples_per_face: int = setting(2, "map points per face of an occupied cell bordering a non-occupied one", min=1)
    surface_depth_cells: float = setting(0.5, "the map points moved this far into the cell (as native, fixed)",
                                         min=0, max=1)
    coarse_voxel_size_m: float = setting(0.8, "coarse stage (robust to a guess ~0.5 m / 15 deg off)", gt=0)
    coarse_max_points_per_voxel: int = setting(64, "coarse stage", min=1)
    coarse_max_correspondence_m: float = setting(1.5, "coarse stage; 0 skips it", min=0)
    coarse_kernel_m: float = setting(0.5, "coarse stage robust kernel", gt=0)
    coarse_max_iterations: int = setting(50, "coarse stage", min=1)
    coarse_convergence_criterion: float = setting(1e-4, "coarse stage", gt=0)
    voxel_size_m: float = setting(0.25, "fine stage voxel size", gt=0)
    max_points_per_voxel: int = setting(150, "fine stage", min=1)
    max_correspondence_m: float = setting(0.25, "fine stage", gt=0)
    kernel_m: float = setting(0.05, "fine stage robust kernel", gt=0)
    max_iterations: int = setting(50, "fine stage", min=1)
    convergence_criterion: float = setting(1e-5, "fine stage", gt=0)
    max_threads: int = setting(1, "kiss_icp TBB threads (0 = all cores)", min=0)
    inlier_dist_m: float = setting(0.1, "|residual| below this is an inlier", gt=0)
    min_inliers: int = setting(30, "fewer inliers -> no fix", min=0)
    min_inlier_fraction: float = setting(0.4, "smaller inlier fraction -> no fix", min=0, max=1)
    max_jump_m: float = setting(1.0, "farther from the guess -> no fix", gt=0)
    max_jump_deg: float = setting(30.0, "more heading change from the guess -> no fix", gt=0)
    min_eigen_ratio: float = setting(1e-3, "smallest/largest Hessian eigenvalue below this -> no fix", min=0)
    cov_inflation: tuple[float, ...] = setting((17.0, 36.0), "[kxy, kyaw] as for native", gt=0)
    cov_floor: tuple[float, float, float] = setting((1e-8, 1e-8, 1e-9), "m^2, m^2, rad^2 added", min=0)
    map_accuracy_m: float | Literal["auto"] = setting(
        "auto", "map registration floor as for native (auto: the map's accuracy_m, else 0)")
    max_backface_fraction: float = setting(0.5, "still more inliers on the back of walls after the retry -> no fix",
                                           min=0, max=1)
    retry_backface_fraction: float = setting(0.1, "more inliers on the back of walls -> retry on front-facing "
                                             "surfaces", min=0, max=1)
    retry_inlier_fraction: float = setting(0.9, "fewer inliers -> restart from the optimum moved by the offsets",
                                           min=0, max=1)
    retry_offset_m: float = setting(0.15, "restart offset in x and y (base frame)", min=0)
    retry_offset_deg: float = setting(5.0, "restart offset in yaw", min=0)


class KissMatcher(FrontendBase):
    """kiss_icp point-to-point registration against a static voxel map of the occupied surfaces."""

    name = "kiss"

    def __init__(
        self,
        occ_map: OccupancyMap,
        laser_mount: StaticTransform | None = None,
        config: KissConfig | None = None,
        **overrides: Any,
    ):
        conf = with_overrides(KissConfig, config, overrides)
        self.config = conf
        super().__init__(occ_map, laser_mount, conf.preprocess)
        self.map_accuracy_m = map_accuracy(occ_map, conf.map_accuracy_m, "kiss")
        self.floor_sigma_m = registration_sigma(self.map_accuracy_m, occ_map.resolution)
        try:
            from kiss_icp.mapping import VoxelHashMap
            from kiss_icp.registration import Registration
        except ImportError as e:  # pragma: no cover - kiss-icp is a declared dependency
            raise ConfigError(f"front-end 'kiss' needs kiss-icp ({e})") from None
        from scipy.spatial import cKDTree

        pts2, self.map_normals = surface_points(occ_map, conf.samples_per_face, conf.surface_depth_cells)
        if len(pts2) == 0:
            raise ConfigError("front-end 'kiss': the map has no occupied cell bordering free space")
        pts3 = np.column_stack([pts2, np.zeros(len(pts2))])
        big = 1e9  # static map: never drop points for distance
        self.coarse_map = VoxelHashMap(float(conf.coarse_voxel_size_m), big, int(conf.coarse_max_points_per_voxel))
        self.coarse_map.add_points(pts3)
        self.fine_map = VoxelHashMap(float(conf.voxel_size_m), big, int(conf.max_points_per_voxel))
        self.fine_map.add_points(pts3)
        self.map_points = pts2
        self.tree = cKDTree(pts2)
        self._voxel_map_cls = VoxelHashMap
        self._map_args = (
            (float(conf.coarse_voxel_size_m), big, int(conf.coarse_max_points_per_voxel)),
            (float(conf.voxel_size_m), big, int(conf.max_points_per_voxel)),
        )
        self.max_backface_fraction = float(conf.max_backface_fraction)
        self.retry_backface_fraction = float(conf.retry_backface_fraction)
        self.retry_fraction = float(conf.retry_inlier_fraction)
        dm, da = float(conf.retry_offset_m), math.radians(float(conf.retry_offset_deg))
        self.retry_offsets = [np.array(v) for v in (
            (0.0, 0.0, da), (0.0, 0.0, -da), (dm, 0.0, 0.0), (-dm, 0.0, 0.0), (0.0, dm, 0.0), (0.0, -dm, 0.0))]
        self.registration = Registration(int(conf.max_iterations), float(conf.convergence_criterion),
                                         int(conf.max_threads))
        self.coarse_registration = Registration(int(conf.coarse_max_iterations),
                                                float(conf.coarse_convergence_criterion), int(conf.max_threads))
        self.coarse_corr = float(conf.coarse_max_correspondence_m)
        self.coarse_kernel = float(conf.coarse_kernel_m)
        self.max_corr = float(conf.max_correspondence_m)
        self.kernel = float(conf.kernel_m)
        self.accept = FixAcceptance(self.name, conf)

    def _register(self, pts3: FloatArray, guess: FloatArray, coarse: Any, fine: Any) -> FloatArray | None:
        T = to_matrix4(guess)
        if self.coarse_corr > 0:
            T = self.coarse_registration.align_points_to_map(pts3, coarse, T, self.coarse_corr, self.coarse_kernel)
        T = self.registration.align_points_to_map(pts3, fine, T, self.max_corr, self.kernel)
        if not np.all(np.isfinite(T)):
            return None
        pose = from_matrix(T)
        pose[YAW] = wrap_angle(pose[YAW])
        return pose

    def _associate(
        self, points: FloatArray, pose: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray, float]:
        """World points, NN distances, NN indices, and the back-face fraction among the inliers."""
        c, s = math.cos(pose[2]), math.sin(pose[2])
        q = np.column_stack([pose[0] + c * points[:, 0] - s * points[:, 1],
                             pose[1] + s * points[:, 0] + c * points[:, 1]])
        dist, idx = self.tree.query(q, distance_upper_bound=self.max_corr)
        inl = dist < self.accept.inlier_dist
        if not inl.any():
            return q, dist, idx, 0.0
        lx, ly = self.pre.mount[0], self.pre.mount[1]
        origin = np.array([pose[0] + c * lx - s * ly, pose[1] + s * lx + c * ly])
        beam = q[inl] - origin
        back = np.sum(beam * self.map_normals[idx[inl]], axis=1) > 0
        return q, dist, idx, float(back.mean())

    def _front_facing_maps(self, guess: FloatArray, reach: float) -> tuple[Any, Any]:
        """Voxel maps of only the surfaces near the guess that face it (a beam from there can hit them)."""
        d = self.map_points - guess[:2]
        keep = (np.sum(d * self.map_normals, axis=1) < 0) & (np.sum(d * d, axis=1) < reach * reach)
        pts3 = np.column_stack([self.map_points[keep], np.zeros(int(keep.sum()))])
        maps = []
        for args in self._map_args:
            vm = self._voxel_map_cls(*args)
            vm.add_points(pts3)
            maps.append(vm)
        return maps[0], maps[1]

    def _match(self, points: FloatArray, guess: FloatArray, scan: LaserScan) -> MatchResult:
        t0 = time.perf_counter()
        n = len(points)
        pts3 = np.ascontiguousarray(np.column_stack([points, np.zeros(n)]))
        pose = self._register(pts3, guess, self.coarse_map, self.fine_map)
        if pose is None:
            return no_fix("kiss: registration diverged (non-finite transform)")
        q, dist, idx, back = self._associate(points, pose)
        recovered = False
        if back > self.retry_backface_fraction:
            # landed on the far side of a thin wall: redo against the surfaces facing the guess
            reach = float(np.sqrt(np.max(np.sum(points * points, axis=1)))) + self.accept.max_jump_m + 1.0
            coarse, fine = self._front_facing_maps(guess, reach)
            alt = self._register(pts3, guess, coarse, fine)
            if alt is not None:
                q2, dist2, idx2, back2 = self._associate(points, alt)
                if back2 < back:
                    pose, q, dist, idx, back, recovered = alt, q2, dist2, idx2, back2, True
        restarts = 0
        if np.count_nonzero(dist < self.accept.inlier_dist) < self.retry_fraction * n:
            # a doubtful optimum (ICP's local minima): restart around it (yaw, then x, y offsets), keep the best
            best = (int(np.count_nonzero(dist < self.accept.inlier_dist)), pose, q, dist, idx, back)
            for d in self.retry_offsets:
                start = compose(pose, d)  # around the doubtful optimum
                alt = self._register(pts3, start, self.coarse_map, self.fine_map)
                restarts += 1
                if alt is None:
                    continue
                q2, dist2, idx2, back2 = self._associate(points, alt)
                n2 = int(np.count_nonzero(dist2 < self.accept.inlier_dist))
                if n2 > best[0] and back2 <= max(back, self.retry_backface_fraction):
                    best = (n2, alt, q2, dist2, idx2, back2)
                if n2 >= self.retry_fraction * n:
                    break
            _, pose, q, dist, idx, back = best
        c, s = math.cos(pose[2]), math.sin(pose[2])
        used = np.isfinite(dist)
        inl = dist < self.accept.inlier_dist
        n_in = int(inl.sum())
        quality = n_in / n
        info: dict[str, Any] = {"time_s": time.perf_counter() - t0, "n_points": n, "backface": back,
                                "recovered": recovered, "restarts": restarts}
        rejected = self.accept.too_few_inliers(n_in, n, **info)
        if rejected is not None:
            return rejected
        if back > self.max_backface_fraction:
            return no_fix(f"kiss: matched points lie on the back of walls ({100 * back:.0f} %)",
                          n_inliers=n_in, quality=quality, **info)
        rejected = self.accept.jumped(pose, guess, n_in, quality, **info)
        if rejected is not None:
            return rejected
        e = q[used] - self.map_points[idx[used]]
        r2 = np.sum(e * e, axis=1)
        w = (self.kernel ** 2) / (self.kernel + r2) ** 2  # kiss_icp's Geman-McClure weight (same form)
        w = w / w.max()
        p = points[used]
        jy = np.column_stack([-s * p[:, 0] - c * p[:, 1], c * p[:, 0] - s * p[:, 1]])  # d q / d yaw
        H = np.zeros((3, 3))
        H[0, 0] = H[1, 1] = w.sum()
        H[0, 2] = H[2, 0] = float(np.sum(w * jy[:, 0]))
        H[1, 2] = H[2, 1] = float(np.sum(w * jy[:, 1]))
        H[2, 2] = float(np.sum(w * np.sum(jy * jy, axis=1)))
        lever = float(np.sqrt(np.mean(np.sum(p * p, axis=1)))) or 1.0
        S = np.diag([1.0, 1.0, 1.0 / lever])
        ev = np.linalg.eigvalsh(S @ H @ S)
        if not (np.all(np.isfinite(ev)) and ev[-1] > 0 and ev[0] > self.accept.min_eigen_ratio * ev[-1]):
            return no_fix("kiss: degenerate geometry (point-to-point Hessian near singular)",
                          n_inliers=n_in, quality=quality, **info)
        sigma2 = float(np.sum(w * r2)) / max(2.0 * w.sum() - 3.0, 1.0)
        cov = self.accept.finish(self.accept.inflate(sigma2 * np.linalg.inv(H))
                                 + registration_floor(H, self.floor_sigma_m))
        info["sigma_m"] = math.sqrt(sigma2)
        info["time_s"] = time.perf_counter() - t0
        return MatchResult(True, pose, cov, quality=float(quality), reason="", n_inliers=n_in, info=info)


__all__ = ["KissMatcher", "surface_points"]
