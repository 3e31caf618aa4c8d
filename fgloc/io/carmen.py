"""CARMEN log files (``.clf`` / ``.log``, plain, gzip or bzip2) as a stream of fgloc messages.

Line formats (one message per line, the last three fields are always
``ipc_timestamp ipc_hostname logger_timestamp``; the ipc timestamp is the message time):

* ``ODOM x y theta tv rv accel ...``                       -> ``("/odom", Odometry)``
* ``FLASER n r1..rn x y theta odom_x odom_y odom_theta ...`` -> ``("/scan", LaserScan)``
  (``RLASER`` the same for the rear laser, frame ``rear_laser``)
* ``ROBOTLASER1 type start_angle fov resolution max_range accuracy remission_mode
  n r1..rn m rem1..remm laser_x laser_y laser_theta robot_x robot_y robot_theta
  tv rv forward_safety side_safety turn_axis ...``            -> ``("/scan", LaserScan)``

Everything else (``#`` comments, ``PARAM``, ``SYNC``, ``NEFF``, ``TRUEPOS``, ...) is skipped
and counted; malformed lines are skipped and counted too, and one warning with the counts
is logged at the end (never an exception for a bad line).

Beam geometry of FLASER/RLASER (which carry no angles) follows CARMEN's own
``carmen_laser_guess_angle_increment``: the first beam is at -90 deg; 180 or 181 beams are
1 deg apart, 360 or 361 beams 0.5 deg, 400 or 401 beams 0.25 deg, any other count spreads
``n`` beams over 180 deg (``pi / (n - 1)``).  So a 180-beam scan covers -90 .. +89 deg.

No-return readings (REP 117 ``+inf``): CARMEN writes the laser's maximum code instead of
"nothing seen" (81.83 / 81.91 m for SICK LMS error codes, 50.00 m in the ACES log, whose
driver clipped at 50 m).  The threshold is decided per file from the first
``PEEK_LASER_LINES`` FLASER/RLASER scans: if their largest reading repeats in at least
``NO_RETURN_FRACTION`` of all beams it is the no-return code; the threshold is that code,
capped at ``SICK_MAX_RANGE_M`` (a SICK LMS cannot measure beyond 80 m, so anything at or
above that is an error code).  Readings ``>= threshold`` become ``+inf`` and the scan's
``range_max`` is the threshold.  Readings ``<= 0`` become NaN (invalid).  ROBOTLASER1 lines
carry their own maximum range, used the same way.  ``max_range_m`` overrides the detection.

Laser mount: the FLASER pose ``x y theta`` is the laser's pose and ``odom_x odom_y
odom_theta`` the robot's odometry pose (ROBOTLASER1: laser pose vs robot pose), so
``base_link -> laser = between(odom_pose, laser_pose)`` of the first laser line.  It is
emitted once, first, as ``("/tf_static", [StaticTransform, ...])`` (identity when the two
poses coincide, as in the Radish logs).

Odometry: from ODOM lines (pose ``[x, y, theta]``, twist ``[tv, 0, rv]``).  If the peek
window (the lines up to the ``PEEK_LASER_LINES``-th laser line) has no ODOM line, odometry
is taken from every laser line's odometry pose instead (ROBOTLASER1: with its tv / rv; FLASER:
twist by finite difference of consecutive poses, zero for the first), yielded after its scan
with the scan's stamp.

ODOM stamps in bursts: a logger that writes its ODOM lines in bursts (intel: median spacing 0.9 ms
for a mean of 113 ms over the whole log) stamps them when they were written, not when each pose was
measured; each front laser line's odometry pose is the odometry when that scan was logged.  So
when the peek window's ODOM stamps are not regular (the median spacing of the increasing
stamps below ``BURST_REGULAR`` of their mean: :func:`fgloc.io.source.stamp_spacing`, the
rule ``fgloc.localization.clock`` uses; from three stamps on) and every front
laser line there carries an odometry pose, the ODOM lines are read and counted but not yielded;
odometry comes from the front laser lines' poses (FLASER twist by finite difference; CarmenSource
takes it again over the stamps it yields, its repaired ones, in its order), each yielded just
before its scan, stamped ``CARRIED_LEAD_S`` earlier, so the scan finds the odometry it was
taken at.  One warning says so; ``stats["odom_from_laser"]`` is true and
``stats["odom_bursts"]`` holds the spacings.  Logs with regular ODOM stamps (fr079, aces) read
as before.

The file is read twice, lazily: a short peek (mount, no-return code, ODOM present) and then
the streaming pass; it is never loaded whole.
"""

