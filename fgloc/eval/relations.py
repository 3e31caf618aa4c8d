"""The relations metric of Kuemmerle et al. 2009, "On measuring the accuracy of SLAM algorithms".

A relation ``(t1, t2, delta)`` states the pose at ``t2`` expressed in the frame
of the pose at ``t1`` (``delta = between(pose(t1), pose(t2))``, ``[x, y, yaw]``).
A trajectory is scored by how well its own relative poses agree:
``e = between(delta_ref, delta_est)``, translational error ``|e_xy|`` (m) and
rotational error ``|e_yaw|`` (deg), reported as mean +- std.  Because only
relative poses enter, the metric is blind to the global frame (no alignment).

File format (one relation per line, as the Freiburg relation files):
``t1 t2 x y z roll pitch yaw`` (seconds, metres, radians); ``#`` starts a comment.
Trajectory poses are associated with ``t1`` / ``t2`` by nearest timestamp within
``max_assoc_dt`` (relations whose stamps have no pose that close are counted as
unmatched, never guessed by interpolation).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fgloc.errors import LogError, read_user_text
from fgloc.geometry import between, wrap_angle
from fgloc.types import FloatArray, Trajectory


@dataclass
class Relation:
    """``delta`` = ``[x, y, yaw]`` of the pose at ``t2`` in the frame of the pose at ``t1``."""

    t1: float
    t2: float
    delta: FloatArray


def read_relations(path: str | Path) -> list[Relation]:
    """Read a relations file. Errors are :class:`LogError` naming the file and line."""
    path = Path(path)
    lines = read_user_text(path, "relations file").splitlines()
    out: list[Relation] = []
    for i, line in enumerate(lines, 1):
        s = line.split("#", 1)[0].strip()
        if not s:
            continue
        parts = s.replace(",", " ").split()
        if len(parts) != 8:
            raise LogError(f"{path}:{i}: expected 8 numbers 't1 t2 x y z roll pitch yaw', got {len(parts)}")
        try:
            v = [float(p) for p in parts]
        except ValueError:
            raise LogError(f"{path}:{i}: not a number in '{s[:60]}'") from None
        if not all(np.isfinite(v)):
            raise LogError(f"{path}:{i}: non-finite value")
        out.append(Relation(v[0], v[1], np.array([v[2], v[3], float(wrap_angle(v[7]))])))
    if not out:
        raise LogError(f"{path}: relations file has no relations")
    return out


def write_relations(path: str | Path, relations: list[Relation]) -> None:
    """Write relations as ``t1 t2 x y z roll pitch yaw`` lines (z, roll, pitch = 0)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w") as f:
        f.write("# t1 t2 x y z roll pitch yaw\n")
        for r in relations:
            d = [float(v) for v in np.asarray(r.delta, dtype=float)]
            f.write(f"{float(r.t1):.6f} {float(r.t2):.6f} {d[0]!r} {d[1]!r} 0 0 0 {d[2]!r}\n")


def relations_from_reference(
    ref: Trajectory,
    min_dt: float = 1.0,
    max_dt: float = 2.0,
    loop_closures: bool = True,
    loop_min_dt: float = 30.0,
    loop_radius_m: float = 1.0,
    loop_max_yaw_rad: float = np.pi / 2,
) -> list[Relation]:
    """Relations from a reference trajectory.

    *Local*: every reference pose ``i`` is paired with the first pose ``j`` at least
    ``min_dt`` later, kept if ``t_j - t_i <= max_dt``.  *Loop closures* (optional):
    for reference poses taken at least ``min_dt`` apart, the earliest pose at least
    ``loop_min_dt`` earlier within ``loop_radius_m`` (and ``loop_max_yaw_rad``) of it
    — poses close in space but far apart in time, which test global consistency.
    """
    t = ref.stamps
    p = ref.poses
    out: list[Relation] = []
    n = len(t)
    js = np.searchsorted(t, t + min_dt, side="left")
    for i in range(n):
        j = int(js[i])
        if j < n and t[j] - t[i] <= max_dt:
            out.append(Relation(float(t[i]), float(t[j]), between(p[i], p[j])))
    if loop_closures and n > 1:
        last = -np.inf
        for i in range(n):
            if t[i] - last < min_dt:
                continue
            k = int(np.searchsorted(t, t[i] - loop_min_dt, side="right"))
            if k <= 0:
                continue
            d = np.hypot(p[:k, 0] - p[i, 0], p[:k, 1] - p[i, 1])
            dy = np.abs(wrap_angle(p[:k, 2] - p[i, 2]))
            ok = np.nonzero((d <= loop_radius_m) & (dy <= loop_max_yaw_rad))[0]
            if len(ok):
                j = int(ok[0])
                out.append(Relation(float(t[j]), float(t[i]), between(p[j], p[i])))
                last = t[i]
    return out


def _nearest(stamps: FloatArray, q: FloatArray) -> tuple[np.ndarray, FloatArray]:
    idx = np.clip(np.searchsorted(stamps, q), 1, max(len(stamps) - 1, 1))
    lo = idx - 1
    if len(stamps) == 1:
        z = np.zeros(len(q), dtype=np.int64)
        return z, np.abs(stamps[0] - q)
    pick = np.where(np.abs(stamps[lo] - q) <= np.abs(stamps[idx] - q), lo, idx)
    return pick, np.abs(stamps[pick] - q)


def relation_errors(traj: Trajectory, relations: list[Relation], max_assoc_dt: float = 0.05
                    ) -> tuple[FloatArray, FloatArray, int]:
    """Per-relation translational (m) and absolute rotational (rad) errors, and the unmatched count."""
    if not relations or len(traj) == 0:
        return np.zeros(0), np.zeros(0), len(relations)
    t1 = np.array([r.t1 for r in relations])
    t2 = np.array([r.t2 for r in relations])
    d_ref = np.array([np.asarray(r.delta, dtype=float) for r in relations]).reshape(-1, 3)
    i1, e1 = _nearest(traj.stamps, t1)
    i2, e2 = _nearest(traj.stamps, t2)
    ok = (e1 <= max_assoc_dt) & (e2 <= max_assoc_dt)
    d_est = between(traj.poses[i1[ok]], traj.poses[i2[ok]])
    err = between(d_ref[ok], d_est)
    return np.hypot(err[:, 0], err[:, 1]), np.abs(np.asarray(wrap_angle(err[:, 2]))), int((~ok).sum())


def evaluate_relations(traj: Trajectory, relations: list[Relation], max_assoc_dt: float = 0.05) -> dict:
    """Mean +- std of the relation errors of ``traj``.

    Returns ``{"n", "trans_mean", "trans_std", "rot_mean_deg", "rot_std_deg", "unmatched"}``
    (plus ``trans_max`` and ``rot_max_deg``); NaN statistics when nothing matched.
    """
    et, er, unmatched = relation_errors(traj, relations, max_assoc_dt)
    n = len(et)
    nan = float("nan")
    erd = np.degrees(er)
    return {
        "n": n,
        "trans_mean": float(et.mean()) if n else nan,
        "trans_std": float(et.std()) if n else nan,
        "rot_mean_deg": float(erd.mean()) if n else nan,
        "rot_std_deg": float(erd.std()) if n else nan,
        "trans_max": float(et.max()) if n else nan,
        "rot_max_deg": float(erd.max()) if n else nan,
        "unmatched": unmatched,
    }
