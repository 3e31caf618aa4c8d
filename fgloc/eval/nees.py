"""How honest a trajectory's covariances are: the NEES of its poses against a reference.

Pure maths on :class:`fgloc.types.Trajectory` (no printing, no files).

Each estimated pose is associated with the reference as :func:`fgloc.eval.metrics.associate` does
(the reference interpolated at the pose's stamp, never across a gap); its error ``e = [ex_m, ey_m,
eyaw_rad]`` (estimate minus reference, map frame, yaw wrapped) is weighed by the pose's own 3x3
covariance ``P`` (m^2, m rad, rad^2, the order of ``trajectory_status.csv``'s ``cov_*`` columns):
``NEES = e^T P^-1 e``.  When the covariances are honest (the errors zero-mean Gaussian with
covariance ``P``) the NEES is chi-square with 3 degrees of freedom: mean 3, median 2.37, and 95 %
of the poses inside :data:`CHI2_3DOF_95` (7.81).  A mean far above 3 says the covariances are too
small (overconfident), far below too large; the per-axis means ``e_i^2 / P_ii`` (1 each when honest)
say which axis.  The poses of one run are correlated in time, so a run's mean NEES spreads far more
than chi-square over independent poses would (``docs/results/consistency.md`` states the band).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields

import numpy as np
from numpy.typing import NDArray

from fgloc.eval.metrics import DEFAULT_MAX_GAP_S, Association, associate, nees_summary
from fgloc.geometry import YAW, wrap_angle
from fgloc.types import Trajectory

FloatArray = NDArray[np.float64]

#: chi-square with 3 degrees of freedom: its 95th percentile and its median
CHI2_3DOF_95 = 7.814727903251178
CHI2_3DOF_MEDIAN = 2.3659738843753377


def pose_nees(err: FloatArray, cov: FloatArray) -> FloatArray:
    """``e^T P^-1 e`` per pose: ``err`` (N x 3, ``[ex_m, ey_m, eyaw_rad]``), ``cov`` (N x 3 x 3).
    NaN where the covariance is not finite or not positive definite (no NEES can be said)."""
    e = np.asarray(err, dtype=float).reshape(-1, 3)
    P = np.asarray(cov, dtype=float).reshape(-1, 3, 3)
    out = np.full(len(e), np.nan)
    ok = np.all(np.isfinite(P), axis=(1, 2)) & np.all(np.isfinite(e), axis=1)
    if np.any(ok):
        Ps = 0.5 * (P[ok] + np.swapaxes(P[ok], 1, 2))
        w = np.linalg.eigvalsh(Ps)
        pd = w[:, 0] > 1e-12 * np.maximum(w[:, -1], 1e-300)
        idx = np.flatnonzero(ok)[pd]
        if len(idx):
            sol = np.linalg.solve(Ps[pd], e[idx][..., None])[..., 0]
            out[idx] = np.einsum("ni,ni->n", e[idx], sol)
    return out


@dataclass
class NeesMetrics:
    """The NEES of a trajectory's poses (units in the names; NaN when it cannot be said).

    ``n``: poses with a usable covariance; ``n_without_cov``: associated poses without one (not
    counted in the rest).  ``nees_mean`` (3 when honest), ``nees_median`` (2.37), ``inside_95``: the
    share of the poses whose NEES is inside chi-square's 95 % bound (0.95); ``nees_x`` / ``nees_y`` /
    ``nees_yaw``: per-axis means ``e_i^2 / P_ii`` (1 each); ``worst_share``: the share of the NEES sum
    the worst 5 % of the poses carry (0.17 for chi-square), ``nees_trimmed``: the mean of the other
    95 % (2.63); ``sigma_xy_med_m`` / ``sigma_yaw_med_deg``: the covariances' median sigmas;
    ``position_rmse_m`` / ``heading_rmse_deg``: the errors they are to cover."""

    n: int
    n_without_cov: int
    nees_mean: float
    nees_median: float
    inside_95: float
    nees_x: float
    nees_y: float
    nees_yaw: float
    worst_share: float
    nees_trimmed: float
    sigma_xy_med_m: float
    sigma_yaw_med_deg: float
    position_rmse_m: float
    heading_rmse_deg: float

    def to_dict(self) -> dict[str, float | int | None]:
        """Flat JSON-ready dict, same keys as the fields; NaN becomes ``None``."""
        return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in asdict(self).items()}

    @classmethod
    def keys(cls) -> list[str]:
        return [f.name for f in fields(cls)]


def nees_metrics(err: FloatArray, cov: FloatArray) -> NeesMetrics:
    """:class:`NeesMetrics` of pose errors ``err`` (N x 3, ``[ex_m, ey_m, eyaw_rad]``, yaw wrapped)
    against their covariances ``cov`` (N x 3 x 3)."""
    e = np.asarray(err, dtype=float).reshape(-1, 3)
    P = np.asarray(cov, dtype=float).reshape(-1, 3, 3)
    v = pose_nees(e, P)
    ok = np.isfinite(v)
    nan = float("nan")
    if not np.any(ok):
        return NeesMetrics(0, len(e), *([nan] * 12))
    s = nees_summary(e[ok], P[ok])
    return NeesMetrics(
        n=int(np.count_nonzero(ok)), n_without_cov=int(len(e) - np.count_nonzero(ok)),
        nees_mean=s["nees_mean"], nees_median=s["nees_median"], inside_95=float(np.mean(v[ok] <= CHI2_3DOF_95)),
        nees_x=s["nees_x"], nees_y=s["nees_y"], nees_yaw=s["nees_yaw"], worst_share=s["worst_share"],
        nees_trimmed=s["nees_trimmed"], sigma_xy_med_m=s["sigma_xy_med_m"], sigma_yaw_med_deg=s["sigma_yaw_med_deg"],
        position_rmse_m=s["rmse_m"], heading_rmse_deg=s["rmse_deg"])


def pose_errors(est: Trajectory, gt: Trajectory, max_gap: float = DEFAULT_MAX_GAP_S,
                association: Association | None = None) -> tuple[FloatArray, NDArray[np.int64]]:
    """``(err, index)``: the errors ``[ex_m, ey_m, eyaw_rad]`` of the poses of ``est`` the reference
    ``gt`` covers (see :func:`fgloc.eval.metrics.associate`; ``association``: those pairs, already
    made) and their indices in ``est``."""
    a = associate(est, gt, max_gap=max_gap, min_poses=1) if association is None else association
    e = a.est - a.gt
    e[:, YAW] = wrap_angle(e[:, YAW])
    return e, a.index


def evaluate_nees(est: Trajectory, gt: Trajectory, covs: FloatArray | None = None,
                  max_gap: float = DEFAULT_MAX_GAP_S, association: Association | None = None) -> NeesMetrics:
    """:class:`NeesMetrics` of the poses of ``est`` against the reference ``gt``, each weighed by its
    covariance: ``covs`` (N x 3 x 3, one per pose of ``est``; NaN: none) or else ``est.covs``;
    ``association``: their pairs when already made by :func:`~fgloc.eval.metrics.associate`.  Raises
    :class:`~fgloc.eval.metrics.AssociationError` when no pose can be paired and ``ValueError``
    when there are no covariances or not one per pose."""
    c = est.covs if covs is None else covs
    if c is None:
        raise ValueError("the estimate has no per-pose covariances")
    C = np.asarray(c, dtype=float).reshape(-1, 3, 3)
    if len(C) != len(est):
        raise ValueError(f"{len(C)} covariances for {len(est)} poses")
    e, idx = pose_errors(est, gt, max_gap=max_gap, association=association)
    return nees_metrics(e, C[idx])


__all__ = ["CHI2_3DOF_95", "CHI2_3DOF_MEDIAN", "NeesMetrics", "evaluate_nees", "nees_metrics", "pose_errors",
           "pose_nees"]