from __future__ import annotations

import bz2
import gzip
import heapq
import io
import logging
import math
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

import numpy as np

from fgloc.errors import LogError, read_user_head
from fgloc.geometry import between
from fgloc.io.ros import stamp_to_ns
from fgloc.io.source import REGULAR, LogSource, Record, TopicInfo, stamp_spacing
from fgloc.io.topics import LASER_SCAN, ODOMETRY, TF_MESSAGE, Topics
from fgloc.types import LaserScan, Odometry, StaticTransform

log = logging.getLogger(__name__)

PEEK_LASER_LINES = 500
NO_RETURN_FRACTION = 0.005
SICK_MAX_RANGE_M = 80.0
RANGE_MIN_M = 0.0
#: ODOM stamps are regular when their median spacing is at least this share of the mean spacing
#: (fgloc.io.source's rule, shared with fgloc.localization.clock); below it they come in bursts
BURST_REGULAR = REGULAR
#: s, odometry from a laser line's pose (bursty ODOM) is stamped this much before its scan
CARRIED_LEAD_S = 1e-6

SCAN_TOPIC = "/scan"
ODOM_TOPIC = "/odom"
TF_STATIC_TOPIC = "/tf_static"

LASER_KINDS = ("FLASER", "RLASER", "ROBOTLASER1")
IGNORED_KINDS = ("PARAM", "SYNC", "NEFF", "TRUEPOS", "NMEAGGA", "NMEARMC", "SONAR", "BUMPER")
FRAME_OF = {"FLASER": "laser", "RLASER": "rear_laser", "ROBOTLASER1": "laser"}


def open_text(path: str | Path) -> IO[str]:
    """Open a plain, gzip or bzip2 text file (by its magic bytes), decoding leniently."""
    path = Path(path)
    magic = read_user_head(path, 3)
    raw: IO[bytes] | gzip.GzipFile | bz2.BZ2File
    if magic[:2] == b"\x1f\x8b":
        raw = gzip.open(path, "rb")
    elif magic == b"BZh":
        raw = bz2.open(path, "rb")
    else:
        raw = path.open("rb")
    return io.TextIOWrapper(raw, encoding="utf-8", errors="replace")


def flaser_angle_increment(n: int) -> float:
    """Beam spacing of an ``n``-beam FLASER/RLASER scan (CARMEN's convention, radians)."""
    if n in (180, 181):
        return math.pi / 180.0
    if n in (360, 361):
        return math.pi / 360.0
    if n in (400, 401):
        return math.pi / 720.0
    return math.pi / max(n - 1, 1)


@dataclass
class _Laser:
    kind: str
    stamp: float
    ranges: np.ndarray
    laser_pose: np.ndarray | None
    odom_pose: np.ndarray | None
    angle_min: float
    angle_increment: float
    max_range: float | None = None  # ROBOTLASER1 only
    twist: np.ndarray | None = None  # ROBOTLASER1 only (tv, 0, rv)


MAX_STAMP_S = 1e10  # a plausible ipc timestamp (unix time before the year 2286)


def _stamp(text: str) -> float:
    """An ipc timestamp; ValueError for inf, nan, negative or absurd values."""
    t = float(text)
    if not 0.0 <= t < MAX_STAMP_S:
        raise ValueError(f"timestamp {text} out of range")
    return t


def _finite(vals: list[float]) -> list[float]:
    if not all(math.isfinite(v) for v in vals):
        raise ValueError("non-finite value")
    return vals


def _parse_odom(tok: list[str]) -> Odometry:
    # ODOM x y theta tv rv accel ipc_timestamp host logger_timestamp
    x, y, th, tv, rv = _finite([float(v) for v in tok[1:6]])
    stamp = _stamp(tok[7])
    return Odometry(
        stamp=stamp,
        twist=np.array([tv, 0.0, rv]),
        pose=np.array([x, y, th]),
    )


