"""One reader interface over every log format fgloc reads (kiss-icp's dataloaders are the model).

:func:`fgloc.io.open_log` picks the format by content and returns a :class:`LogSource`:

* :class:`~fgloc.io.mcap_reader.McapSource`: ROS 2 MCAP (also a rosbag2 folder holding one ``.mcap``);
* :class:`~fgloc.io.rosbag2.Rosbag2Source`: a rosbag2 folder with SQLite ``.db3`` or split MCAP files;
* :class:`~fgloc.io.rosbag1.Rosbag1Source`: a ROS 1 ``.bag``;
* :class:`~fgloc.io.carmen.CarmenSource`: a CARMEN ``.clf`` / ``.log`` (plain, gzip or bzip2).

Every source offers the same queries: :meth:`LogSource.summary`, :meth:`~LogSource.topic_types`,
:meth:`~LogSource.has`, :meth:`~LogSource.require`, :meth:`~LogSource.messages` (``(topic,
message)`` in log-time order), :meth:`~LogSource.records` (the same with log time and, where the
input is ROS 2 CDR, the original bytes and schema for copying), :meth:`~LogSource.laser_mount`,
:meth:`~LogSource.ground_truth`, :meth:`~LogSource.clock_skew`, and the health counters
``truncated``, ``damaged_chunks``, ``undecodable`` and ``skipped``.

Log time is the recorder's time (MCAP log time, bag record time); a CARMEN line's is its
ipc timestamp.  Messages come in log-time order, ties in file order.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from operator import sub
from pathlib import Path
from typing import ClassVar, NamedTuple

import numpy as np

from fgloc.errors import LogError
from fgloc.frames.tf import TfTree, frame_name, tf_edge
from fgloc.io.ros import mirror_scan
from fgloc.io.topics import Topics
from fgloc.types import LaserScan, Odometry, StaticTransform, Trajectory

log = logging.getLogger(__name__)

#: a message stream's stamps are regular when their median spacing is at least this share of their
#: mean spacing; below it they come in bursts (a logger that stamps several messages when it writes
#: them: the stamps do not say when each was measured).  fgloc.io.carmen and fgloc.localization.clock
REGULAR = 0.5
#: increasing stamps :func:`stamp_spacing` needs before a spacing is judged
SPACING_MIN_STAMPS = 3


def stamp_spacing(stamps: Iterable[float]) -> tuple[float, float] | None:
    """``(median, mean)`` spacing (s) of the increasing stamps among ``stamps`` (a stamp not after
    the last one kept is left out); None with fewer than ``SPACING_MIN_STAMPS`` of them.  Regular
    stamps: ``median >= REGULAR * mean``."""
    kept: list[float] = []
    for t in stamps:
        if not kept or t > kept[-1]:
            kept.append(t)
    if len(kept) < max(SPACING_MIN_STAMPS, 2):
        return None
    d = sorted(map(sub, kept[1:], kept[:-1]))  # np.median(np.diff(kept))'s, without numpy's overhead
    m = len(d) // 2
    median = d[m] if len(d) % 2 else (d[m - 1] + d[m]) / 2.0
    return float(median), (kept[-1] - kept[0]) / (len(kept) - 1)


MAX_TF_MESSAGES = 2000  # /tf messages looked through for the laser mount


@dataclass(frozen=True)
class ChannelInfo:
    """A topic as a log stores it: its type and, for ROS 2 inputs, the schema to copy it with."""

    topic: str
    type: str                      # normalized ROS 2 type name (``pkg/msg/Type``)
    schema_name: str = ""
    schema_encoding: str = ""      # "ros2msg", "ros2idl", "" (none)
    schema_data: bytes = b""
    message_encoding: str = "cdr"


class Record(NamedTuple):
    """One message of a log: its topic, the fgloc object, its log time and, when the input
    holds it as ROS 2 CDR, the original bytes (``data``) and the channel to copy it with
    (:meth:`fgloc.io.mcap_writer.LogWriter.copy`); ``data`` is None otherwise."""

    topic: str
    msg: object
    log_time_ns: int
    data: bytes | None = None
    channel: ChannelInfo | None = None


@dataclass
class TopicInfo:
    type: str
    count: int = 0


class LogSource:
    """Base of every log format's reader (see the module doc).  Subclasses fill
    ``_topic_info``, ``_start_ns``, ``_end_ns``, ``_n`` when opened and implement
    :meth:`_records` (decoded records of the wanted topics in log-time order, scans not yet
    mirrored); tf messages they decode go through :meth:`note_tf` (upside-down flags)."""

    format: ClassVar[str] = "?"

    def __init__(self, path: str | Path, topics: Topics | None = None) -> None:
        self.path = Path(path)
        self.topics = topics or Topics()
        self.truncated: str | None = None         # where a cut file broke (one line)
        self._damaged: dict[int, str] = {}        # offset -> reason of corrupt chunks skipped (MCAP)
        self.lost_messages: int | None = None     # messages in damaged chunks, when known
        self.undecodable: dict[str, int] = {}     # topic -> messages that failed to decode
        self.skipped: dict[str, int] = {}         # kind -> malformed / unknown lines (CARMEN)
        self.indexed = False
        self._topic_info: dict[str, TopicInfo] = {}
        self._start_ns: int | None = None
        self._end_ns: int | None = None
        self._n = 0
        self._tf = TfTree()
        self._unstamped: dict[str, bool] = {}      # topics whose first header stamp is 0 (clock_offsets)
        self._mirror_frames: set[str] = set()     # scan frames read mirrored (laser_mount)
        # True (fgloc import): records of types fgloc does not read come too, as ``msg`` None with their
        # ROS 2 CDR bytes and channel (a ROS 1 bag's converted by rosbags), instead of being skipped
        self.keep_other_types = False
        # True: a source that can (McapSource) keeps what ground_truth() needs while records() reads
        # the log through, so that ground_truth() after that pass reads nothing again
        self.collect_ground_truth = False

    # -- queries -----------------------------------------------------------------------------
    @property
    def damaged_chunks(self) -> int:
        """Damaged chunks skipped so far (all of them after :meth:`verify` or a full read)."""
        return len(self._damaged)

    def verify(self) -> int:
        """Check every chunk of the file (formats with checksummed chunks); returns
        :attr:`damaged_chunks`."""
        return self.damaged_chunks

    def topic_types(self) -> dict[str, str]:
        return {t: i.type for t, i in self._topic_info.items()}

    def has(self, topic: str) -> bool:
        return topic in self._topic_info and self._topic_info[topic].count > 0

    def require(self, *topics: str) -> None:
        """Raise :class:`LogError` naming the file, the topic and the topics that exist."""
        for t in topics:
            if not self.has(t):
                have = ", ".join(sorted(self._topic_info)) or "none"
                raise LogError(f"{self.path}: topic '{t}' not in log (topics: {have})")

    def damage(self) -> str | None:
        """One line on what could not be read (damaged chunks, undecodable messages), or None."""
        parts = []
        if self.damaged_chunks:
            lost = "" if self.lost_messages is None else f", {self.lost_messages} messages lost"
            parts.append(f"{self.damaged_chunks} damaged chunk(s) skipped{lost}")
        if self.undecodable:
            parts.append("undecodable messages skipped: " + ", ".join(
                f"{t} {n}" for t, n in sorted(self.undecodable.items())))
        return "; ".join(parts) or None

    def summary(self) -> dict:
        """``{"path", "format", "topics": {name: {"type", "count"}}, "messages", "start", "end",
        "duration", "indexed", "truncated", "damaged_chunks", "skipped"}`` (times in seconds of
        log time)."""
        start = None if self._start_ns is None else self._start_ns * 1e-9
        end = None if self._end_ns is None else self._end_ns * 1e-9
        return {
            "path": str(self.path),
            "format": self.format,
            "topics": {t: {"type": i.type, "count": i.count} for t, i in sorted(self._topic_info.items())},
            "messages": self._n,
            "start": start,
            "end": end,
            "duration": (end - start) if start is not None and end is not None else 0.0,
            "indexed": self.indexed,
            "truncated": self.truncated,
            "damaged_chunks": self.damaged_chunks,
            "skipped": dict(self.skipped),
        }

    # -- messages ----------------------------------------------------------------------------
    def _wanted(self, topics: Iterable[str] | None) -> set[str]:
        if topics is None:
            return {t for t in self.topics.roles() if self.has(t)}
        want = set(topics)
        self.require(*sorted(want))
        return want

    def messages(self, topics: Iterable[str] | None = None) -> Iterator[tuple[str, object]]:
        """``(topic, message)`` in log-time order; ``topics`` None = every role topic present.

        A requested topic that is not in the log raises :class:`LogError` (before the first
        message); topics of a type fgloc does not read are skipped with a warning.
        """
        return ((r.topic, r.msg) for r in self.records(topics))

    def records(self, topics: Iterable[str] | None = None) -> Iterator[Record]:
        """:class:`Record` s in log-time order (see :meth:`messages`).  Scans of a frame that
        :meth:`laser_mount` found upside down (before this call) come mirrored, and the
        transforms that turned them upside down come upright (their yaw only), as the upright
        scanner the mirrored scans are from has them: a log written from these messages (``fgloc
        import``, a run's recording) is read back the same (``rec.data`` keeps the original bytes)."""
        it = self._records(self._wanted(topics))
        return self._mirrored(it, self._flipped_edges()) if self._mirror_frames else it

    def _flipped_edges(self) -> set[tuple[str, str]]:
        """``(parent, child)`` of the flipped transforms on the chains from the mirrored scan frames."""
        out: set[tuple[str, str]] = set()
        for frame in self._mirror_frames:
            cur = frame_name(frame)
            for _ in range(64):
                tr = self._tf.parents.get(cur)
                if tr is None:
                    break
                edge = tf_edge(tr)
                if self._tf.flipped.get(edge, False):
                    out.add(edge)
                cur = edge[0]
        return out

    def _mirrored(self, it: Iterator[Record], edges: set[tuple[str, str]]) -> Iterator[Record]:
        for rec in it:
            if isinstance(rec.msg, LaserScan) and rec.msg.frame_id.lstrip("/") in self._mirror_frames:
                rec = rec._replace(msg=mirror_scan(rec.msg))
            elif edges and isinstance(rec.msg, list) and any(tf_edge(t) in edges for t in rec.msg):
                rec = rec._replace(msg=[StaticTransform(t.parent, t.child, t.pose, t.z)
                                        if tf_edge(t) in edges else t for t in rec.msg])
            yield rec

    def _records(self, want: set[str]) -> Iterator[Record]:
        raise NotImplementedError

    def note_tf(self, transforms: list[StaticTransform], flips: list[bool]) -> None:
        for tr, flip in zip(transforms, flips, strict=True):
            if flip:
                self._tf.flipped[tf_edge(tr)] = True

    # -- derived -----------------------------------------------------------------------------
    def clock_offsets(self, topics: Iterable[str]) -> dict[str, float]:
        """``{topic: header stamp - log time}`` (s) of the first message of each topic present.

        A recorder stamps log time on its own clock; sensors on one clock show (nearly) the same
        offset, whatever that clock is (wall time, sim time, or equal for fgloc's own logs).
        """
        out: dict[str, float] = {}
        for t in topics:
            if not self.has(t):
                continue
            for rec in self._records({t}):
                st = getattr(rec.msg, "stamp", None)
                if st is not None and math.isfinite(float(st)):
                    out[t] = float(st) - rec.log_time_ns * 1e-9
                    self._unstamped[t] = float(st) == 0.0
                break
        return out

    def clock_skew(self, topics: Iterable[str], tolerance_s: float = 10.0) -> str | None:
        """None, or a one-line description of topics stamped by different clocks: their
        :meth:`clock_offsets` differ by more than ``tolerance_s`` (e.g. a laser driver on
        sim time or its own device clock while the odometry is on wall time)."""
        off = self.clock_offsets(topics)
        if len(off) < 2:
            return None
        lo, hi = min(off, key=lambda t: off[t]), max(off, key=lambda t: off[t])
        d = off[hi] - off[lo]
        if d <= tolerance_s:
            return None
        unset = [t for t in (hi, lo) if self._unstamped.get(t)]
        why = f" (the first {unset[0]} header stamp is 0: does its driver leave the stamps unset?)" if unset else ""
        return (f"{hi} and {lo} are stamped by different clocks: relative to the recording time their "
                f"header stamps differ by {d:.1f} s{why}")

    def scan_frame(self) -> str:
        """The ``frame_id`` of the first scan (``laser`` if none)."""
        if self.has(self.topics.scan):
            for rec in self._records({self.topics.scan}):
                return getattr(rec.msg, "frame_id", "laser").lstrip("/") or "laser"
        return "laser"

    def laser_mount(self) -> StaticTransform:
        """``base_link -> <scan frame>`` from /tf_static (or the first /tf), identity if absent.

        The scan's ``frame_id`` (of the first scan) names the laser frame; a chain of
        transforms from ``base_link`` (or ``base_footprint``) to it is composed.  A scanner
        mounted upside down (its z axis pointing down, as tf2 would transform its beams) is
        returned as the equivalent upright mount, and from then on :meth:`messages` yields
        its scans mirrored (``angle_min`` and ``angle_increment`` negated), as nav2 does.
        """
        frame = self.scan_frame()
        sources = [t for t in (self.topics.tf_static, self.topics.tf) if self.has(t)]
        for src in sources:
            n = 0
            for rec in self._records({src}):
                self._tf.add(rec.msg)  # type: ignore[arg-type]
                n += 1
                found = self._tf.chain(frame)
                if found is not None:
                    return self._use_mount(found, frame)
                if src == self.topics.tf and n >= MAX_TF_MESSAGES:
                    break
        found = self._tf.chain(frame)
        if found is not None:
            return self._use_mount(found, frame)
        log.warning("%s: no transform base_link -> %s in %s; assuming the laser at the robot centre",
                    self.path, frame, " or ".join(sources) or "the log (no tf topics)")
        return StaticTransform("base_link", frame, np.zeros(3))

    def _use_mount(self, found: tuple[StaticTransform, bool], frame: str) -> StaticTransform:
        mount, mirrored = found
        if mirrored:
            self._mirror_frames.add(frame_name(frame))
            log.info("%s: laser %s is mounted upside down; its scans are read mirrored", self.path, frame)
        return mount

    def ground_truth(self) -> Trajectory | None:
        """The ``/ground_truth`` topic as a trajectory (map frame), or None if absent."""
        topic = self.topics.ground_truth
        if not self.has(topic):
            return None
        stamps, poses = [], []
        for rec in self._records({topic}):
            m = rec.msg
            if isinstance(m, Odometry) and m.pose is not None:
                stamps.append(m.stamp)
                poses.append(m.pose)
        if not stamps:
            return None
        return Trajectory.from_unsorted(np.asarray(stamps), np.asarray(poses), "map")

    def close(self) -> None:
        """Release open files (sources open them per iteration; nothing to do by default)."""

    def __enter__(self) -> LogSource:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
