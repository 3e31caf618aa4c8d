"""Trajectory error metrics: the paper's eq. 11/12, max errors, along/cross-track, APE and RPE.

Pure maths on :class:`fgloc.types.Trajectory` (no printing, no files).

Association (how an estimate is paired with the ground truth)
-------------------------------------------------------------
Every estimated pose is kept at its own timestamp; the ground truth is
*interpolated* at that timestamp: linearly in position, and along the
shortest arc in yaw (``yaw0 + f * wrap(yaw1 - yaw0)``).  An estimated pose is
used only if its stamp lies inside the ground truth's time span
``[gt.t0, gt.t_end]`` (no extrapolation) and the two ground-truth samples that
bracket it are at most ``max_gap`` seconds apart (default 0.5 s), so that a
hole in the reference is never bridged by a straight line; a stamp that hits a
ground-truth stamp exactly (within 1 ns) is always used.  Estimated poses
outside are counted as ``n_unassociated`` and ignored.  No time offset and no
spatial alignment are applied by default: the paper evaluates in the map frame
against the reference directly (:func:`align_se2` is available for estimates
in another frame).

Error conventions
-----------------
Errors are *estimate minus reference* in the map frame: ``ex = x - x_ref``,
``ey = y - y_ref``, ``eyaw = wrap(yaw - yaw_ref)`` in ``[-pi, pi)``.  The
along-track / cross-track errors project ``(ex, ey)`` on the reference's
direction of travel ``u`` (unit vector of the reference velocity, from the
reference interpolated at ``t -+ tangent_dt``) and on its left normal ``n``
(``u`` rotated by +90 deg, REP 103): ``along = e . u`` (positive = ahead of the
reference), ``cross = e . n`` (positive = left of the reference).  When the
reference moves slower than ``min_speed`` (standing still or rotating in place)
its heading is used as the direction of travel.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, fields, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fgloc.errors import LogError
from fgloc.geometry import YAW, between, compose, interpolate_poses, wrap_angle
from fgloc.types import Trajectory

FloatArray = NDArray[np.float64]

DEFAULT_MAX_GAP_S = 0.5
DEFAULT_TANGENT_DT_S = 0.1
DEFAULT_MIN_SPEED_MPS = 0.02
DEFAULT_RPE_DELTA_M = 1.0
DEFAULT_RPE_DELTA_S = 1.0
_EXACT_S = 1e-9


class AssociationError(LogError):
    """The estimate and the ground truth cannot be paired (no overlap, too few poses)."""


@dataclass
class Association:
    """Estimated poses and the ground truth interpolated at their stamps.

    ``stamps`` ``(N,)`` s; ``est`` and ``gt`` ``(N, 3)`` ``[x_m, y_m, yaw_rad]`` (map frame);
    ``direction`` ``(N,)`` rad, the reference's direction of travel (heading when it is
    not moving); ``index`` ``(N,)`` the indices of the used poses in the estimate;
    ``n_est`` the estimate's total number of poses.
    """

    stamps: FloatArray
    est: FloatArray
    gt: FloatArray
    direction: FloatArray
    index: NDArray[np.int64]
    n_est: int

    def __len__(self) -> int:
        return len(self.stamps)

    def subset(self, keep: NDArray[np.bool_]) -> Association:
        """The pairs where ``keep`` (one per pair) is true; the poses left out no longer count in
        ``n_est``."""
        return Association(self.stamps[keep], self.est[keep], self.gt[keep], self.direction[keep], self.index[keep],
                           self.n_est - int(np.count_nonzero(~keep)))


@dataclass
class ErrorSeries:
    """Per-time errors (estimate minus reference): ``t`` s, ``ex``/``ey``/``along``/``cross`` m,
    ``eyaw`` rad (wrapped)."""

    t: FloatArray
    ex: FloatArray
    ey: FloatArray
    eyaw: FloatArray
    along: FloatArray
    cross: FloatArray

    @property
    def epos(self) -> FloatArray:
        """Euclidean position error per pose (m)."""
        return np.hypot(self.ex, self.ey)


@dataclass
class Metrics:
    """Error statistics of one estimate against a reference (units in the names).

    ``position_rmse_m`` is the paper's eq. 11, ``heading_rmse_deg`` its eq. 12 (wrapped
    differences).  ``ape_*`` are evo's APE on the translation part (population std);
    ``ape_rmse_m == position_rmse_m``.  ``rpe_dist_*``: relative pose error between pose
    pairs ``delta_m`` of reference path apart (consecutive, non-overlapping pairs on the
    reference's path: evo's ``--delta 1 --delta_unit m --pairs_from_reference``; evo 1.38 pairs on
    the estimate's path unless that flag is given); ``rpe_time_*`` the same for pairs
    ``delta_s`` apart.  Statistics that cannot be computed (too short a trajectory for
    an RPE pair) are NaN (``None`` in :meth:`to_dict`).
    """

    n: int
    n_unassociated: int
    t_start_s: float
    t_end_s: float
    duration_s: float
    path_length_m: float
    aligned: bool
    # the paper's figures
    position_rmse_m: float
    heading_rmse_deg: float
    max_abs_x_m: float
    max_abs_y_m: float
    max_abs_heading_deg: float
    along_rms_m: float
    along_mean_abs_m: float
    along_max_abs_m: float
    cross_rms_m: float
    cross_mean_abs_m: float
    cross_max_abs_m: float
    position_p95_m: float
    heading_p95_deg: float
    # APE (translation part, as evo reports it)
    ape_rmse_m: float
    ape_mean_m: float
    ape_median_m: float
    ape_std_m: float
    ape_min_m: float
    ape_max_m: float
    # RPE over a fixed travelled distance
    rpe_dist_delta_m: float
    rpe_dist_pairs: int
    rpe_dist_trans_rmse_m: float
    rpe_dist_trans_mean_m: float
    rpe_dist_trans_max_m: float
    rpe_dist_rot_rmse_deg: float
    rpe_dist_rot_mean_deg: float
    rpe_dist_rot_max_deg: float
    # RPE over a fixed time
    rpe_time_delta_s: float
    rpe_time_pairs: int
    rpe_time_trans_rmse_m: float
    rpe_time_trans_mean_m: float
    rpe_time_trans_max_m: float
    rpe_time_rot_rmse_deg: float
    rpe_time_rot_mean_deg: float
    rpe_time_rot_max_deg: float

    def to_dict(self) -> dict[str, float | int | bool | None]:
        """Flat JSON-ready dict, same keys as the fields; NaN becomes ``None``."""
        out: dict[str, float | int | bool | None] = {}
        for k, v in asdict(self).items():
            if isinstance(v, float) and not math.isfinite(v):
                out[k] = None
            else:
                out[k] = v
        return out

    @classmethod
    def keys(cls) -> list[str]:
        """The field names (= the keys of :meth:`to_dict`), in order."""
        return [f.name for f in fields(cls)]


# --------------------------------------------------------------------------- association
def associate(
    est: Trajectory,
    gt: Trajectory,
    max_gap: float = DEFAULT_MAX_GAP_S,
    tangent_dt: float = DEFAULT_TANGENT_DT_S,
    min_speed: float = DEFAULT_MIN_SPEED_MPS,
    min_poses: int = 2,
) -> Association:
    """Pair each estimated pose with the ground truth interpolated at its stamp.

    The ground truth is interpolated linearly in position and along the shortest arc in
    yaw, only inside its own time span and only between two of its samples at most
    ``max_gap`` s apart (an exact stamp match is always accepted).  The direction of
    travel is the direction of the reference's displacement between ``t - tangent_dt``
    and ``t + tangent_dt`` (clamped to its span); below ``min_speed`` m/s the reference
    heading is used instead.  Raises :class:`AssociationError` when fewer than
    ``min_poses`` poses can be paired (e.g. no overlap in time).
    """
    if len(gt) < 2:
        raise AssociationError(f"ground truth has {len(gt)} pose(s); at least 2 are needed")
    if len(est) < min_poses:
        raise AssociationError(f"estimate has {len(est)} pose(s); at least {min_poses} are needed")
    gs, ts = gt.stamps, est.stamps
    inside = (ts >= gs[0] - _EXACT_S) & (ts <= gs[-1] + _EXACT_S)
    tc = np.clip(ts, gs[0], gs[-1])
    i1 = np.clip(np.searchsorted(gs, tc, side="right"), 1, len(gs) - 1)
    i0 = i1 - 1
    exact = (np.abs(gs[i0] - tc) <= _EXACT_S) | (np.abs(gs[i1] - tc) <= _EXACT_S)
    ok = inside & (exact | (gs[i1] - gs[i0] <= max_gap))
    idx = np.flatnonzero(ok)
    if len(idx) < min_poses:
        if not np.any(inside):
            raise AssociationError(
                f"estimate ({ts[0]:.3f}-{ts[-1]:.3f} s) and ground truth ({gs[0]:.3f}-{gs[-1]:.3f} s) "
                "do not overlap in time"
            )
        raise AssociationError(
            f"only {len(idx)} estimated pose(s) fall inside the ground truth's time span without a gap "
            f"> {max_gap:g} s; at least {min_poses} are needed"
        )
    t = tc[idx]
    gt_at = interpolate_poses(gs, gt.poses, t)
    # a stamp that hits a reference stamp takes that pose bit for bit (no rounding)
    k = np.clip(np.searchsorted(gs, t), 0, len(gs) - 1)
    k = np.where((k > 0) & (np.abs(gs[k - 1] - t) < np.abs(gs[k] - t)), k - 1, k)
    hit = np.abs(gs[k] - t) <= _EXACT_S
    gt_at[hit] = gt.poses[k[hit]]
    # direction of travel from the reference's displacement over [t - h, t + h]
    ta = np.clip(t - tangent_dt, gs[0], gs[-1])
    tb = np.clip(t + tangent_dt, gs[0], gs[-1])
    pa = interpolate_poses(gs, gt.poses, ta)[:, :2]
    pb = interpolate_poses(gs, gt.poses, tb)[:, :2]
    d = pb - pa
    span = np.maximum(tb - ta, 1e-12)
    speed = np.hypot(d[:, 0], d[:, 1]) / span
    direction = np.where(speed >= min_speed, np.arctan2(d[:, 1], d[:, 0]), gt_at[:, YAW])
    return Association(
        stamps=t,
        est=est.poses[idx].copy(),
        gt=gt_at,
        direction=np.asarray(direction, dtype=float),
        index=idx.astype(np.int64),
        n_est=len(est),
    )


def _series(a: Association) -> ErrorSeries:
    ex = a.est[:, 0] - a.gt[:, 0]
    ey = a.est[:, 1] - a.gt[:, 1]
    eyaw = np.asarray(wrap_angle(a.est[:, YAW] - a.gt[:, YAW]), dtype=float)
    c, s = np.cos(a.direction), np.sin(a.direction)
    return ErrorSeries(
        t=a.stamps.copy(), ex=ex, ey=ey, eyaw=eyaw, along=c * ex + s * ey, cross=-s * ex + c * ey
    )


def error_series(
    est: Trajectory,
    gt: Trajectory,
    max_gap: float = DEFAULT_MAX_GAP_S,
    align: bool = False,
) -> ErrorSeries:
    """Per-time errors ``(t, ex, ey, eyaw, along, cross)`` of ``est`` against ``gt`` (for plots)."""
    a = associate(est, gt, max_gap=max_gap)
    if align:
        a = _aligned(a)
    return _series(a)


# --------------------------------------------------------------------------- alignment
def align_se2(est_xy: FloatArray, gt_xy: FloatArray) -> FloatArray:
    """Rigid 2-D alignment (Umeyama / Horn, no scale) of associated positions.

    Returns the pose ``T = [x, y, yaw]`` minimizing ``sum |T (+) est_i - gt_i|^2``, i.e.
    ``compose(T, est_pose)`` maps an estimated pose into the reference frame.
    """
    p = np.asarray(est_xy, dtype=float).reshape(-1, 2)
    q = np.asarray(gt_xy, dtype=float).reshape(-1, 2)
    if len(p) < 2:
        raise ValueError("alignment needs at least 2 associated positions")
    mp, mq = p.mean(axis=0), q.mean(axis=0)
    cov = (q - mq).T @ (p - mp) / len(p)
    u, _, vt = np.linalg.svd(cov)
    sign = np.eye(2)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        sign[1, 1] = -1.0
    r = u @ sign @ vt
    t = mq - r @ mp
    return np.array([t[0], t[1], math.atan2(r[1, 0], r[0, 0])])


def _aligned(a: Association) -> Association:
    tf = align_se2(a.est[:, :2], a.gt[:, :2])
    return Association(a.stamps, compose(tf, a.est), a.gt, a.direction, a.index, a.n_est)


# --------------------------------------------------------------------------- RPE
def pairs_by_distance(positions: FloatArray, delta_m: float) -> list[tuple[int, int]]:
    """Consecutive, non-overlapping index pairs ``delta_m`` of path apart (evo's pairing).

    The path is accumulated along ``positions`` (the reference); when it reaches
    ``delta_m`` the current index closes a pair and the count restarts from it.
    """
    ids = [0]
    step = np.linalg.norm(np.diff(np.asarray(positions, dtype=float), axis=0), axis=1)
    acc = 0.0
    for i, s in enumerate(step, start=1):
        acc += float(s)
        if acc >= delta_m:
            ids.append(i)
            acc = 0.0
    return list(zip(ids[:-1], ids[1:], strict=True))


def pairs_by_time(stamps: FloatArray, delta_s: float) -> list[tuple[int, int]]:
    """Consecutive, non-overlapping index pairs at least ``delta_s`` apart in time."""
    ids = [0]
    for i in range(1, len(stamps)):
        if stamps[i] - stamps[ids[-1]] >= delta_s - _EXACT_S:
            ids.append(i)
    return list(zip(ids[:-1], ids[1:], strict=True))


def relative_errors(est: FloatArray, gt: FloatArray, pairs: list[tuple[int, int]]) -> tuple[FloatArray, FloatArray]:
    """RPE per pair: ``E = (gt_i^-1 gt_j)^-1 (est_i^-1 est_j)``; returns (|t(E)| m, |yaw(E)| rad).

    With ``G = gt_i^-1 gt_j`` and ``P = est_i^-1 est_j``, ``t(E) = R(G)^T (t(P) - t(G))`` so
    ``|t(E)| = |t(P) - t(G)|`` and ``yaw(E) = wrap(yaw(P) - yaw(G))``; computed that way the
    error of identical trajectories is exactly zero.
    """
    if not pairs:
        return np.zeros(0), np.zeros(0)
    i = np.array([p[0] for p in pairs])
    j = np.array([p[1] for p in pairs])
    g = between(gt[i], gt[j])
    p = between(est[i], est[j])
    dyaw = np.asarray(wrap_angle(p[:, YAW] - g[:, YAW]), dtype=float)
    return np.hypot(p[:, 0] - g[:, 0], p[:, 1] - g[:, 1]), np.abs(dyaw)


def _rms(v: FloatArray) -> float:
    return float(np.sqrt(np.mean(np.square(v)))) if len(v) else float("nan")


def _mean(v: FloatArray) -> float:
    return float(np.mean(v)) if len(v) else float("nan")


def _max(v: FloatArray) -> float:
    return float(np.max(v)) if len(v) else float("nan")


# --------------------------------------------------------------------------- evaluate
def evaluate(
    est: Trajectory,
    gt: Trajectory,
    max_gap: float = DEFAULT_MAX_GAP_S,
    align: bool = False,
    rpe_delta_m: float = DEFAULT_RPE_DELTA_M,
    rpe_delta_s: float = DEFAULT_RPE_DELTA_S,
) -> Metrics:
    """All error statistics of ``est`` against ``gt`` (see :class:`Metrics` and the module doc).

    ``align=True`` first applies the best rigid 2-D transform (:func:`align_se2`); the
    paper evaluates without it.  Raises :class:`AssociationError` on no overlap in time
    or fewer than 2 associated poses.
    """
    return association_metrics(associate(est, gt, max_gap=max_gap), align=align, rpe_delta_m=rpe_delta_m,
                               rpe_delta_s=rpe_delta_s)


def association_metrics(
    a: Association,
    align: bool = False,
    rpe_delta_m: float = DEFAULT_RPE_DELTA_M,
    rpe_delta_s: float = DEFAULT_RPE_DELTA_S,
) -> Metrics:
    """:func:`evaluate` of poses already paired by :func:`associate` (one association, several uses)."""
    if align:
        a = _aligned(a)
    s = _series(a)
    epos = s.epos
    eyaw_deg = np.degrees(s.eyaw)
    gt_steps = np.linalg.norm(np.diff(a.gt[:, :2], axis=0), axis=1)
    dpairs = pairs_by_distance(a.gt[:, :2], rpe_delta_m)
    tpairs = pairs_by_time(a.stamps, rpe_delta_s)
    dt_err, dr_err = relative_errors(a.est, a.gt, dpairs)
    tt_err, tr_err = relative_errors(a.est, a.gt, tpairs)
    dr_deg, tr_deg = np.degrees(dr_err), np.degrees(tr_err)
    return Metrics(
        n=len(a),
        n_unassociated=a.n_est - len(a),
        t_start_s=float(a.stamps[0]),
        t_end_s=float(a.stamps[-1]),
        duration_s=float(a.stamps[-1] - a.stamps[0]),
        path_length_m=float(np.sum(gt_steps)),
        aligned=bool(align),
        position_rmse_m=float(np.sqrt(np.mean(s.ex**2 + s.ey**2))),
        heading_rmse_deg=float(np.sqrt(np.mean(eyaw_deg**2))),
        max_abs_x_m=float(np.max(np.abs(s.ex))),
        max_abs_y_m=float(np.max(np.abs(s.ey))),
        max_abs_heading_deg=float(np.max(np.abs(eyaw_deg))),
        along_rms_m=_rms(s.along),
        along_mean_abs_m=float(np.mean(np.abs(s.along))),
        along_max_abs_m=float(np.max(np.abs(s.along))),
        cross_rms_m=_rms(s.cross),
        cross_mean_abs_m=float(np.mean(np.abs(s.cross))),
        cross_max_abs_m=float(np.max(np.abs(s.cross))),
        position_p95_m=float(np.percentile(epos, 95)),
        heading_p95_deg=float(np.percentile(np.abs(eyaw_deg), 95)),
        ape_rmse_m=_rms(epos),
        ape_mean_m=float(np.mean(epos)),
        ape_median_m=float(np.median(epos)),
        ape_std_m=float(np.std(epos)),
        ape_min_m=float(np.min(epos)),
        ape_max_m=float(np.max(epos)),
        rpe_dist_delta_m=float(rpe_delta_m),
        rpe_dist_pairs=len(dpairs),
        rpe_dist_trans_rmse_m=_rms(dt_err),
        rpe_dist_trans_mean_m=_mean(dt_err),
        rpe_dist_trans_max_m=_max(dt_err),
        rpe_dist_rot_rmse_deg=_rms(dr_deg),
        rpe_dist_rot_mean_deg=_mean(dr_deg),
        rpe_dist_rot_max_deg=_max(dr_deg),
        rpe_time_delta_s=float(rpe_delta_s),
        rpe_time_pairs=len(tpairs),
        rpe_time_trans_rmse_m=_rms(tt_err),
        rpe_time_trans_mean_m=_mean(tt_err),
        rpe_time_trans_max_m=_max(tt_err),
        rpe_time_rot_rmse_deg=_rms(tr_deg),
        rpe_time_rot_mean_deg=_mean(tr_deg),
        rpe_time_rot_max_deg=_max(tr_deg),
    )


# --------------------------------------------------------------------------- by status
#: the statuses of the poses a run vouches for (``trajectory_status.csv``, :mod:`fgloc.localization.monitor`):
#: ``ok`` (the map confirms the pose) and ``degraded`` (dead reckoning nothing contradicts); ``suspect`` and
#: ``lost`` are the run saying the pose may be wrong or is not known
VOUCHED_STATUSES = ("ok", "degraded")


@dataclass
class StatusSplit:
    """A trajectory's errors split by its poses' statuses.

    ``metrics``: over the paired poses the run vouches for (:data:`VOUCHED_STATUSES`; None when fewer
    than 2); ``left_out``: the paired poses it does not vouch for, counted by status (in the order met);
    ``left_out_rmse_m`` / ``left_out_max_m``: their position error's RMSE and largest value (NaN when
    none); ``all_rmse_m``: the position RMSE over every paired pose (what a table over all of them says).
    """

    metrics: Metrics | None
    left_out: dict[str, int]
    left_out_rmse_m: float
    left_out_max_m: float
    all_rmse_m: float

    @property
    def n_vouched(self) -> int:
        return 0 if self.metrics is None else self.metrics.n

    @property
    def n_left_out(self) -> int:
        return sum(self.left_out.values())

    def left_out_counts(self) -> str:
        """The left-out poses by status, e.g. ``"90 lost, 3 suspect"`` (in the order met)."""
        return ", ".join(f"{n} {k}" for k, n in self.left_out.items())

    def left_out_errors(self) -> str:
        """The left-out poses and their errors beside the all-pose RMSE, as a clause: ``"90 lost pose(s),
        12.3800 m RMSE, up to 17.512 m off (over every pose 3.0733 m RMSE"`` (the caller closes it)."""
        return (f"{self.left_out_counts()} pose(s), {self.left_out_rmse_m:.4f} m RMSE, up to {self.left_out_max_m:.3f} "
                f"m off (over every pose {self.all_rmse_m:.4f} m RMSE")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (NaN as None; ``metrics`` as :meth:`Metrics.to_dict`)."""
        def num(v: float) -> float | None:
            return v if math.isfinite(v) else None

        return {"vouched_statuses": list(VOUCHED_STATUSES), "n_vouched": self.n_vouched,
                "left_out": dict(self.left_out), "left_out_rmse_m": num(self.left_out_rmse_m),
                "left_out_max_m": num(self.left_out_max_m), "all_rmse_m": num(self.all_rmse_m)}


def paired_statuses(a: Association, statuses: Sequence[str]) -> NDArray[np.object_]:
    """The status of each pair of ``a``, from ``statuses``: one per pose of the estimate (``a.n_est``)."""
    st = np.asarray(list(statuses), dtype=object)
    if len(st) != a.n_est:
        raise ValueError(f"{len(st)} statuses for an estimate of {a.n_est} poses")
    return st[a.index]


def vouched_pairs(a: Association, statuses: Sequence[str]) -> NDArray[np.bool_]:
    """Which pairs of ``a`` are of a pose the run vouches for (:data:`VOUCHED_STATUSES`); ``statuses``: one
    per pose of the estimate."""
    return np.isin(paired_statuses(a, statuses), VOUCHED_STATUSES)


def split_by_status(
    a: Association,
    statuses: Sequence[str],
    align: bool = False,
    rpe_delta_m: float = DEFAULT_RPE_DELTA_M,
    rpe_delta_s: float = DEFAULT_RPE_DELTA_S,
) -> StatusSplit:
    """:func:`association_metrics` over the poses whose status (``statuses``: one per pose of the
    estimate, ``a.n_est``) the run vouches for, and what the others' errors are.  ``align``: the rigid
    transform is fitted to the vouched poses (all paired poses when fewer than 2) and applied to every
    pose.  Poses not paired with the reference are not counted as left out."""
    st = paired_statuses(a, statuses)
    keep = np.isin(st, VOUCHED_STATUSES)
    if align:
        fit = keep if np.count_nonzero(keep) >= 2 else np.ones(len(a), dtype=bool)
        tf = align_se2(a.est[fit, :2], a.gt[fit, :2])
        a = Association(a.stamps, compose(tf, a.est), a.gt, a.direction, a.index, a.n_est)
    epos = _series(a).epos
    out = ~keep
    left: dict[str, int] = {}
    for s in st[out]:
        left[str(s)] = left.get(str(s), 0) + 1
    metrics = None
    if np.count_nonzero(keep) >= 2:
        metrics = replace(association_metrics(a.subset(keep), rpe_delta_m=rpe_delta_m, rpe_delta_s=rpe_delta_s),
                          aligned=bool(align))
    return StatusSplit(metrics=metrics, left_out=left, left_out_rmse_m=_rms(epos[out]),
                       left_out_max_m=_max(epos[out]), all_rmse_m=_rms(epos))


def position_errors_and_steps(est: Trajectory, gt: Trajectory) -> tuple[FloatArray, FloatArray]:
    """Per estimated pose, its position error (m) against ``gt`` interpolated at its stamp, and per
    consecutive pair, how far the estimate's step differs from the reference's (m): a jump shows as
    a large step error.  ``gt`` must span ``est``'s stamps."""
    ref = gt.interpolate(est.stamps)
    err = np.hypot(*(est.poses[:, :2] - ref[:, :2]).T)
    step = np.hypot(*(np.diff(est.poses[:, :2], axis=0) - np.diff(ref[:, :2], axis=0)).T)
    return err, step


def track_errors(poses: FloatArray, reference: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``(along_m, cross_m, err)``: each of ``poses`` (N x 3) minus ``reference`` (N x 3, same stamps) in
    the reference robot's frame: along its heading (ahead +) and across it (left +), and the raw
    difference ``err`` (N x 3, the heading wrapped to [-pi, pi))."""
    p = np.asarray(poses, dtype=float).reshape(-1, 3)
    g = np.asarray(reference, dtype=float).reshape(-1, 3)
    e = p - g
    e[:, 2] = wrap_angle(e[:, 2])
    c, s = np.cos(g[:, 2]), np.sin(g[:, 2])
    return c * e[:, 0] + s * e[:, 1], -s * e[:, 0] + c * e[:, 1], e

# --------------------------------------------------------------------------- coverage split
def within_radius(points_xy: FloatArray, anchors_xy: FloatArray, radius_m: float) -> NDArray[np.bool_]:
    """For each of ``points_xy`` (N x 2, m), whether an anchor of ``anchors_xy`` (M x 2, m) lies within
    ``radius_m``: e.g. a reference pose "mapped" when a keyframe the map was built from is that close.
    All False without anchors."""
    pts = np.asarray(points_xy, dtype=float).reshape(-1, 2)
    anc = np.asarray(anchors_xy, dtype=float).reshape(-1, 2)
    if len(anc) == 0 or len(pts) == 0:
        return np.zeros(len(pts), dtype=bool)
    from scipy.spatial import cKDTree

    d, _ = cKDTree(anc).query(pts)
    return np.asarray(d < radius_m, dtype=bool)


def split_errors(err_xy_m: FloatArray, err_yaw_rad: FloatArray, mask: NDArray[np.bool_]) -> dict[str, dict[str, float]]:
    """Position / heading RMSE and max position error over the poses ``mask`` selects ("in") and the
    rest ("out"): ``{"in": {"n", "rmse_m", "max_m", "rmse_deg"}, "out": {...}}``, NaN for an empty
    part.  ``err_xy_m``: position error norms (m); ``err_yaw_rad``: wrapped heading errors (rad)."""
    e = np.asarray(err_xy_m, dtype=float)
    y = np.asarray(err_yaw_rad, dtype=float)
    m = np.asarray(mask, dtype=bool)
    out: dict[str, dict[str, float]] = {}
    for part, sel in (("in", m), ("out", ~m)):
        out[part] = {"n": float(np.count_nonzero(sel)), "rmse_m": _rms(e[sel]), "max_m": _max(e[sel]),
                     "rmse_deg": math.degrees(_rms(y[sel])) if np.any(sel) else float("nan")}
    return out


# --------------------------------------------------------------------------- reference error
def three_cornered_hat(v_ab: float, v_ac: float, v_bc: float) -> tuple[float, float, float]:
    """Each of three estimates' own error variance ``(v_a, v_b, v_c)`` from the mean squares of their
    pairwise differences (``v_ab``: of ``a - b``), assuming their errors independent:
    ``v_a = (v_ab + v_ac - v_bc) / 2`` and so on (the three-cornered hat).  Used to split a
    localizer's error against a SLAM reference into its own and the reference's with a second
    reference (GMapping's).  An error two of them share cancels in their pair and is counted to the
    third; a negative value says the errors are not independent.  Unclipped."""
    a = 0.5 * (v_ab + v_ac - v_bc)
    b = 0.5 * (v_ab + v_bc - v_ac)
    c = 0.5 * (v_ac + v_bc - v_ab)
    return float(a), float(b), float(c)


# --------------------------------------------------------------------------- covariance consistency
def nees_summary(err: FloatArray, cov: FloatArray, worst_share: float = 0.05) -> dict[str, float]:
    """How well covariances ``cov`` (N x 3 x 3, m^2 / rad^2) cover the pose errors ``err`` (N x 3,
    ``[ex_m, ey_m, eyaw_rad]``, the yaw wrapped): the NEES ``e^T P^-1 e`` (3 on average when the
    covariances are honest; chi-square's median 2.37) as ``nees_mean`` / ``nees_median``, the per-axis
    means ``e_i^2 / P_ii`` (``nees_x`` / ``nees_y`` / ``nees_yaw``, 1 each when honest), the errors'
    RMSE (``rmse_m`` over the position, ``rmse_deg``), the median sigmas (``sigma_xy_med_m``:
    ``sqrt((P_xx + P_yy) / 2)``, ``sigma_yaw_med_deg``), ``worst_share``: the share of the NEES sum
    that the worst ``worst_share`` of the poses (at least one) carry (0.17 for chi-square's 3 dof over
    many poses and a share of 0.05: a larger share says a few outliers set the mean), and
    ``nees_trimmed``: the mean NEES of the other poses (2.63 for chi-square's 3 dof and 0.05: how the
    covariances cover the bulk).  ``{"n": 0}`` without poses."""
    e = np.asarray(err, dtype=float).reshape(-1, 3)
    P = np.asarray(cov, dtype=float).reshape(-1, 3, 3)
    n = len(e)
    if n == 0:
        return {"n": 0}
    nees = np.einsum("ni,nij,nj->n", e, np.linalg.inv(P), e)
    ax = e**2 / np.einsum("nii->ni", P)
    k = max(1, int(round(worst_share * n)))
    srt = np.sort(nees)
    total = float(srt.sum())
    return {"n": n, "nees_mean": float(nees.mean()), "nees_median": float(np.median(nees)),
            "nees_x": float(ax[:, 0].mean()), "nees_y": float(ax[:, 1].mean()), "nees_yaw": float(ax[:, 2].mean()),
            "rmse_m": float(np.sqrt(np.mean(e[:, 0] ** 2 + e[:, 1] ** 2))),
            "rmse_deg": math.degrees(float(np.sqrt(np.mean(e[:, 2] ** 2)))),
            "sigma_xy_med_m": float(np.median(np.sqrt(0.5 * (P[:, 0, 0] + P[:, 1, 1])))),
            "sigma_yaw_med_deg": math.degrees(float(np.median(np.sqrt(P[:, 2, 2])))),
            "worst_share": float(srt[-k:].sum() / total) if total > 0 else float("nan"),
            "nees_trimmed": float(srt[:-k].mean()) if n > k else float("nan")}
