"""What an evaluation's numbers may hide, as one-line notes, and the start alignment of two odometry
frames: a reference published only on updates (most poses unpaired), errors that are one offset, one
rigid transform or one scale (two frames, not a localization error), the end error after aligning the
starts. Used by ``fgloc eval``; returns text, never prints."""

from __future__ import annotations

import math
from typing import Any

#: the --max-gap values a note suggests for a sparse reference, smallest first
_GAP_STEPS_S = (1.0, 2.0, 5.0)


def gap_note(label: str, stamps: Any, ref_stamps: Any, max_gap: float) -> str | None:
    """A note when most poses of an estimate fall in gaps of the reference longer than ``max_gap``
    (a reference published on updates only, as AMCL's ``/amcl_pose`` or a slow motion capture),
    with the smallest ``--max-gap`` of :data:`_GAP_STEPS_S` that pairs 90 % of those inside its span."""
    import numpy as np

    ts, gs = np.asarray(stamps, dtype=float), np.asarray(ref_stamps, dtype=float)
    if len(ts) == 0 or len(gs) < 2:
        return None
    inside = ts[(ts >= gs[0]) & (ts <= gs[-1])]
    if len(inside) == 0:
        return None
    i1 = np.clip(np.searchsorted(gs, inside, side="right"), 1, len(gs) - 1)
    span = gs[i1] - gs[i1 - 1]
    exact = (np.abs(gs[i1] - inside) <= 1e-6) | (np.abs(gs[i1 - 1] - inside) <= 1e-6)  # paired at any gap
    lost = int(np.sum((span > max_gap) & ~exact))
    if lost <= 0.5 * len(ts):
        return None
    spacing = float(np.median(np.diff(gs)))
    note = (f"{lost} of {len(ts)} poses of {label} fall in gaps of the reference longer than --max-gap {max_gap:g} s "
            f"(its median spacing {spacing:.2f} s: a pose published on updates, as AMCL's /amcl_pose?)")
    for step in _GAP_STEPS_S:
        paired = int(np.sum((span <= step) | exact))
        if step > max_gap and paired >= 0.9 * len(inside):
            return note + f"; --max-gap {step:g} pairs {paired}, interpolating across its gaps"
    return note


def frame_note(label: str, a: Any) -> str | None:
    """A note when an estimate's position errors are mostly one constant offset, or a scale, metres
    large: the estimate and the reference in different frames (a simulator's world frame and the map's,
    a motion capture's room frame), what ``--align`` (one rigid transform) removes.  ``a``: the
    estimate's :class:`~fgloc.eval.metrics.Association` with the reference."""
    import numpy as np

    e = a.est[:, :2] - a.gt[:, :2]
    rms = float(np.sqrt(np.mean(np.sum(e**2, axis=1))))
    mean = e.mean(axis=0)
    rest = float(np.sqrt(np.mean(np.sum((e - mean) ** 2, axis=1))))
    if rms < 0.5 or len(a) < 10:
        return None
    if rest < 0.2 * rms:
        return (f"the errors of {label} are mostly one offset ({mean[0]:+.2f}, {mean[1]:+.2f}) m (RMSE {rms:.2f} m, "
                f"{rest:.2f} m about it): the estimate and the reference in different frames? --align fits one "
                "rigid transform")
    g0, e0 = a.gt[:, :2] - a.gt[:, :2].mean(axis=0), a.est[:, :2] - a.est[:, :2].mean(axis=0)
    var = float(np.mean(np.sum(g0**2, axis=1)))
    if var < 1.0:
        return None
    u, sv, vt = np.linalg.svd(e0.T @ g0 / len(a))  # Umeyama: est ~ scale R gt + t
    d = np.diag([1.0, float(np.sign(np.linalg.det(u @ vt)))])
    r = u @ d @ vt
    scale = float(np.trace(np.diag(sv) @ d)) / var
    fit = float(np.sqrt(np.mean(np.sum((e0 - scale * g0 @ r.T) ** 2, axis=1))))
    if fit >= 0.2 * rms:
        return None
    if abs(scale - 1.0) > 0.02:
        return (f"{label} is the reference scaled by {scale:.3f} (RMSE {rms:.2f} m, {fit:.2f} m after a fit with a "
                "scale): a map scaled against the reference's world (a simulator's bitmap fitted to a size, a "
                "wrong map resolution)?")
    turn = math.degrees(math.atan2(r[1, 0], r[0, 0]))
    return (f"the errors of {label} are mostly one rigid transform (a turn of {turn:+.1f} deg; RMSE {rms:.2f} m, "
            f"{fit:.2f} m after it): the estimate and the reference in different frames? --align fits it, "
            "--align-start moves the estimate's start onto the reference's")