def _parse_laser(tok: list[str]) -> _Laser:
    kind = tok[0]
    if kind == "ROBOTLASER1":
        start, _fov, res, max_range = _finite([float(v) for v in tok[2:6]])
        n = int(tok[8])
        if not 0 < n <= len(tok):
            raise ValueError("bad beam count")
        ranges = np.array(tok[9 : 9 + n], dtype=np.float64)
        i = 9 + n
        m = int(tok[i])
        if not 0 <= m <= len(tok):
            raise ValueError("bad remission count")
        i += 1 + m
        rest = _finite([float(v) for v in tok[i : i + 11]])
        if len(rest) < 11 or len(tok) < i + 12 or len(ranges) != n or max_range <= 0.0:
            raise ValueError("short ROBOTLASER1 line")
        stamp = _stamp(tok[i + 11])
        return _Laser(
            kind, stamp, ranges, np.array(rest[0:3]), np.array(rest[3:6]), start, res,
            max_range=max_range, twist=np.array([rest[6], 0.0, rest[7]]),
        )
    n = int(tok[1])
    if not 0 < n <= len(tok):
        raise ValueError("bad beam count")
    ranges = np.array(tok[2 : 2 + n], dtype=np.float64)
    if len(ranges) != n:
        raise ValueError("short laser line")
    tail = tok[2 + n :]
    laser_pose = odom_pose = None
    if len(tail) >= 9:  # x y theta odom_x odom_y odom_theta ipc host logger
        vals = _finite([float(v) for v in tail[:6]])
        laser_pose, odom_pose, stamp = np.array(vals[0:3]), np.array(vals[3:6]), _stamp(tail[6])
    elif len(tail) >= 1:  # old format: ipc host logger only
        stamp = _stamp(tail[0])
    else:
        raise ValueError("laser line without timestamp")
    return _Laser(kind, stamp, ranges, laser_pose, odom_pose, -math.pi / 2, flaser_angle_increment(n))


def laser_line_poses(path: str | Path) -> tuple[list[float], list[np.ndarray]]:
    """``(ipc stamps, poses)`` of the front laser lines' ``x y theta`` (the laser's pose: corrected in
    a SLAM-corrected log), in file order; malformed lines and lines without a pose are left out."""
    stamps: list[float] = []
    poses: list[np.ndarray] = []
    with open_text(path) as f:
        for line in f:
            tok = line.split()
            if not tok or tok[0] not in LASER_KINDS or tok[0] == "RLASER":
                continue
            try:
                las = _parse_laser(tok)
            except (ValueError, IndexError, OverflowError):
                continue
            if las.laser_pose is not None:
                stamps.append(las.stamp)
                poses.append(las.laser_pose)
    return stamps, poses


@dataclass
class _Peek:
    mounts: dict[str, np.ndarray] = field(default_factory=dict)
    has_odom: bool = False
    no_return_m: float = SICK_MAX_RANGE_M
    n_laser: int = 0
    odom_stamps: list[float] = field(default_factory=list)
    n_front: int = 0          # front laser lines (FLASER, ROBOTLASER1)
    n_front_posed: int = 0    # ... that carry an odometry pose
    bursts: tuple[float, float] | None = None  # (median, mean) ODOM spacing when they come in bursts


