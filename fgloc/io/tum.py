"""TUM trajectory files, as ``evo`` reads them.

One pose per line: ``timestamp x y z qx qy qz qw`` (seconds, metres, unit
quaternion); ``#`` starts a comment.  Planar poses are written with ``z = 0``
and a yaw-only quaternion; reading takes the yaw of any quaternion.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fgloc.errors import LogError, read_user_text
from fgloc.geometry import quaternion_to_yaw, yaw_to_quaternion
from fgloc.types import Trajectory


def write_tum(path: str | Path, traj: Trajectory) -> Path:
    """Write ``traj`` as a TUM file (full float precision, 9 decimals on stamps)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    q = yaw_to_quaternion(traj.poses[:, 2])
    # the rows as Python floats at once (tolist: the same values), one write of the whole text
    poses = np.asarray(traj.poses, dtype=float)[:, :2].tolist()
    lines = [f"{t:.9f} {x!r} {y!r} 0.0 {qx!r} {qy!r} {qz!r} {qw!r}\n"
             for t, (x, y), (qx, qy, qz, qw) in zip(np.asarray(traj.stamps, dtype=float).tolist(), poses,
                                                    np.asarray(q, dtype=float).tolist(), strict=True)]
    with path.open("w") as f:
        f.write("# timestamp x y z qx qy qz qw\n" + "".join(lines))
    return path


def read_tum(path: str | Path, frame_id: str = "map") -> Trajectory:
    """Read a TUM file. Errors are :class:`LogError` naming the file and the line."""
    path = Path(path)
    lines = read_user_text(path, "trajectory file").splitlines()
    rows = []
    for i, line in enumerate(lines, 1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        parts = s.replace(",", " ").split()
        if len(parts) != 8:
            raise LogError(f"{path}:{i}: expected 8 numbers 'timestamp x y z qx qy qz qw', got {len(parts)}")
        try:
            rows.append([float(v) for v in parts])
        except ValueError:
            raise LogError(f"{path}:{i}: not a number in '{s[:60]}'") from None
    if not rows:
        raise LogError(f"{path}: trajectory file has no poses")
    a = np.asarray(rows)
    if not np.all(np.isfinite(a)):
        raise LogError(f"{path}: trajectory has non-finite values")
    yaw = quaternion_to_yaw(a[:, 4], a[:, 5], a[:, 6], a[:, 7])
    poses = np.column_stack([a[:, 1], a[:, 2], yaw])
    if np.any(np.diff(a[:, 0]) <= 0):
        raise LogError(f"{path}: timestamps are not strictly increasing")
    return Trajectory(a[:, 0], poses, frame_id)