def start_aligned(est: Any, a: Any, first: int = 0) -> tuple[Any, Any]:
    """``est`` moved rigidly so that its pose of pair ``first`` (by default the first paired with the
    reference) is the reference's pose there (SE(2)): two trajectories in frames that differ by where each
    started.  ``a``: the estimate's :class:`~fgloc.eval.metrics.Association` with the reference; returns
    the moved estimate and its association (the same pairs: a rigid move keeps the stamps)."""
    from dataclasses import replace

    from fgloc.geometry import compose, inverse
    from fgloc.types import Trajectory

    move = compose(a.gt[first], inverse(a.est[first]))
    return Trajectory(est.stamps, compose(move, est.poses), est.frame_id), replace(a, est=compose(move, a.est))


def end_error(a: Any) -> float:
    """The distance between the estimate's last pose paired with the reference and the reference there
    (m); ``a``: their :class:`~fgloc.eval.metrics.Association`."""
    import numpy as np

    return float(np.hypot(*(a.est[-1, :2] - a.gt[-1, :2])))


def clock_note(est: Any, est_src: Any, gt: Any, gt_src: Any, t_offset: float = 0.0) -> str | None:
    """For two trajectories that do not overlap in time (``est`` already shifted by ``t_offset``): when
    both are topics of logs, whose log times put their stamps on one clock (a simulator's clock in
    one header, the wall clock in the other, or a recorder's clock), the ``--t-offset`` that does,
    as a clause; None when the log times say nothing (a TUM file) or would not make them overlap."""
    a, b = getattr(est_src, "clock_offset_s", None), getattr(gt_src, "clock_offset_s", None)
    if a is None or b is None or not len(est.stamps) or not len(gt.stamps):
        return None
    shift = float(a) - float(b)  # the estimate's stamp + shift = the reference's stamp of the same log time
    lo, hi = est.stamps[0] - t_offset + shift, est.stamps[-1] - t_offset + shift
    if hi < gt.stamps[0] or lo > gt.stamps[-1] or abs(shift) < 1e-3:
        return None
    return (f"their log times put them on one clock: --t-offset {shift:.3f} moves the estimate's stamps onto "
            "the reference's")


def heading_note(label: str, a: Any, align: bool = False) -> str | None:
    """A note when an estimate's heading errors are mostly one constant offset, tens of degrees large,
    while its positions agree with the reference (``align``: after ``--align``'s rigid fit, which
    the positions alone decide): the reference's body axes turned from the robot's (a motion-capture
    rigid body defined off the robot's axes), an offset no position metric shows.  ``a``: the
    estimate's :class:`~fgloc.eval.metrics.Association` with the reference."""
    import numpy as np

    from fgloc.geometry import wrap_angle

    if len(a) < 10:
        return None
    est = np.asarray(a.est, dtype=float)
    if align:
        from fgloc.eval.metrics import align_se2
        from fgloc.geometry import compose

        est = np.asarray(compose(align_se2(est[:, :2], a.gt[:, :2]), est), dtype=float)
    if float(np.sqrt(np.mean(np.sum((est[:, :2] - a.gt[:, :2]) ** 2, axis=1)))) >= 0.5:
        return None  # the positions disagree too: frame_note's case, or a wrong estimate
    e = np.asarray(wrap_angle(est[:, 2] - a.gt[:, 2]), dtype=float)
    mean = math.atan2(float(np.mean(np.sin(e))), float(np.mean(np.cos(e))))
    spread = math.degrees(float(np.sqrt(np.mean(np.asarray(wrap_angle(e - mean), dtype=float) ** 2))))
    off = math.degrees(mean)
    if abs(off) < 20.0 or spread > min(10.0, 0.2 * abs(off)):
        return None
    return (f"the heading errors of {label} are mostly one offset ({off:+.1f} deg, {spread:.1f} deg about it) where "
            "the positions agree: the reference's body axes turned from the robot's (a motion-capture rigid body "
            "defined off the robot's axes)? The heading metrics hold that offset; the position metrics do not")