class CarmenReader:
    """Iterable over ``(topic, message)`` of one CARMEN log; ``stats`` counts the lines.

    ``stats`` (filled while iterating): ``{"ODOM": n, "FLASER": n, ..., "skipped": {kind: n},
    "malformed": {kind: n}, "odom_from_laser": bool, "no_return_m": float}``, and when the ODOM
    stamps come in bursts ``"odom_bursts": {"median_spacing_s": s, "mean_spacing_s": s}`` (see the
    module docstring).
    """

    def __init__(self, path: str | Path, max_range_m: float | None = None) -> None:
        self.path = Path(path)
        self.max_range_m = max_range_m
        self.stats: dict = {}
        self.last_laser_pose: np.ndarray | None = None  # the odometry pose of the last laser line yielded
        self._peek = self._do_peek()

    # -- first, short pass ------------------------------------------------------------------
    def _do_peek(self) -> _Peek:
        peek = _Peek()
        values: list[np.ndarray] = []
        with open_text(self.path) as f:
            try:
                for line in f:
                    tok = line.split()
                    if not tok:
                        continue
                    if tok[0] == "ODOM":
                        peek.has_odom = True
                        try:
                            peek.odom_stamps.append(_parse_odom(tok).stamp)
                        except (ValueError, IndexError, OverflowError):
                            pass
                    elif tok[0] in LASER_KINDS:
                        try:
                            las = _parse_laser(tok)
                        except (ValueError, IndexError, OverflowError):
                            continue
                        peek.n_laser += 1
                        if las.kind != "RLASER":
                            peek.n_front += 1
                            peek.n_front_posed += las.odom_pose is not None
                        frame = FRAME_OF[las.kind]
                        if frame not in peek.mounts:
                            if las.laser_pose is not None and las.odom_pose is not None:
                                mount = between(las.odom_pose, las.laser_pose)
                                mount[np.abs(mount) < 1e-9] = 0.0  # float noise of equal poses
                                peek.mounts[frame] = mount
                            else:
                                peek.mounts[frame] = np.zeros(3)
                        if las.kind != "ROBOTLASER1":
                            values.append(las.ranges)
                        if peek.n_laser >= PEEK_LASER_LINES:
                            break
            except (OSError, EOFError, UnicodeError) as e:
                raise LogError(f"{self.path}: cannot read CARMEN log ({e})") from None
        if peek.n_laser == 0 and not peek.has_odom:
            raise LogError(f"{self.path}: no ODOM, FLASER, RLASER or ROBOTLASER1 lines (not a CARMEN log?)")
        if values:
            allv = np.concatenate(values)
            top = float(allv.max())
            if np.count_nonzero(allv == top) >= NO_RETURN_FRACTION * allv.size:
                peek.no_return_m = min(top, SICK_MAX_RANGE_M)
        if self.max_range_m is not None:
            peek.no_return_m = float(self.max_range_m)
        spacing = stamp_spacing(peek.odom_stamps)
        if (spacing is not None and spacing[0] < BURST_REGULAR * spacing[1]
                and peek.n_front > 0 and peek.n_front_posed == peek.n_front):
            peek.bursts = spacing
            log.warning("%s: ODOM stamps come in bursts (median spacing %.1f ms for a mean of %.1f ms over the "
                        "first %d ODOM lines): odometry taken from the poses the laser lines carry, the ODOM "
                        "lines not used",
                        self.path, 1e3 * spacing[0], 1e3 * spacing[1], len(peek.odom_stamps))
        return peek

    @property
    def laser_mounts(self) -> list[StaticTransform]:
        """``base_link -> laser`` (and ``-> rear_laser``) from the first laser line of each."""
        out = [StaticTransform("base_link", fr, p.copy()) for fr, p in self._peek.mounts.items()]
        return out or [StaticTransform("base_link", "laser", np.zeros(3))]

    # -- second, streaming pass -------------------------------------------------------------
    def _scan(self, las: _Laser) -> LaserScan:
        r = las.ranges
        if las.max_range is not None:
            rmax = float(las.max_range)
            if self.max_range_m is not None:
                rmax = min(rmax, float(self.max_range_m))
        else:
            rmax = self._peek.no_return_m
        with np.errstate(over="ignore", invalid="ignore"):  # 1e300 -> inf, at or beyond range_max anyway
            out = r.astype(np.float32)
        with np.errstate(invalid="ignore"):
            out[r >= rmax] = np.inf
            out[r <= 0.0] = np.nan
        return LaserScan(
            stamp=las.stamp,
            angle_min=las.angle_min,
            angle_increment=las.angle_increment,
            range_min=RANGE_MIN_M,
            range_max=rmax,
            ranges=out,
            frame_id=FRAME_OF[las.kind],
        )

    def __iter__(self) -> Iterator[tuple[str, object]]:
        counts: Counter[str] = Counter()
        skipped: Counter[str] = Counter()
        malformed: Counter[str] = Counter()
        bursts = self._peek.bursts
        odom_from_laser = not self._peek.has_odom or bursts is not None
        self.stats = {
            "counts": counts, "skipped": skipped, "malformed": malformed,
            "odom_from_laser": odom_from_laser, "no_return_m": self._peek.no_return_m,
        }
        if bursts is not None:
            self.stats["odom_bursts"] = {"median_spacing_s": bursts[0], "mean_spacing_s": bursts[1]}
        yield TF_STATIC_TOPIC, self.laser_mounts
        prev_odom: tuple[float, np.ndarray] | None = None
        lineno = 0
        with open_text(self.path) as f:
            try:
                for line in f:
                    lineno += 1
                    tok = line.split()
                    if not tok:
                        continue
                    kind = tok[0]
                    laser = kind in LASER_KINDS
                    if kind != "ODOM" and not laser:
                        skipped["#" if kind.startswith("#") else kind] += 1
                        continue
                    try:
                        rec = _parse_laser(tok) if laser else _parse_odom(tok)
                    except (ValueError, IndexError, OverflowError):
                        malformed[kind] += 1
                        continue
                    counts[kind] += 1
                    if not isinstance(rec, _Laser):
                        if bursts is None:
                            yield ODOM_TOPIC, rec
                        continue
                    las = rec
                    self.last_laser_pose = las.odom_pose  # the repair's evidence (CarmenSource)
                    carried = None
                    if odom_from_laser and las.odom_pose is not None and kind != "RLASER":
                        twist = las.twist
                        if twist is None:
                            twist = np.zeros(3)
                            if prev_odom is not None and las.stamp > prev_odom[0]:
                                twist = between(prev_odom[1], las.odom_pose) / (las.stamp - prev_odom[0])
                        prev_odom = (las.stamp, las.odom_pose)
                        counts["odom_from_laser"] += 1
                        # bursty ODOM: the odometry the scan was taken at, just before it
                        lead = 0.0 if bursts is None else CARRIED_LEAD_S
                        carried = Odometry(stamp=las.stamp - lead, twist=twist, pose=las.odom_pose.copy())
                    if carried is not None and bursts is not None:
                        yield ODOM_TOPIC, carried
                        carried = None
                    yield SCAN_TOPIC, self._scan(las)
                    if carried is not None:
                        yield ODOM_TOPIC, carried
            except (OSError, EOFError, UnicodeError) as e:
                log.warning("%s: read error after line %d (%s); stopping there", self.path, lineno, e)
                self.stats["read_error"] = f"after line {lineno}: {e}"
        unknown = {k: v for k, v in skipped.items() if k != "#" and k not in IGNORED_KINDS}
        if malformed or unknown:
            log.warning(
                "%s: skipped %d malformed line(s) %s and %d unknown line(s) %s",
                self.path, sum(malformed.values()), dict(malformed), sum(unknown.values()), unknown,
            )
        if skipped:
            log.info("%s: skipped lines by type %s", self.path, dict(skipped))


