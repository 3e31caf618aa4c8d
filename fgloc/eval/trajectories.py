"""Trajectories from every file fgloc writes or reads, for ``fgloc eval`` and ``fgloc export``.

A trajectory is named ``FILE`` or ``FILE:TOPIC`` (``run.mcap:/fused_pose``, ``log.bag:/odom``); the
file's kind is found by its content:

* a TUM file (``timestamp x y z qx qy qz qw`` lines): its poses;
* a log (ROS 2 MCAP, rosbag2 folder, ROS 1 bag): the poses of a ``nav_msgs/Odometry``,
  ``geometry_msgs/PoseWithCovarianceStamped`` or ``geometry_msgs/PoseStamped`` topic (a motion-capture
  system's, as vrpn_client_ros publishes it), at their header stamps.  Without a topic:
  ``/fused_pose`` (what ``fgloc run`` writes), else ``/ground_truth``, else the log's only topic of
  those types; several candidates are a one-line error naming them;
* a CARMEN log (raw or a SLAM-corrected one): the pose each laser line carries (``x y theta``, the
  laser's pose; corrected in a corrected log) at its ipc timestamp; ``FILE:/odom`` is the odometry
  as ``fgloc run`` reads it.

Errors are one-line :class:`~fgloc.errors.LogError` naming the file.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fgloc.errors import LogError
from fgloc.types import PoseFix, Trajectory

#: topics taken without being named, in this order
PREFERRED_TOPICS = ("/fused_pose", "/ground_truth")
CARMEN_LASER = "laser"  # the CARMEN pseudo-topic of the laser lines' poses
#: a pose without covariance (motion capture): fgloc's readers do not decode it, this module does
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"


@dataclass
class TrajectorySource:
    """Where a trajectory was read from: the file, its kind and the topic (None for TUM)."""

    path: Path
    kind: str  # "tum", "carmen" or a log format ("mcap", "rosbag1", "rosbag2")
    topic: str | None = None
    #: a log's topic: the median of (log time - header stamp), s; two topics of one log whose stamps are on two
    #: clocks (a simulator's, the wall clock) differ by it (None: a file without log times)
    clock_offset_s: float | None = None

    @property
    def label(self) -> str:
        return str(self.path) if self.topic is None else f"{self.path}:{self.topic}"


def split_spec(spec: str | Path) -> tuple[Path, str | None]:
    """``FILE`` or ``FILE:TOPIC`` -> ``(path, topic or None)``; a path that exists is never split."""
    s = str(spec)
    if Path(s).exists() or ":" not in s:
        return Path(s), None
    head, _, topic = s.rpartition(":")
    if not head:
        return Path(s), None
    from fgloc.io.topics import resolve_name

    return Path(head), resolve_name(topic) or None


def _is_tum(path: Path) -> bool:
    """A text file whose first data line is numbers (eight in a good one: read_tum says what is wrong)."""
    from fgloc.io.carmen import open_text

    try:
        with open_text(path) as f:
            for k, line in enumerate(f):
                s = line.strip()
                if s and not s.startswith("#"):
                    parts = s.replace(",", " ").split()
                    try:
                        [float(v) for v in parts]
                    except ValueError:
                        return False
                    return True
                if k > 1000:
                    return False
    except (OSError, EOFError, UnicodeError):
        return False
    return False


def read_trajectory(spec: str | Path, topic: str | None = None) -> tuple[Trajectory, TrajectorySource]:
    """The trajectory ``spec`` names (see the module doc); ``topic`` is used when ``spec`` names none."""
    from fgloc.io.formats import detect_format

    path, named = split_spec(spec)
    topic = named or (None if not topic else topic)
    if topic is not None:
        from fgloc.io.topics import resolve_name

        topic = resolve_name(topic)
    kind, _ = detect_format(path)  # one-line errors for a missing file, an empty one, a Git LFS pointer
    if kind == "carmen" and not path.is_dir() and _is_tum(path):
        if topic is not None:
            raise LogError(f"{path}: a TUM file has no topics (drop ':{topic}')")
        from fgloc.io.tum import read_tum

        return read_tum(path), TrajectorySource(path, "tum")
    if kind == "carmen" and topic in (None, "/" + CARMEN_LASER):
        return _carmen_laser_poses(path), TrajectorySource(path, "carmen", "/" + CARMEN_LASER)
    return _log_topic(path, kind, topic)


def _carmen_laser_poses(path: Path) -> Trajectory:
    from fgloc.io.carmen import laser_line_poses

    stamps, poses = laser_line_poses(path)
    if not stamps:
        raise LogError(f"{path}: no laser lines with poses (FLASER / ROBOTLASER1 'x y theta') to read a "
                       f"trajectory from (not a CARMEN log?)")
    return Trajectory.from_unsorted(np.asarray(stamps), np.asarray(poses), "map")


def _log_topic(path: Path, kind: str, topic: str | None) -> tuple[Trajectory, TrajectorySource]:
    from fgloc.io import open_log
    from fgloc.io.topics import ODOMETRY, POSE_COV_STAMPED, normalize_type

    src = open_log(path)
    types = {t: normalize_type(ty) for t, ty in src.topic_types().items() if src.has(t)}
    posed = [t for t, ty in sorted(types.items()) if ty in (ODOMETRY, POSE_COV_STAMPED, POSE_STAMPED)]
    listing = ", ".join(f"{t} ({types[t]})" for t in posed) or "none"
    if topic is None:
        topic = next((t for t in PREFERRED_TOPICS if t in posed), None)
        if topic is None:
            if len(posed) != 1:
                raise LogError(f"{path}: which trajectory? name a topic as {path}:TOPIC (its pose topics: "
                               f"{listing})" if posed else
                               f"{path}: no nav_msgs/Odometry, geometry_msgs/PoseWithCovarianceStamped or PoseStamped "
                               f"topic to read a trajectory from (its topics: {', '.join(sorted(types)) or 'none'})")
            topic = posed[0]
    elif topic not in types:
        raise LogError(f"{path}: no topic {topic} (its pose topics: {listing})")
    elif topic not in posed:
        raise LogError(f"{path}: {topic} is {types[topic]}, not nav_msgs/Odometry, "
                       f"geometry_msgs/PoseWithCovarianceStamped or PoseStamped (its pose topics: {listing})")
    stamps: list[float] = []
    poses: list[np.ndarray] = []
    covs: list[np.ndarray] = []
    frames: set[str] = set()
    logged: list[float] = []  # the accepted messages' log times, s
    records = _pose_stamped(src, topic) if types[topic] == POSE_STAMPED else \
        ((r.log_time_ns, r.msg) for r in src.records([topic]))
    for log_ns, msg in records:
        pose = getattr(msg, "pose", None)
        if pose is None:
            continue
        p = np.asarray(pose, dtype=float).reshape(-1)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            continue
        stamps.append(float(msg.stamp))  # type: ignore[attr-defined]
        logged.append(1e-9 * log_ns)
        poses.append(p)
        covs.append(_pose_cov(msg))
        frames.add(str(getattr(msg, "frame_id", "") or ""))
    if not stamps:
        raise LogError(f"{path}: {topic} has no finite poses")
    frame = next(iter(frames)) if len(frames) == 1 and "" not in frames else "map"
    offset = float(np.median(np.asarray(logged) - np.asarray(stamps)))
    return (_sorted(np.asarray(stamps), np.asarray(poses), np.asarray(covs), frame),
            TrajectorySource(path, kind, topic, clock_offset_s=offset))


def _pose_stamped(src: Any, topic: str) -> Iterator[tuple[int, PoseFix]]:
    """A ``geometry_msgs/PoseStamped`` topic's messages as planar :class:`PoseFix` es without a covariance
    (the readers hand its messages over as CDR, rosbags' typestore decodes them; one that does not
    decode is skipped)."""
    from rosbags.typesys import Stores, get_typestore

    from fgloc.geometry import quaternion_to_yaw

    store = get_typestore(Stores.ROS2_HUMBLE)
    src.keep_other_types = True  # the readers hand over a type fgloc does not read as its CDR bytes
    nan = np.full((3, 3), np.nan)
    for rec in src.records([topic]):
        if rec.data is None:
            continue
        try:
            m: Any = store.deserialize_cdr(bytes(rec.data), POSE_STAMPED)
        except Exception:  # noqa: BLE001 - a message that does not decode is no pose
            continue
        q, p = m.pose.orientation, m.pose.position
        yaw = float(quaternion_to_yaw(q.x, q.y, q.z, q.w))
        stamp = m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec
        yield rec.log_time_ns, PoseFix(stamp, np.array([p.x, p.y, yaw], dtype=float), nan,
                                       frame_id=str(m.header.frame_id))


def _pose_cov(msg: object) -> np.ndarray:
    """A pose message's 3x3 covariance over (x, y, yaw) (``PoseFix.cov``, ``Odometry.pose_cov``); NaN
    when it carries none or an all-zero one (ROS's "unknown")."""
    c = getattr(msg, "cov", None)
    if c is None:
        c = getattr(msg, "pose_cov", None)
    if c is None:
        return np.full((3, 3), np.nan)
    a = np.asarray(c, dtype=float)
    if a.size != 9 or not np.any(a):
        return np.full((3, 3), np.nan)
    return a.reshape(3, 3)


def _sorted(stamps: np.ndarray, poses: np.ndarray, covs: np.ndarray, frame: str) -> Trajectory:
    """As :meth:`Trajectory.from_unsorted` (sorted, the last of duplicate stamps kept), with the
    per-pose covariances (``covs`` None when no pose has one)."""
    order = np.argsort(stamps, kind="stable")
    s = stamps[order]
    keep = np.ones(len(s), dtype=bool)
    keep[:-1] = np.diff(s) > 0
    c = covs[order][keep]
    return Trajectory(s[keep], poses[order][keep], frame, covs=c if np.any(np.isfinite(c)) else None)


#: the per-pose status file ``fgloc run`` writes beside ``trajectory.tum``
STATUS_FILE = "trajectory_status.csv"
_COV_COLUMNS = ("cov_xx", "cov_xy", "cov_xyaw", "cov_yy", "cov_yyaw", "cov_yawyaw")


def _status_rows(path: str | Path, columns: tuple[str, ...], need: str) -> tuple[Path, list[int], list[list[str]]]:
    """A ``trajectory_status.csv``'s column indices of ``columns`` and its data rows (comment and blank
    lines skipped); one-line :class:`LogError` unless its column line has them (``need``: what it lacks)."""
    import csv

    from fgloc.errors import read_user_text

    path = Path(path)
    lines = [ln for ln in read_user_text(path, "status file").splitlines() if ln.strip() and not ln.startswith("#")]
    rows = list(csv.reader(lines))
    if not rows or not set(columns) <= set(rows[0]):
        raise LogError(f"{path}: not a pose status file (a column line with {need})")
    return path, [rows[0].index(c) for c in columns], rows[1:]


def read_status_covariances(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """``(stamps_s, covs)`` of a ``trajectory_status.csv`` (its ``t`` and ``cov_*`` columns; a
    covariance NaN where the file has none).  One-line :class:`LogError` for a file that is not one."""
    path, (it, *ic), rows = _status_rows(path, ("t", *_COV_COLUMNS), f"t and {', '.join(_COV_COLUMNS)}")
    stamps, covs = [], []
    for k, r in enumerate(rows, start=2):
        try:
            t = float(r[it])
            xx, xy, xa, yy, ya, aa = (float(r[i]) for i in ic)
        except (ValueError, IndexError):
            raise LogError(f"{path}: row {k}: not a status row (t and six covariance numbers)") from None
        stamps.append(t)
        covs.append([[xx, xy, xa], [xy, yy, ya], [xa, ya, aa]])
    return np.asarray(stamps, dtype=float), np.asarray(covs, dtype=float).reshape(-1, 3, 3)


def read_statuses(path: str | Path) -> tuple[np.ndarray, list[str]]:
    """``(stamps_s, statuses)`` of a ``trajectory_status.csv`` (its ``t`` and ``status`` columns).
    One-line :class:`LogError` for a file that is not one."""
    path, (it, js), rows = _status_rows(path, ("t", "status"), "t and status")
    stamps, statuses = [], []
    for k, r in enumerate(rows, start=2):
        try:
            stamps.append(float(r[it]))
            statuses.append(r[js].strip())
        except (ValueError, IndexError):
            raise LogError(f"{path}: row {k}: not a status row (t and a status)") from None
    return np.asarray(stamps, dtype=float), statuses


#: the channel of each fused pose's status in ``fgloc run``'s ``run.mcap`` (JSON: stamp, status, why, frame_id)
RUN_STATUS_TOPIC = "/fgloc/pose/status"


def read_run_statuses(path: str | Path) -> tuple[np.ndarray, list[str]] | None:
    """``(stamps_s, statuses)`` of an MCAP file's :data:`RUN_STATUS_TOPIC` (``fgloc run``'s ``run.mcap``: the
    status of each ``/fused_pose``, as known online), the last of each stamp; None when it has no such
    messages."""
    import json

    from mcap.reader import make_reader

    stamps: dict[float, str] = {}
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        if summary is not None and all(c.topic != RUN_STATUS_TOPIC for c in summary.channels.values()):
            return None
        for _schema, _channel, message in reader.iter_messages(topics=[RUN_STATUS_TOPIC]):
            try:
                d = json.loads(message.data)
                stamps[float(d["stamp"])] = str(d["status"])
            except (ValueError, KeyError, TypeError):
                continue
    if not stamps:
        return None
    t = np.asarray(sorted(stamps), dtype=float)
    return t, [stamps[float(x)] for x in t]


def _rows_at(traj: Trajectory, stamps: np.ndarray, tol_s: float) -> tuple[np.ndarray, np.ndarray]:
    """For each pose of ``traj``, the index into ``stamps`` of the stamp nearest its own, and whether that
    one is within ``tol_s`` (``stamps`` non-empty, in any order)."""
    st = np.asarray(stamps, dtype=float)
    order = np.argsort(st, kind="stable")
    st = st[order]
    j = np.clip(np.searchsorted(st, traj.stamps), 0, len(st) - 1)
    jm = np.clip(j - 1, 0, len(st) - 1)
    j = np.where(np.abs(st[jm] - traj.stamps) < np.abs(st[j] - traj.stamps), jm, j)
    return order[j], np.abs(st[j] - traj.stamps) <= tol_s


def statuses_at(traj: Trajectory, stamps: np.ndarray, statuses: list[str], tol_s: float = 1e-6) -> list[str] | None:
    """One status per pose of ``traj``: the one of ``(stamps, statuses)`` at the pose's stamp (within
    ``tol_s``); None when a pose has none (the file is another trajectory's)."""
    if not len(stamps) or not len(traj):
        return None
    idx, hit = _rows_at(traj, stamps, tol_s)
    return [statuses[i] for i in idx] if np.all(hit) else None


def covariances_at(traj: Trajectory, stamps: np.ndarray, covs: np.ndarray, tol_s: float = 1e-6) -> np.ndarray:
    """One covariance per pose of ``traj``: the one of ``(stamps, covs)`` at the pose's stamp (within
    ``tol_s``), NaN where there is none."""
    out = np.full((len(traj), 3, 3), np.nan)
    if not len(stamps) or not len(traj):
        return out
    idx, hit = _rows_at(traj, stamps, tol_s)
    out[hit] = np.asarray(covs, dtype=float)[idx[hit]]
    return out
