"""Turn a log (CARMEN or MCAP) into scans paired with odometry poses.

Reading belongs to :mod:`fgloc.io` (``open_log``: every format it reads); this
module only pairs each scan with the wheel-odometry pose at its stamp.
Messages are taken in file order; a scan's odometry is interpolated between
the odometry messages just before and just after it in the file when their
stamps bracket the scan stamp, else the latest earlier one is used (real logs,
e.g. intel, have stamps that jump backwards).  Odometry without a pose is
dead-reckoned from its twist.  A log without any odometry (or ``odom_topic`` "") gives scans with
no odometry pose (NaN): the mapper then matches the scans to each other alone.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fgloc.errors import ConfigError, LogError
from fgloc.frames.tf import mount_of, planar_mount
from fgloc.geometry import compose, wrap_angle
from fgloc.io.topics import LASER_SCAN, MULTI_ECHO_SCAN, ODOMETRY, pick_topics
from fgloc.types import FloatArray, LaserScan, Odometry, StaticTransform

DEFAULT_SCAN = "/scan"
DEFAULT_ODOM = "/odom"
CARMEN_SUFFIXES = (".clf", ".log", ".clf.gz", ".log.gz", ".clf.bz2", ".log.bz2", ".gfs", ".carmen")


@dataclass
class ScanRecord:
    """One scan with the odometry pose ``[x, y, yaw]`` (odom frame) at its stamp."""

    stamp: float
    odom: FloatArray
    scan: LaserScan
    index: int  # order of the scan in the log (0-based)


def is_carmen(path: str | Path) -> bool:
    name = str(path).lower()
    return any(name.endswith(s) for s in CARMEN_SUFFIXES)


def with_mount(messages: Iterable[tuple[str, object]], mount: StaticTransform,
               mirrored: bool) -> Iterator[tuple[str, object]]:
    """``messages`` with the user's laser ``mount`` in place of the log's (it comes first on
    ``/tf_static``; the log's transforms to the same frame are dropped) and, ``mirrored``, that
    frame's scans mirrored (:func:`planar_mount`)."""
    from fgloc.io.ros import mirror_scan

    frame = mount.child.lstrip("/")
    yield "/tf_static", [mount]
    for topic, msg in messages:
        if topic == "/tf_static" and isinstance(msg, list):
            msg = [t for t in msg if not (isinstance(t, StaticTransform) and t.child.lstrip("/") == frame)]
        elif mirrored and isinstance(msg, LaserScan) and msg.frame_id.lstrip("/") == frame:
            msg = mirror_scan(msg)
        yield topic, msg


def log_messages(
    path: str | Path, scan_topic: str = "/scan", odom_topic: str = "/odom",
    static_transforms: Sequence[StaticTransform] = (),
) -> Iterator[tuple[str, object]]:
    """``(topic, msg)`` of any log :func:`fgloc.io.open_log` reads (MCAP, rosbag2, ROS 1 bag; CARMEN
    through ``iter_carmen`` in file order).

    Topics are normalised to ``/scan``, ``/odom`` and ``/tf_static`` (the laser mount first).
    ``static_transforms``: mounts the log lacks (``fgloc map --static-transform``); the one to the
    scans' frame wins over the log's (:func:`planar_mount`: an upside-down laser's scans mirrored).
    A default topic the log lacks is its only topic of that type (:func:`pick_topics`: a name other
    than the default is the user's, kept).  A log without odometry (none of type nav_msgs/Odometry),
    or ``odom_topic`` "", gives the scans alone; a named odometry topic the log lacks, or a default
    one beside other Odometry topics, is a one-line :class:`LogError`.
    """
    from fgloc.io import open_log
    from fgloc.io.topics import Topics

    p = Path(path)
    if not p.exists():
        raise LogError(f"{p}: log file not found")
    from fgloc.io.formats import detect_format

    detect_format(p)  # one-line errors for what is no log at all (an empty file, a Git LFS pointer)
    if is_carmen(p):
        # CARMEN in file order: open_log yields ipc-time order, and real logs (intel) have ipc
        # stamps that jump backwards, where sorting pairs scans with the wrong odometry
        # (intel rotational relation error 0.47 -> 0.56 +- 1.54 deg)
        from fgloc.io.carmen import iter_carmen

        it = iter_carmen(p)
        if static_transforms:  # the scans' frame (read up to the first scan), then from the top again
            frame = next((m.frame_id for _, m in it if isinstance(m, LaserScan) and "rear" not in m.frame_id),
                         "laser")  # the front laser's (CARMEN's RLASER lines are left out beside it)
            it = iter_carmen(p)
            mine = mount_of(frame, static_transforms)
            _check_mount_frames(static_transforms, frame, p)
            if mine is not None:
                it = with_mount(it, *planar_mount(mine))
        yield from it
        return
    scans_only = not odom_topic
    src = open_log(p, Topics(scan=scan_topic, odom=odom_topic or DEFAULT_ODOM))
    picked = pick_topics(src, p, {"scan": (scan_topic, False), "odom": (odom_topic or DEFAULT_ODOM, False)})
    scan_topic, odom_topic = picked["scan"], picked["odom"]
    src.topics = Topics(scan=scan_topic, odom=odom_topic)
    if not src.has(scan_topic) and scan_topic == DEFAULT_SCAN:
        lasers = _topics_of(src, (LASER_SCAN, MULTI_ECHO_SCAN))
        if len(lasers) > 1:  # several lasers, none the default: which one is the user's to say
            raise LogError(f"{p}: no {scan_topic}; the log has {len(lasers)} laser scan topics: name the one to map "
                           f"with --scan-topic {' | '.join(lasers)}")
    src.require(scan_topic)
    if not scans_only and not src.has(odom_topic):
        have = ", ".join(f"{t} ({v['type']}, {v['count']})" for t, v in sorted(src.summary()["topics"].items()))
        if odom_topic != DEFAULT_ODOM or _topics_of(src, (ODOMETRY,)):
            raise LogError(f"{p}: no odometry on {odom_topic}: name the wheel odometry's topic with --odom-topic "
                           f"(or map the scans alone with --odom-topic ''); its topics: {have or 'none'}")
        scans_only = True  # no odometry at all: the scans are matched to each other alone
    if scans_only:
        odom_topic = ""
    skew = src.clock_skew([scan_topic, odom_topic]) if odom_topic and src.has(odom_topic) else None
    if skew is not None:  # scans would be paired with odometry from another time
        raise LogError(f"{p}: {skew}")
    mine = mount_of(src.scan_frame(), static_transforms)
    if static_transforms:
        _check_mount_frames(static_transforms, src.scan_frame(), p)
    rename = {scan_topic: "/scan", odom_topic: "/odom"}
    wanted = [t for t in (scan_topic, odom_topic) if src.has(t)]
    msgs = ((rename.get(topic, topic), msg) for topic, msg in src.messages(wanted))
    if mine is not None:  # the user's mount: the log's is not looked up (nor its scans mirrored by it)
        yield from with_mount(msgs, *planar_mount(mine))
        return
    yield "/tf_static", [src.laser_mount()]
    yield from msgs


def _topics_of(src: Any, types: tuple[str, ...]) -> list[str]:
    """The log's topics of these types that hold messages, sorted."""
    from fgloc.io.topics import normalize_type

    return sorted(t for t, ty in src.topic_types().items() if src.has(t) and normalize_type(ty) in types)


def _check_mount_frames(static_transforms: Sequence[StaticTransform], scan_frame: str, path: Path) -> None:
    """A given mount that is not the laser's (the only one mapping uses) is a one-line error, not
    silently unused."""
    from fgloc.frames.tf import frame_name

    other = [t for t in static_transforms if frame_name(t.child) != frame_name(scan_frame)]
    if other:
        t = other[0]
        raise ConfigError(f"{path}: --static-transform {t.parent} {frame_name(t.child)}: the log's scans are in "
                          f"'{frame_name(scan_frame)}', not '{frame_name(t.child)}' (mapping uses the laser's mount "
                          f"only): give the scans' frame as CHILD, e.g. --static-transform {t.parent} "
                          f"{frame_name(scan_frame)} ...")


def rear_frames(frames: Iterable[str]) -> set[str]:
    """The frames of a scan stream to leave out: ``*rear*`` ones when the stream mixes them with
    others (CARMEN's front and rear lasers on one topic); none when it has one laser, whatever its
    name (a topic the user chose, a robot with a rear laser only)."""
    fs = {f.lstrip("/") for f in frames}
    rear = {f for f in fs if "rear" in f}
    return rear if rear and rear != fs else set()


def pair_scans(messages: Iterable[tuple[str, object]],
               name: str | Path = "log") -> tuple[list[ScanRecord], StaticTransform]:
    """Collect scans with odometry poses and the ``base_link -> laser`` mount (identity if absent).

    The mount is the transform whose child is the scans' ``frame_id`` (REP 105 frame names
    vary: ``base_scan``, ``laser_link``, ...); failing that, the last one to a ``*laser*``
    frame (CARMEN's front laser).  Scans of a rear laser are left out only beside a front one
    (:func:`rear_frames`).  ``name``: the log, for the one-line errors.
    """
    mount = StaticTransform("base_link", "laser", np.zeros(3))
    by_child: dict[str, StaticTransform] = {}
    events: list[tuple[int, object]] = []  # (kind 0 odom / 1 scan, msg)
    odo_stamps: list[float] = []
    odo_poses: list[FloatArray] = []
    dead = np.zeros(3)
    last_t: float | None = None
    for topic, msg in messages:
        if topic == "/tf_static" and isinstance(msg, list):
            for tf in msg:
                if not isinstance(tf, StaticTransform):
                    continue
                by_child[tf.child.lstrip("/")] = tf
                if "laser" in tf.child and "rear" not in tf.child:
                    mount = tf
        elif topic == "/odom" and isinstance(msg, Odometry):
            if msg.pose is not None and np.all(np.isfinite(msg.pose)):
                pose = np.asarray(msg.pose, dtype=float)
            else:
                tw = np.asarray(msg.twist, dtype=float)
                if last_t is not None and np.all(np.isfinite(tw)):
                    dt = min(max(msg.stamp - last_t, 0.0), 1.0)
                    dead = compose(dead, np.array([tw[0] * dt, tw[1] * dt, tw[2] * dt]))
                pose = dead.copy()
            last_t = msg.stamp
            odo_stamps.append(float(msg.stamp))
            odo_poses.append(pose)
            events.append((0, len(odo_stamps) - 1))
        elif topic == "/scan" and isinstance(msg, LaserScan):
            if np.isfinite(msg.stamp):
                events.append((1, msg))
    drop = rear_frames({m.frame_id for k, m in events if k == 1 and isinstance(m, LaserScan)})
    if drop:
        events = [(k, m) for k, m in events if k == 0 or not (isinstance(m, LaserScan)
                                                                 and m.frame_id.lstrip("/") in drop)]
    scan_frame = next((m.frame_id.lstrip("/") for k, m in events if k == 1 and isinstance(m, LaserScan)), None)
    if scan_frame is not None and scan_frame in by_child:
        mount = by_child[scan_frame]
    if not scans_found(events):
        raise LogError(f"{name}: no laser scans")
    if not odo_stamps:  # scans only: no odometry pose (the mapper matches the scans to each other alone)
        recs = [ScanRecord(float(m.stamp), np.full(3, np.nan), m, k)
                for k, m in enumerate(m for kind, m in events if kind == 1 and isinstance(m, LaserScan))]
        return recs, mount
    st = np.asarray(odo_stamps)
    po = np.asarray(odo_poses)
    # each scan between the odometry messages before and after it in the file: interpolated when
    # their stamps bracket it, else the one before (the first one before any); all at once
    scans: list[LaserScan] = []
    before: list[int] = []
    after: list[int] = []
    prev_odo = -1
    n_pending = 0
    for kind, item in events:
        if kind == 0:
            assert isinstance(item, int)
            after.extend([item] * n_pending)
            n_pending = 0
            prev_odo = item
        else:
            assert isinstance(item, LaserScan)
            scans.append(item)
            before.append(prev_odo)
            n_pending += 1
    after.extend([-1] * n_pending)
    if not scans:
        raise LogError(f"{name}: no laser scans")
    t = np.array([sc.stamp for sc in scans], dtype=float)
    i0 = np.asarray(before, dtype=np.int64)
    i1 = np.asarray(after, dtype=np.int64)
    pose = po[np.where(i0 >= 0, i0, np.where(i1 >= 0, i1, 0))].copy()
    s0, s1 = st[np.maximum(i0, 0)], st[np.maximum(i1, 0)]
    inter = (i0 >= 0) & (i1 >= 0) & (s0 <= t) & (t <= s1) & (s1 > s0)
    if inter.any():
        pose[inter] = interpolate_pairs(s0[inter], po[i0[inter]], s1[inter], po[i1[inter]], t[inter])
    recs = [ScanRecord(float(t[k]), pose[k], sc, k) for k, sc in enumerate(scans)]
    return recs, mount


def scans_found(events: Iterable[tuple[int, object]]) -> bool:
    return any(kind == 1 for kind, _ in events)


def scans_only(records: Sequence[ScanRecord]) -> bool:
    """Whether the records carry no odometry at all (a log with scans only)."""
    return bool(records) and not any(np.all(np.isfinite(r.odom)) for r in records)


def scan_problem(scan: LaserScan) -> str | None:
    """Why a scan cannot be mapped at all, or None: beams without directions (``angle_increment``
    0 or not finite with more than one beam, ``angle_min`` not finite)."""
    if not math.isfinite(scan.angle_min):
        return "angle_min not finite"
    if len(scan.ranges) > 1 and not (math.isfinite(scan.angle_increment) and scan.angle_increment != 0.0):
        return "angle_increment 0 or not finite (the beams have no directions)"
    return None


def has_return(scan: LaserScan) -> bool:
    """Whether any beam of the scan returned within its ``[range_min, range_max]``."""
    r = np.asarray(scan.ranges, dtype=float)
    lo = scan.range_min if math.isfinite(scan.range_min) else 0.0
    hi = scan.range_max if math.isfinite(scan.range_max) else np.inf
    return bool(np.any(np.isfinite(r) & (r >= lo) & (r < hi) & (r > 0.0)))


def interpolate_pairs(t0: FloatArray, p0: FloatArray, t1: FloatArray, p1: FloatArray, t: FloatArray) -> FloatArray:
    """Poses at ``t`` between ``p0`` at ``t0`` and ``p1`` at ``t1`` (row by row; ``t0 < t1``): the
    arithmetic of :func:`fgloc.geometry.interpolate_poses` on each pair, bit for bit."""
    f = (t - t0) / (t1 - t0)
    out = np.empty((len(t), 3))
    out[:, :2] = p0[:, :2] + f[:, None] * (p1[:, :2] - p0[:, :2])
    dyaw = wrap_angle(p1[:, 2] - p0[:, 2])
    out[:, 2] = wrap_angle(p0[:, 2] + f * dyaw)
    return out


def open_log_scan_stamps(path: str | Path, records: list[ScanRecord]) -> FloatArray:
    """Each record's stamp as :func:`fgloc.io.open_log` (``fgloc run``) gives it: a CARMEN line out of
    place in its topic whose pose fits the file order gets the repaired stamp (the mapper keeps the
    file's stamps, which relation files index by); other formats: the records' own.  To compare a
    localization run of a log with the mapper's trajectory of it, re-stamp the latter with these."""
    own = np.array([r.stamp for r in records], dtype=float)
    if not is_carmen(path):
        return own
    from fgloc.io.carmen import carmen_file_order

    scans = [m for t, m in carmen_file_order(path)
             if t == "/scan" and isinstance(m, LaserScan) and np.isfinite(m.stamp)]
    drop = rear_frames({m.frame_id for m in scans})
    fixed = np.array([m.stamp for m in scans if m.frame_id.lstrip("/") not in drop], dtype=float)
    idx = np.array([r.index for r in records], dtype=np.int64)
    return fixed[idx] if len(fixed) > int(idx.max(initial=-1)) else own