def _detour(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> float:
    """How much longer the path a -> b -> c is than a -> c (m, positions only)."""
    return (math.hypot(b[0] - a[0], b[1] - a[1]) + math.hypot(c[0] - b[0], c[1] - b[1])
            - math.hypot(c[0] - a[0], c[1] - a[1]))


#: how many lines back a stamp that went backwards is looked for among its topic's stamps
REPAIR_LOOKBACK = 1000


def _repair_backward_stamps(seq: list[tuple[int, float, np.ndarray | None]]) -> dict[int, float]:
    """``{message index: stamp}`` for the lines of one topic whose stamp is out of place while their
    pose fits the file order (see :class:`CarmenSource`); ``seq`` is ``(index, stamp, pose)`` in
    file order.  Where a stamp goes back (line ``j`` before line ``j - 1``), the one line out of
    place is ``j`` (stamped too early: the next line is again after ``j - 1``) or ``j - 1``
    (stamped too late: ``j`` is after ``j - 2``)."""
    out: dict[int, float] = {}
    stamps = [t for _, t, _ in seq]
    poses = [p for _, _, p in seq]
    n = len(seq)

    def by_stamp_detour(i: int) -> float | None:
        # the detour through line i's pose at its place by stamp (among lines within REPAIR_LOOKBACK)
        t = stamps[i]
        k = i - 1
        while k >= max(i - REPAIR_LOOKBACK, 0) and stamps[k] > t:
            k -= 1  # too early: after the last line before it stamped at or before it
        if k < i - 1:
            lo, hi = k, k + 1
        else:
            k = i + 1
            while k < min(i + REPAIR_LOOKBACK, n) and stamps[k] < t:
                k += 1  # too late: before the first line after it stamped at or after it
            lo, hi = k - 1, k
        if lo < 0 or hi >= n or lo == i or hi == i or poses[lo] is None or poses[hi] is None:
            return None
        return _detour(poses[lo], poses[i], poses[hi])  # type: ignore[arg-type]

    for j in range(1, n):
        if not stamps[j] < stamps[j - 1]:
            continue
        if j + 1 < n and stamps[j + 1] >= stamps[j - 1]:
            i = j                   # j stamped too early
        elif j >= 2 and stamps[j - 2] <= stamps[j]:
            i = j - 1               # j - 1 stamped too late
        else:
            continue
        if i < 1 or i + 1 >= n or poses[i - 1] is None or poses[i] is None or poses[i + 1] is None:
            continue
        other = by_stamp_detour(i)
        if other is not None and _detour(poses[i - 1], poses[i], poses[i + 1]) < other:  # type: ignore[arg-type]
            stamps[i] = 0.5 * (stamps[i - 1] + stamps[i + 1])  # between its file neighbours
            out[seq[i][0]] = stamps[i]
    return out


def iter_carmen(path: str | Path, max_range_m: float | None = None) -> Iterator[tuple[str, object]]:
    """``(topic, message)`` pairs of a CARMEN log, lazily; first ``("/tf_static", [mount])``.

    Raises :class:`LogError` (file missing, unreadable, or no CARMEN lines) before the first
    message; bad lines later are skipped and counted (see :class:`CarmenReader`).
    """
    return iter(CarmenReader(path, max_range_m=max_range_m))


def carmen_file_order(path: str | Path, max_range_m: float | None = None) -> list[tuple[str, object]]:
    """Every ``(topic, message)`` of a CARMEN log in *file* order, stamped as :class:`CarmenSource`
    (``open_log``, ``fgloc run``) stamps them: lines out of place in their topic whose poses fit
    the file order get the repaired stamp (see :class:`CarmenSource`), all others their own.  One
    pass over the file; for putting the stamps a localization run sees on scans read in file order
    (``fgloc.mapping.source.open_log_scan_stamps``)."""
    reader = CarmenReader(path, max_range_m=max_range_m)
    msgs: list[tuple[str, object]] = []
    streams: dict[str, list[tuple[int, float, np.ndarray | None]]] = {}
    for topic, msg in reader:
        if topic != TF_STATIC_TOPIC:
            pose = msg.pose if topic == ODOM_TOPIC else reader.last_laser_pose  # type: ignore[attr-defined]
            streams.setdefault(topic, []).append((len(msgs), float(msg.stamp), pose))  # type: ignore[attr-defined]
        msgs.append((topic, msg))
    for seq in streams.values():
        for i, t in _repair_backward_stamps(seq).items():
            msgs[i][1].stamp = t  # type: ignore[attr-defined]
    return msgs


class CarmenSource(LogSource):
    """A CARMEN log as a :class:`~fgloc.io.source.LogSource` (topics ``/scan``, ``/odom``,
    ``/tf_static``).

    Log time is each line's ipc timestamp (the ``/tf_static`` mount gets the first message's),
    and messages come in log-time order, ties in file order, as they read back from the MCAP
    that ``fgloc import`` writes: a first pass parses the file for the counts and stamps (real
    logs have stamps that jump backwards), the second yields the messages, holding back only
    those a later line's earlier stamp must precede.

    A line whose stamp goes back past the previous line of its topic while the next one does not
    (one stamp out of place) is judged by its odometry pose (ODOM's, or the laser line's): when the
    pose fits its place in the file (the detour through it from its file neighbours is shorter
    than from its neighbours by stamp), the file order is right and the stamp wrong: it is set
    halfway between its file neighbours' (clamping it to the previous one's made the localizer drop
    it as a repeated stamp), counted in ``repaired`` and ``skipped`` and warned about once.  Else
    (no pose, no motion, or the pose fits the stamp) it is sorted by its stamp as before.  Intel's
    ODOM lines: the poses fit the file position in 346 cases, the stamp in 0.
    """

    format = "carmen"

    def __init__(self, path: str | Path, topics: Topics | None = None, max_range_m: float | None = None) -> None:
        super().__init__(path, topics)
        self._reader = CarmenReader(self.path, max_range_m=max_range_m)
        keys: list[int] = []
        first: int | None = None
        streams: dict[str, list[tuple[int, float, np.ndarray | None]]] = {}  # topic -> (index, stamp, pose)
        for topic, msg in self._reader:
            if topic == TF_STATIC_TOPIC:
                keys.append(-1)
            else:
                keys.append(stamp_to_ns(msg.stamp))  # type: ignore[attr-defined]
                first = keys[-1] if first is None else first
                pose = msg.pose if topic == ODOM_TOPIC else self._reader.last_laser_pose  # type: ignore[attr-defined]
                streams.setdefault(topic, []).append((len(keys) - 1, float(msg.stamp), pose))  # type: ignore[attr-defined]
            info = self._topic_info.setdefault(topic, TopicInfo(TF_MESSAGE if topic == TF_STATIC_TOPIC else
                                                                LASER_SCAN if topic == SCAN_TOPIC else ODOMETRY))
            info.count += 1
        first_ns = 0 if first is None else first
        #: message index -> the repaired stamp (s); per topic, how many
        self.repaired: dict[str, int] = {}
        self._stamp_fix: dict[int, float] = {}
        for topic, seq in streams.items():
            fixed = _repair_backward_stamps(seq)
            for i, t in fixed.items():
                self._stamp_fix[i] = t
                keys[i] = stamp_to_ns(t)
            if fixed:
                self.repaired[topic] = len(fixed)
        self._keys = np.array([first_ns if k < 0 else k for k in keys], dtype=np.int64)
        self._n = len(keys)
        if self._n:
            self._start_ns, self._end_ns = int(self._keys.min()), int(self._keys.max())
        self._sorted = bool(np.all(np.diff(self._keys) >= 0))
        # the smallest key from message i on: what every message held back is compared with
        self._suffix_min = np.minimum.accumulate(self._keys[::-1])[::-1]
        st = self._reader.stats
        self.skipped = {**{f"malformed {k}": v for k, v in st.get("malformed", {}).items()},
                        **{k: v for k, v in st.get("skipped", {}).items() if k != "#" and k not in IGNORED_KINDS}}
        if st.get("read_error"):
            self.truncated = f"read error {st['read_error']}"
        for topic, n in self.repaired.items():
            self.skipped[f"backward stamps repaired {topic}"] = n
        if self.repaired:
            log.warning("%s: %s line(s) stamped before the previous one of their topic while their poses fit the "
                        "file order: stamped halfway between their file neighbours", self.path,
                        ", ".join(f"{n} {t}" for t, n in self.repaired.items()))

    def laser_mount(self) -> StaticTransform:
        frame = self.scan_frame()
        for m in self._reader.laser_mounts:
            if m.child == frame:
                return m
        return super().laser_mount()

    def _records(self, want: set[str]) -> Iterator[Record]:
        recs = self._records_in_order(want)
        if self._reader.stats.get("odom_bursts") is None:
            yield from recs
            return
        # odometry from the laser lines' poses (bursty ODOM stamps): the FLASER twist again, by finite
        # difference over the stamps yielded here (repaired, in log-time order) rather than the file's
        # raw ones, so that it integrates to the next pose over the stamps a consumer sees
        prev: tuple[float, np.ndarray] | None = None
        for rec in recs:
            msg = rec.msg
            if rec.topic == ODOM_TOPIC and isinstance(msg, Odometry) and msg.pose is not None:
                pose = np.asarray(msg.pose, dtype=float)
                msg.twist = np.zeros(3)
                if prev is not None and msg.stamp > prev[0]:
                    msg.twist = between(prev[1], pose) / (msg.stamp - prev[0])
                prev = (float(msg.stamp), pose)
            yield rec

    def _records_in_order(self, want: set[str]) -> Iterator[Record]:
        keys, suffix = self._keys.tolist(), self._suffix_min.tolist()
        n = len(keys)
        heap: list[tuple[int, int, Record]] = []
        for i, (topic, msg) in enumerate(self._reader):
            if i >= n:
                break
            if topic in want:
                fix = self._stamp_fix.get(i)
                if fix is not None:
                    msg.stamp = fix  # type: ignore[attr-defined]
                rec = Record(topic, msg, keys[i])
                if self._sorted:
                    yield rec
                    continue
                heapq.heappush(heap, (keys[i], i, rec))
            nxt = suffix[i + 1] if i + 1 < n else None
            while heap and (nxt is None or heap[0][0] <= nxt):
                yield heapq.heappop(heap)[2]
        while heap:
            yield heapq.heappop(heap)[2]
