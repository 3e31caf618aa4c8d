"""``fgloc live --ros2``: the localizer as a ROS 2 peer, a drop-in for nav2's AMCL.

:class:`Ros2Live` joins a DDS domain (:mod:`fgloc.ros2.transport`), subscribes to the robot's
scan, odometry / IMU / pose sources (the config's ``sources:``), ``/tf``, ``/tf_static``, the map
(nav2 map_server's ``/map``, unless ``--map FILE``) and ``/initialpose``, and runs the same
:class:`~fgloc.localization.Localizer` and :class:`~fgloc.localization.Session` as ``fgloc run``
through the live runner (:class:`fgloc.live.app.LiveSession`: its queue, reorder buffer, sensor
health, recording, UDP publisher and Foxglove view).  It publishes what nav2's AMCL publishes:

* ``/amcl_pose`` (``geometry_msgs/PoseWithCovarianceStamped``, reliable, transient local, depth 1)
  for each localized scan, stamped with the scan (as AMCL), in ``global_frame_id``: the back-end's
  online estimate there, published as soon as it has it (:class:`Ros2Outputs`);
* ``map -> odom`` on ``/tf`` (tf2's broadcaster QoS), right after each scan's match (``tf_at_match``,
  as AMCL after its update; else with the online estimate), stamped ``transform_tolerance_s`` after
  the scan (AMCL's post-dating, so that tf users may extrapolate that far);
  ``odom -> base`` at the pose's stamp comes from the robot's ``/tf`` (nav2's way) or, when the
  robot does not publish it, from its odometry messages' poses;
* ``/fgloc/status`` (``diagnostic_msgs/DiagnosticArray``, one status per input and output topic,
  one for the pose): what each topic received and every DDS problem, named.

Start-up: messages are kept (``startup_buffer_s``) until the map and the laser mount are known
(the mount: the config's ``sources.static_transforms``, else the tf chain from the robot to the
scan's frame, else after ``mount_wait_s`` the robot centre, said); then the localizer is built and
the kept messages are fused first, in their order, so nothing before the start is lost.  A new map
after the start (a map server republishing another one) is localized on from the next scan once its
front-end is built, the pose re-initialized where it was (``first_map_only``: as nav2's AMCL).

Never blocks, never dies: DDS hands the bytes to a receive thread that decodes them (an
undecodable message is counted on its topic) and queues them; the fusion loop is the caller's; a
reliable subscriber that stalls costs at most a few milliseconds per write, then the sample is
dropped and counted (:data:`fgloc.ros2.qos.MAX_BLOCKING_S`); a publisher of another type or with
a QoS that cannot match, a publisher that vanishes and returns, are counted and named on the
status line and on ``/fgloc/status``.
"""

from __future__ import annotations

import bisect
import heapq
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fgloc.frames.tf import TfTree, frame_name, is_base_frame, mount_of, planar_mount
from fgloc.geometry import compose, inverse, wrap_scalar
from fgloc.io.ros import mirror_scan
from fgloc.io.topics import IMU, LASER_SCAN, ODOMETRY, POSE_COV_STAMPED, TF_MESSAGE
from fgloc.localization.session import BaseSink
from fgloc.quantiles import LogHistogram
from fgloc.ros2 import codec, qos
from fgloc.ros2.codec import DIAGNOSTIC_ARRAY, OCCUPANCY_GRID, Undecodable
from fgloc.ros2.transport import EndpointHealth, Transport
from fgloc.types import LaserScan, Odometry, PoseFix, StaticTransform

SENSOR_TYPES = (LASER_SCAN, ODOMETRY, IMU)
SOURCE_TYPES = {"odometry": ODOMETRY, "imu": IMU, "pose": POSE_COV_STAMPED}
OK, WARN, ERROR, STALE = 0, 1, 2, 3  # diagnostic_msgs/DiagnosticStatus levels
#: a transform at the match is followed, once the back-end's estimate at the scan is made, by that one stamped
#: this much later: tf2 drops a second transform with the same stamp, and a lookup of the latest gets this one
REFINED_AFTER_S = 1e-6
ODOM_HISTORY = 4000  # odom -> base poses kept (80 s of a 50 Hz odometry)
ARRIVALS_KEPT = 256  # messages per source whose arrival is kept (2.5 s of a 100 Hz IMU)
SLOWEST_KEPT = 64  # the slowest scans whose latency is reported part by part
SENSOR_DEPTH = 100  # samples a sensor subscription holds until the receive thread takes them


class GcClock:
    """The time this process's cyclic garbage collector has run (every pass, by a ``gc.callbacks`` hook
    installed once): a scan's share of it between two moments is :meth:`total_s`'s difference."""

    _installed: GcClock | None = None

    def __init__(self) -> None:
        self.total_s = 0.0
        self.passes = [0, 0, 0]
        self.longest_ms = [0.0, 0.0, 0.0]
        self._t0 = 0.0

    def _hook(self, phase: str, info: dict[str, Any]) -> None:
        if phase == "start":
            self._t0 = time.perf_counter()
            return
        dt = time.perf_counter() - self._t0
        self.total_s += dt
        g = int(info.get("generation", 0))
        self.passes[g] += 1
        self.longest_ms[g] = max(self.longest_ms[g], dt * 1e3)

    @classmethod
    def get(cls) -> GcClock:
        if cls._installed is None:
            import gc

            cls._installed = cls()
            gc.callbacks.append(cls._installed._hook)
        return cls._installed


class OdomFrame:
    """The robot's ``odom -> base`` pose over time: from ``/tf`` when the robot publishes it there
    (the ``odom_frame_id`` parent to one of its base frames), else from its odometry's poses."""

    def __init__(self, odom_frame: str = "odom") -> None:
        self.odom_frame = frame_name(odom_frame)
        self.from_tf = False
        self.base_frame = ""
        self._t: list[float] = []  # sorted; the newest ODOM_HISTORY to 2 ODOM_HISTORY kept (trimmed in one go)
        self._p: list[np.ndarray] = []
        self._lock = threading.Lock()

    def _add(self, t: float, pose: np.ndarray) -> None:
        with self._lock:
            if self._t and t < self._t[-1]:
                return  # out of order: the history stays sorted
            self._t.append(t)
            self._p.append(np.asarray(pose, dtype=float).copy())
            if len(self._t) > 2 * ODOM_HISTORY:
                del self._t[:-ODOM_HISTORY], self._p[:-ODOM_HISTORY]

    def add_tf(self, transforms: list[StaticTransform], stamps: list[float]) -> None:
        for tr, stamp in zip(transforms, stamps, strict=True):
            if frame_name(tr.parent) == self.odom_frame and is_base_frame(tr.child):
                if not self.from_tf:
                    with self._lock:
                        self._t.clear()
                        self._p.clear()
                    self.from_tf = True
                    self.base_frame = frame_name(tr.child)
                self._add(float(stamp), tr.pose)

    def add_odometry(self, msg: Odometry) -> None:
        if self.from_tf or msg.pose is None or frame_name(msg.frame_id) != self.odom_frame:
            return
        self.base_frame = frame_name(msg.child_frame_id)
        self._add(float(msg.stamp), msg.pose)

    def at(self, t: float, max_gap_s: float = 0.2) -> np.ndarray | None:
        """The pose at ``t``: interpolated (linear in x, y; the shortest arc in yaw) between the two
        poses around it; after the newest one (a scan stamped after the last odometry that came)
        extrapolated at the last two poses' velocity, at most ``max_gap_s``; None without."""
        with self._lock:
            if not self._t:
                return None
            ts = self._t
            if t >= ts[-1] or t <= ts[0]:
                last = t >= ts[-1]
                if abs(t - (ts[-1] if last else ts[0])) > max_gap_s:
                    return None
                if len(ts) < 2:
                    return self._p[-1].copy()
                k = len(ts) - 1 if last else 1
            else:
                k = bisect.bisect_left(ts, t)
            t0, t1 = ts[k - 1], ts[k]
            p0, p1 = self._p[k - 1], self._p[k]
        a = 0.0 if t1 <= t0 else (t - t0) / (t1 - t0)
        return np.array([p0[0] + a * (p1[0] - p0[0]), p0[1] + a * (p1[1] - p0[1]),
                         wrap_scalar(float(p0[2]) + a * wrap_scalar(float(p1[2] - p0[2])))])


class Arrivals:
    """When each odometry / IMU source's recent messages arrived, by stamp: the moment the inputs a scan's
    pose waits for (each source past the scan's stamp: the back-end's keyframe needs them) were all in."""

    def __init__(self, keep: int = ARRIVALS_KEPT) -> None:
        self.keep = keep
        self._by: dict[str, deque[tuple[float, float]]] = {}
        self._lock = threading.Lock()

    def add(self, kind: str, stamp: float, arrival: float) -> None:
        with self._lock:
            d = self._by.get(kind)
            if d is None:
                d = self._by[kind] = deque(maxlen=self.keep)
            if math.isfinite(stamp) and (not d or stamp >= d[-1][0]):
                d.append((stamp, arrival))

    def all_in(self, t: float) -> float | None:
        """The latest arrival among each source's first message stamped at or after ``t`` (a source with
        none yet is not waited for: None when no source has one)."""
        out = None
        with self._lock:
            for d in self._by.values():
                first = None
                for stamp, arrival in reversed(d):
                    if stamp < t:
                        break
                    first = arrival
                if first is not None:
                    out = first if out is None else max(out, first)
        return out


def map_to_odom(map_base: np.ndarray, odom_base: np.ndarray) -> np.ndarray:
    """``map -> odom`` so that ``map -> odom -> base`` is the fused pose: ``T_mb T_ob^-1``."""
    return compose(map_base, inverse(odom_base))


def pose_at_match(pred: np.ndarray, pred_cov: np.ndarray, fix: PoseFix | None) -> np.ndarray:
    """The pose at a scan right after its match: the back-end's prediction there updated with the scan's
    fix (one Kalman update, the fix's covariance as it is), or the prediction without a fix taken.  What
    a filter (nav2's AMCL) publishes at once; a smoother's own estimate there comes once its keyframe is
    made (the odometry / IMU past the scan), a few millimetres from this."""
    pred = np.asarray(pred, dtype=float)
    if fix is None or fix.cov is None:
        return pred.copy()
    p = np.asarray(pred_cov, dtype=float)
    try:
        k = p @ np.linalg.inv(p + np.asarray(fix.cov, dtype=float))
    except np.linalg.LinAlgError:
        return pred.copy()
    d = np.asarray(fix.pose, dtype=float) - pred
    d[2] = wrap_scalar(float(d[2]))
    out = pred + k @ d
    out[2] = wrap_scalar(float(out[2]))
    return out


class Ros2Outputs(BaseSink):
    """Publishes /amcl_pose and map -> odom for each scan, and measures scan arrival (DDS) -> published.

    /amcl_pose carries the back-end's online estimate at the scan's stamp (what ``fgloc run`` writes to
    online.tum), published as soon as the back-end has it: a smoother makes a scan's keyframe once the
    odometry / IMU reach its stamp, so :meth:`publish_new` is called after every message the session
    handles.  map -> odom goes out with it, or, with ``ros2.tf_at_match`` (the default), right after the
    scan's match from :func:`pose_at_match` (as nav2's AMCL publishes it after its update), not waiting for
    the odometry / IMU past the scan, and again from the online estimate once the back-end has it, stamped
    :data:`REFINED_AFTER_S` later (tf2 drops a second transform with the same stamp).  ``odom -> base`` at
    the scan's stamp comes from the robot (interpolated, or extrapolated when
    the scan is newer than its newest odometry, :class:`OdomFrame`).

    Per scan fused live, the whole run's percentiles in constant memory (:class:`LogHistogram`):
    ``tf_ms`` arrival -> map->odom published; ``pose_ms`` arrival -> /amcl_pose published; ``ready_ms``
    from the moment the odometry / IMU past the scan's stamp were in as well -> /amcl_pose (fgloc's share
    of it: the rest is the wait for the robot's sensors); for the transform at the match, ``queue_ms``
    arrival -> the scan's handling began (the receive thread, the fusion loop's wake-up, the messages
    before it), ``handle_ms`` that -> published, and ``cpu_ms`` the fusion thread's own CPU time in it
    (the rest of ``handle_ms`` the thread waited for a core or the GIL: the machine's share);
    ``match_vs_online_mm`` the transform at the match against the one from the online estimate."""

    wants_messages = False
    wants_fused = False

    def __init__(self, live: Ros2Live) -> None:
        self.live = live
        c = live.cfg.ros2
        tr = live.transport
        self.pose_pub = tr.publisher(c.pose_topic, POSE_COV_STAMPED, qos.LATCHED_PUB)
        self.tf_pub = tr.publisher("/tf", TF_MESSAGE, qos.TF) if c.tf_broadcast else None
        self.at_match = bool(c.tf_at_match) and self.tf_pub is not None
        self.tf_ms = LogHistogram()
        self.pose_ms = LogHistogram()
        self.ready_ms = LogHistogram()
        self.queue_ms = LogHistogram()
        self.handle_ms = LogHistogram()
        self.cpu_ms = LogHistogram()
        self.match_vs_online_mm = LogHistogram(lo=1e-4)
        #: the slowest scans' map->odom at the match (a min-heap of SLOWEST_KEPT): what their time was made of
        self.slowest: list[tuple[float, int, dict[str, float]]] = []
        self._n_live = 0
        #: arrival -> the session's fused pose made (its marginal covariance every second): when map->odom went
        #: out while the session computed the fused pose before telling any sink; measured on the same scans
        self.fused_ms = LogHistogram()
        self._awaiting_fused: float | None = None  # the live scan whose transform went out before its fused pose
        self.published = 0
        self.tf_published = 0
        self.tf_refined = 0
        self.no_odom = 0
        self.last_map_odom: np.ndarray | None = None
        self._last_t = -math.inf  # the newest stamp /amcl_pose was published for
        self._tf_last_t = -math.inf  # ... map -> odom
        self._arrivals: deque[tuple[float, float, bool]] = deque(maxlen=64)  # scan stamp, arrival, live
        self._early: deque[tuple[float, np.ndarray]] = deque(maxlen=64)  # stamp, map -> base at the match
        #: per live scan given a pose: a map -> odom at its stamp written before the pose (``tf_first``) or not
        #: (``no_tf``: no odometry at its stamp, or lost); ``tf_after``: transforms at the match written for a
        #: stamp whose pose was already out
        self.order = {"tf_first": 0, "no_tf": 0, "tf_after": 0}
        self.handling: tuple[float, float] | None = None  # wall (time.time), thread CPU s: the scan's handling began

    def on_scan(self, stamp: float, scan: LaserScan, fix_or_reason: PoseFix | str, fused: PoseFix | None) -> None:
        r = self.live.runner
        arrival = r.scan_arrival if r is not None else 0.0
        live = arrival > 0 and not self.live.flushing
        t = float(stamp)
        self._arrivals.append((t, arrival, live))
        self.publish_new()
        loc = self.live.loc
        if (not self.at_match or loc is None or loc.odom_mode or loc.lost or t <= self._tf_last_t
                or not loc.backend.initialized):
            return
        fix = fix_or_reason if isinstance(fix_or_reason, PoseFix) and not loc.last_reason else None
        pred, pred_cov = loc.backend.predict(t)
        at = pose_at_match(pred, pred_cov, fix)
        if self._publish_tf(t, at):
            self._early.append((t, at))
            if t <= self._last_t:
                self.order["tf_after"] += 1
            if live:
                now = time.time()
                ms = (now - arrival) * 1e3
                self.tf_ms.add(ms)
                self._awaiting_fused = arrival
                if self.handling is not None:
                    began, cpu0 = self.handling
                    parts = {"queue_ms": (began - arrival) * 1e3, "handle_ms": (now - began) * 1e3,
                             "cpu_ms": (time.thread_time() - cpu0) * 1e3}
                    self.queue_ms.add(parts["queue_ms"])
                    self.handle_ms.add(parts["handle_ms"])
                    self.cpu_ms.add(parts["cpu_ms"])
                    self._keep_slow(ms, arrival, parts)

    def fused_made(self) -> None:
        """The session's fused pose for the scan was just computed (:class:`_AfterFused`)."""
        if self._awaiting_fused is not None:
            self.fused_ms.add((time.time() - self._awaiting_fused) * 1e3)
            self._awaiting_fused = None

    def _keep_slow(self, ms: float, arrival: float, parts: dict[str, float]) -> None:
        """Keep the scan among the :data:`SLOWEST_KEPT` slowest, with its process CPU and GC time since its
        arrival (the rest of its wall time no thread of this process ran: the machine's)."""
        self._n_live += 1
        if len(self.slowest) >= SLOWEST_KEPT and ms <= self.slowest[0][0]:
            return
        clocks = self.live.scan_clocks.get(arrival)
        if clocks is not None:
            cpu0, gc0 = clocks
            parts["process_cpu_ms"] = (time.process_time() - cpu0) * 1e3
            parts["gc_ms"] = (GcClock.get().total_s - gc0) * 1e3
        parts["since_start_s"] = arrival - self.live.started_at
        parts["tf_ms"] = ms
        item = (ms, self._n_live, parts)
        if len(self.slowest) < SLOWEST_KEPT:
            heapq.heappush(self.slowest, item)
        else:
            heapq.heapreplace(self.slowest, item)

    def _publish_tf(self, t: float, map_base: np.ndarray, after_s: float = 0.0) -> bool:
        assert self.tf_pub is not None
        odom = self.live.odom_frame.at(t)
        if odom is None:
            self.no_odom += 1
            return False
        mo = map_to_odom(map_base, odom)
        self.last_map_odom = mo
        c = self.live.cfg.ros2
        tf = StaticTransform(c.global_frame_id, c.odom_frame_id, mo)
        self.tf_pub.write(codec.encode([tf], t + c.transform_tolerance_s + after_s)[1])
        self._tf_last_t = t
        self.tf_published += 1
        return True

    def publish_new(self) -> None:
        loc = self.live.loc
        if loc is None or loc.odom_mode:
            return
        new = loc.backend.online_after(self._last_t)
        if not new:
            return
        c = self.live.cfg.ros2
        for t, pose_at, cov in new:
            self._last_t = t
            at = np.asarray(pose_at, dtype=float)
            # map -> odom before the pose (as at the match): a consumer of the pose finds the transform there
            tf_now = self.tf_pub is not None and t > self._tf_last_t and self._publish_tf(t, at)
            early = next((e for st, e in self._early if abs(st - t) < 1e-9), None)  # the one out at its match
            tf_before = tf_now or early is not None
            self.pose_pub.write(codec.encode(PoseFix(t, at, cov, 1.0, "fgloc", c.global_frame_id))[1])
            self.published += 1
            if early is not None:
                self.match_vs_online_mm.add(1e3 * math.hypot(early[0] - at[0], early[1] - at[1]))
                if self.tf_pub is not None and t == self._tf_last_t and self._publish_tf(t, at, REFINED_AFTER_S):
                    self.tf_refined += 1
            for st, arrival, live in self._arrivals:
                if abs(st - t) < 1e-9:
                    if live:  # a scan kept from before the start is not live
                        self.order["tf_first" if tf_before else "no_tf"] += 1
                        now = time.time()
                        ms = (now - arrival) * 1e3
                        self.pose_ms.add(ms)
                        if tf_now:
                            self.tf_ms.add(ms)
                        inputs_in = self.live.arrivals.all_in(t)
                        self.ready_ms.add((now - max(arrival, inputs_in or arrival)) * 1e3)
                    break

    def latency_percentiles(self, ready: bool = False) -> tuple[float, float]:
        """p50, p99 of scan arrival -> map->odom published (``ready``: inputs in -> /amcl_pose), ms."""
        lat = self.ready_ms if ready else self.tf_ms
        return lat.percentile(50), lat.percentile(99)

    def report(self) -> dict[str, Any]:
        def pct(h: LogHistogram, nd: int = 3) -> dict[str, float]:
            return {"p50": round(h.percentile(50), nd), "p99": round(h.percentile(99), nd), "n": h.count}

        return {"published": self.published, "tf_published": self.tf_published, "tf_refined": self.tf_refined,
                "tf_at_match": self.at_match,
                "scan_to_tf_ms": pct(self.tf_ms), "scan_to_pose_ms": pct(self.pose_ms),
                "scan_to_fused_ms": pct(self.fused_ms),
                "inputs_in_to_pose_ms": pct(self.ready_ms), "tf_before_pose": dict(self.order),
                "tf_at_match_ms": {"queue": pct(self.queue_ms), "handle": pct(self.handle_ms),
                                   "cpu": pct(self.cpu_ms)},
                "tf_at_match_slowest": [{k: round(v, 3) for k, v in parts.items()}
                                        for _, _, parts in sorted(self.slowest, reverse=True)],
                "gc": {"passes": GcClock.get().passes, "total_ms": round(GcClock.get().total_s * 1e3, 1),
                       "longest_ms": [round(v, 2) for v in GcClock.get().longest_ms]},
                "tf_at_match_vs_online_mm": {**pct(self.match_vs_online_mm), "max": round(
                    self.match_vs_online_mm.max, 3) if self.match_vs_online_mm.count else math.nan}}


class _AfterFused(BaseSink):
    """Right after :class:`Ros2Outputs`: tells it when the session's fused pose is made (the session computes it
    for the first sink that wants it, after the transform went out)."""

    wants_messages = False

    def __init__(self, outputs: Ros2Outputs) -> None:
        self.outputs = outputs

    def on_scan(self, stamp: float, scan: LaserScan, fix_or_reason: PoseFix | str, fused: PoseFix | None) -> None:
        self.outputs.fused_made()


@dataclass
class _Input:
    topic: str
    type_name: str
    kind: str  # the session kind it is dispatched as ("scan", "source:NAME", "tf", "initialpose", "map")
    health: EndpointHealth | None = None


@dataclass
class StartupState:
    buffered: deque[tuple[str, Any, float]] = field(default_factory=deque)
    dropped: int = 0
    scan_frame: str | None = None
    first_scan: LaserScan | None = None
    first_scan_at: float | None = None
    waiting_for: str = ""


class Ros2Live:
    """fgloc on a ROS 2 graph (see the module docstring).

    ``occ_map``: the map (``--map FILE``) or None to take it from ``ros2.map_topic``;
    ``make_session(map, laser_mount) -> Session`` builds the localization session
    (:func:`fgloc.localization.build_session`) once the map and the mount are known;
    ``make_live(session) -> LiveSession`` wraps it for live use (recording, UDP publishing, view:
    the caller's options)."""

    def __init__(self, cfg: Any, transport: Transport, make_session: Callable[[Any, StaticTransform], Any],
                 make_live: Callable[[Any], Any], occ_map: Any = None,
                 event: Callable[[str], None] | None = None, on_started: Callable[[], None] | None = None) -> None:
        from fgloc.localization.sources import parse_sources

        self.cfg = cfg
        self.transport = transport
        self.make_session = make_session
        self.make_live = make_live
        self.occ_map = occ_map
        self.event = event or (lambda s: None)
        self.on_started = on_started
        self.odom_frame = OdomFrame(cfg.ros2.odom_frame_id)
        self.arrivals = Arrivals()
        #: each recent scan's arrival -> (process CPU s, GC s) then (its slowest-scan breakdown)
        self.scan_clocks: dict[float, tuple[float, float]] = {}
        self._gc = GcClock.get()
        self.started_at = time.time()
        self.tf = TfTree()
        self.session: Any = None  # LiveSession once started
        self.runner: Any = None
        self.loc: Any = None
        self.outputs: Ros2Outputs | None = None
        self.mirrored = False
        self.startup = StartupState()
        self._lock = threading.Lock()
        self.maps_ignored = 0  # maps after the first with first_map_only
        self.map_changes = 0  # new maps localized on
        self.map_errors = 0  # new maps no front-end could be built on
        self._pending_map: tuple[Any, Any] | None = None  # a new map and its front-end, for the next scan
        self.flushing = False  # fusing the messages kept from before the start
        self.initial_pose: PoseFix | None = None
        self._pending_pose: PoseFix | None = None  # an /initialpose to apply at the next scan
        c = cfg.ros2
        # ROS 2's sensor-data QoS; the depth is the reader's own (not matched against the publisher): deep
        # enough that a pause of the fusion loop (a slow scan match) loses no odometry
        sensor = (qos.SENSOR_DATA if c.sensor_reliability == "best_effort" else qos.DEFAULT).with_depth(SENSOR_DEPTH)
        self.scan_topic = c.scan_topic
        self.inputs: list[_Input] = [_Input(c.scan_topic, LASER_SCAN, "scan")]
        specs = parse_sources(cfg.sources, {"odom": "/odom", "imu": "/imu"})
        for s in specs:
            self.inputs.append(_Input(s.topic, SOURCE_TYPES[s.type], f"source:{s.name}"))
        self.inputs += [_Input("/tf", TF_MESSAGE, "tf"), _Input("/tf_static", TF_MESSAGE, "tf"),
                        _Input(c.initial_pose_topic, POSE_COV_STAMPED, "initialpose")]
        if occ_map is None:
            self.inputs.append(_Input(c.map_topic, OCCUPANCY_GRID, "map"))
        profiles = {"tf": qos.TF, "initialpose": qos.INITIAL_POSE_SUB, "map": qos.MAP_SUB}
        for inp in self.inputs:
            prof = qos.TF_STATIC_SUB if inp.topic == "/tf_static" else profiles.get(inp.kind, sensor)
            inp.health = transport.subscribe(inp.topic, inp.type_name, prof, self._handler(inp))
        self.status_pub = transport.publisher(c.status_topic, DIAGNOSTIC_ARRAY, qos.DEFAULT)
        self._last_status = 0.0
        self._t0 = time.monotonic()

    # ---------------------------------------------------------------- receive (DDS thread)
    def _handler(self, inp: _Input) -> Callable[[bytes, float], None]:
        return lambda data, arrival: self._receive(inp, data, arrival)

    def _receive(self, inp: _Input, data: bytes, arrival: float) -> None:
        assert inp.health is not None
        try:
            if inp.type_name == TF_MESSAGE:
                msg: Any = codec.decode_tf(data)
            else:
                msg = codec.decode(inp.type_name, data, inp.topic)
        except Undecodable as e:
            inp.health.undecodable += 1
            inp.health.last_error = str(e)[:80]
            return
        if inp.kind == "tf":
            tfs, flips, stamps = msg
            self.odom_frame.add_tf(tfs, stamps)
            with self._lock:
                self.tf.add(tfs, flips)
            if inp.topic != "/tf_static":
                return  # /tf: the odometry frame and the mount lookup; the session takes the static mounts
            msg = tfs
        elif inp.kind.startswith("source:"):
            self.arrivals.add(inp.kind, float(getattr(msg, "stamp", math.nan)), arrival)
            if isinstance(msg, Odometry):
                self.odom_frame.add_odometry(msg)
        elif inp.kind == "scan" and isinstance(msg, LaserScan):
            clocks = self.scan_clocks
            clocks[arrival] = (time.process_time(), self._gc.total_s)
            if len(clocks) > 2 * ARRIVALS_KEPT:  # the oldest half dropped (insertion order)
                for k in list(clocks)[:ARRIVALS_KEPT]:
                    del clocks[k]
            if self.startup.scan_frame is None:
                self.startup.scan_frame = msg.frame_id
                self.startup.first_scan = msg
                self.startup.first_scan_at = time.monotonic()
            if self.mirrored:
                msg = mirror_scan(msg)
        if inp.kind == "map":
            self._map(msg)
            return
        if inp.kind == "initialpose":
            if isinstance(msg, PoseFix):
                self.initial_pose = msg
        with self._lock:
            if self.runner is None:
                self._keep(inp.kind, msg, arrival)
                return
        self.runner.push(inp.kind, msg, arrival)

    def _keep(self, kind: str, msg: Any, arrival: float) -> None:
        b = self.startup.buffered
        b.append((kind, msg, arrival))
        horizon = arrival - self.cfg.ros2.startup_buffer_s
        while b and b[0][2] < horizon:
            b.popleft()
            self.startup.dropped += 1

    def _map(self, m: Any) -> None:
        """A map on ``map_topic`` (DDS thread).  Before the start the newest is kept; after it a new map
        gets its front-end built on a thread of its own (seconds on a large map: the scans go on) and is
        localized on from the next scan after that (:meth:`_apply_map`; as nav2's AMCL, whose map callback
        replaces the map for the scans still queued).  The same map again (a map server republishing, a
        second one) changes nothing; with ``first_map_only`` only the first counts."""
        c = self.cfg.ros2
        with self._lock:
            cur = self.occ_map
            if cur is not None and c.first_map_only:
                if not (m.data.shape == cur.data.shape and m.equals(cur)):
                    self.maps_ignored += 1
                return
            if cur is not None and m.data.shape == cur.data.shape and m.equals(cur):
                return
            self.occ_map = m
            started = self.loc is not None
        if cur is None:
            self.event(f"map from {c.map_topic}: {m.width} x {m.height} cells of {m.resolution:g} m")
        elif started:
            self._build_frontend(m)

    def _build_frontend(self, m: Any) -> None:
        loc = self.loc

        def build() -> None:
            from fgloc.frontends import make_frontend

            try:
                fe = make_frontend(loc.frontend_name, m, loc.laser_mount, self.cfg)
            except Exception as e:  # noqa: BLE001 - a map no front-end takes is counted, said, not used
                self.map_errors += 1
                self.event(f"a new map on {self.cfg.ros2.map_topic} not used: {type(e).__name__}: {e}")
                return
            with self._lock:
                if self.occ_map is m:  # not replaced meanwhile by a newer one
                    self._pending_map = (m, fe)

        threading.Thread(target=build, name="fgloc-map", daemon=True).start()

    def _apply_map(self, t_scan: float) -> None:
        """Localize on the pending new map from the scan at ``t_scan`` on: a pose being tracked is
        re-initialized where the back-end has it (matched on the new map from there, as after
        /initialpose: a map moved against the old one moves the pose with it); lost, the global search
        goes on on the new map."""
        with self._lock:
            pending, self._pending_map = self._pending_map, None
        if pending is None:
            return
        m, fe = pending
        loc = self.loc
        loc.replace_map(m, fe)
        self.map_changes += 1
        how = "lost: searching it globally"
        if loc.backend.initialized and not loc.lost:
            pose = np.asarray(loc.guess(t_scan), dtype=float)
            loc.reinitialize(pose)
            how = f"re-initialized at {pose[0]:.2f} {pose[1]:.2f} {math.degrees(pose[2]):.1f} deg"
        self.event(f"a new map on {self.cfg.ros2.map_topic} ({m.width} x {m.height} cells of {m.resolution:g} m): "
                   f"localizing on it from the scan at {t_scan:.3f}, {how}")

    # ---------------------------------------------------------------- start-up (caller's thread)
    def _mount(self) -> tuple[StaticTransform, bool] | None:
        frame = self.startup.scan_frame
        if frame is None:
            return None
        from fgloc.frames.static import parse_static_transforms

        mine = mount_of(frame, parse_static_transforms(self.cfg.sources.static_transforms))
        if mine is not None:
            return planar_mount(mine, "sources.static_transforms")
        with self._lock:
            found = self.tf.chain(frame)
        if found is not None:
            return found
        waited = time.monotonic() - (self.startup.first_scan_at or time.monotonic())
        if waited >= self.cfg.ros2.mount_wait_s:
            self.event(f"no transform from the robot to the scan frame '{frame}' after "
                       f"{self.cfg.ros2.mount_wait_s:g} s: assuming the laser at the robot centre, upright")
            return StaticTransform("base_link", frame_name(frame), np.zeros(3)), False
        return None

    def try_start(self) -> bool:
        """Build the localizer and the session once the map and the mount are known."""
        if self.runner is not None:
            return True
        if self.occ_map is None:
            self.startup.waiting_for = f"the map on {self.cfg.ros2.map_topic}"
            return False
        if self.startup.scan_frame is None:
            self.startup.waiting_for = f"a scan on {self.scan_topic}"
            return False
        found = self._mount()
        if found is None:
            self.startup.waiting_for = f"a transform from the robot to '{self.startup.scan_frame}' (/tf_static)"
            return False
        mount, mirrored = found
        mount = StaticTransform(frame_name(mount.parent), frame_name(mount.child), mount.pose, mount.z)
        with self._lock:
            occ = self.occ_map
        loc_session = self.make_session(occ, mount)
        loc = loc_session.loc
        if self.initial_pose is not None and loc.initial_pose is None:
            loc.initial_pose = np.asarray(self.initial_pose.pose, dtype=float)
        session = self.make_live(loc_session)
        runner = session.runner
        runner.topics.update({inp.kind: inp.topic for inp in self.inputs})
        runner.reorder_s = self.cfg.ros2.reorder_s
        from fgloc.live.runner import SensorHealth

        runner.health = {inp.kind: SensorHealth(inp.topic) for inp in self.inputs
                         if inp.kind == "scan" or inp.kind.startswith("source:")}
        self.outputs = Ros2Outputs(self)
        # first: map -> odom goes out before the session's fused pose is made (its covariance is not free) and the
        # recording
        runner.session.sinks.insert(0, self.outputs)
        runner.session.sinks.insert(1, _AfterFused(self.outputs))
        outputs = self.outputs
        handlers = runner.session.handlers
        handlers["initialpose"] = self._on_initial_pose
        fuse_scan = handlers["scan"]

        def scan_then(msg: object) -> None:  # a new map, then a pending /initialpose, at the next scan
            outputs.handling = (time.time(), time.thread_time())
            if self._pending_map is not None and isinstance(msg, LaserScan):
                self._apply_map(float(msg.stamp))
            if self._pending_pose is not None and isinstance(msg, LaserScan):
                self._apply_initial_pose(float(msg.stamp))
            fuse_scan(msg)

        handlers["scan"] = scan_then

        def then_publish(handler: Callable[[object], None]) -> Callable[[object], None]:
            def handle(msg: object) -> None:  # a pose the back-end now knows is published at once
                handler(msg)
                outputs.publish_new()
            return handle

        for kind in list(handlers):
            if kind != "scan":  # the scans' sink publishes after each scan
                handlers[kind] = then_publish(handlers[kind])
        with self._lock:
            self.loc, self.session = loc, session
            newer = self.occ_map if self.occ_map is not occ else None
        if newer is not None:  # a map that came while the localizer was built on the one before
            self._build_frontend(newer)
        self._warm_up(loc, mount)
        with self._lock:
            self.mirrored = mirrored
        # the messages kept before the start, and those that come while they are fused, are fused in their
        # order, every scan (none is skipped as a backlog); once caught up, the receive thread queues into
        # the runner
        self.flushing = True
        kept = 0
        try:
            while True:
                with self._lock:
                    if not self.startup.buffered:
                        self.runner = runner
                        break
                    kind, msg, arrival = self.startup.buffered.popleft()
                if mirrored and kind == "scan" and isinstance(msg, LaserScan):
                    msg = mirror_scan(msg)
                runner.process(kind, msg, arrival)
                kept += 1
        finally:
            self.flushing = False
        self.startup.waiting_for = ""
        self.started_at = time.time()
        self.event(f"localizing: laser mount {mount.parent} -> {mount.child} "
                   f"({mount.pose[0]:.3f}, {mount.pose[1]:.3f}, {math.degrees(mount.pose[2]):.1f} deg)"
                   + (", upside down" if mirrored else "") + f"; {kept} messages kept from before the start fused")
        if self.on_started is not None:
            self.on_started()
        return True

    def _warm_up(self, loc: Any, mount: StaticTransform) -> None:
        """Match the first scan once with a throwaway front-end on the map: its compiled kernels are
        loaded now, not while the first live scans wait behind it (they would be skipped as a backlog)."""
        scan = self.startup.first_scan
        if scan is None or loc.frontend is None or loc.map is None:
            return
        from fgloc.frontends import make_frontend
        from fgloc.maps import OccupancyMap

        # a small room (the kernels are compiled per argument types, not per map): cheap on any map
        grid = np.zeros((200, 200), dtype=np.int16)
        grid[[0, -1], :] = grid[:, [0, -1]] = 100
        room = OccupancyMap(grid, 0.05, np.array([-5.0, -5.0, 0.0]))
        try:
            make_frontend(loc.frontend_name, room, mount, self.cfg).match(scan, np.zeros(3), None)
        except Exception:  # noqa: BLE001 - a warm-up only
            pass

    def _on_initial_pose(self, msg: object) -> None:
        if not isinstance(msg, PoseFix) or self.loc is None:
            return
        if frame_name(msg.frame_id) not in ("", frame_name(self.cfg.ros2.global_frame_id)):
            self.event(f"{self.cfg.ros2.initial_pose_topic} in frame '{msg.frame_id}', not "
                       f"'{self.cfg.ros2.global_frame_id}': ignored")
            return
        self._pending_pose = msg

    def _apply_initial_pose(self, t_scan: float) -> None:
        """Re-initialize at the pending /initialpose, moved by the robot's odometry from its stamp to the
        scan's (as AMCL does; a pose stamped 0, or older than the odometry kept, is taken as it is)."""
        msg, self._pending_pose = self._pending_pose, None
        assert msg is not None
        pose = np.asarray(msg.pose, dtype=float)
        moved = ""
        if msg.stamp > 0:
            o0, o1 = self.odom_frame.at(float(msg.stamp), max_gap_s=0.5), self.odom_frame.at(t_scan, max_gap_s=0.5)
            if o0 is not None and o1 is not None:
                pose = compose(pose, compose(inverse(o0), o1))
                moved = f", moved by the odometry over {t_scan - msg.stamp:.2f} s"
        cov = msg.cov if msg.cov is not None and np.all(np.diag(msg.cov) > 0) else None
        self.loc.reinitialize(pose, cov)
        x, y, yaw = pose
        self.event(f"{self.cfg.ros2.initial_pose_topic}: re-initialized at {x:.2f} {y:.2f} "
                   f"{math.degrees(yaw):.1f} deg{moved}")

    # ---------------------------------------------------------------- the loop
    def step(self) -> None:
        if self.runner is None:
            if not self.try_start():
                time.sleep(0.02)
        else:
            self.runner.step()
        self.tick()

    def run(self, stop: threading.Event, duration: float | None = None,
            until: Callable[[], bool] | None = None) -> None:
        t0 = time.monotonic()
        while not stop.is_set():
            self.step()
            if duration is not None and time.monotonic() - t0 >= duration:
                break
            if until is not None and until():
                break

    def tick(self, now: float | None = None) -> None:
        now = time.monotonic() if now is None else now
        if now - self._last_status >= self.cfg.ros2.status_period_s:
            self._last_status = now
            try:
                self.status_pub.write(codec.encode_generic(DIAGNOSTIC_ARRAY, self.diagnostics()))
            except Exception as e:  # noqa: BLE001 - the status never stops localization
                self.status_pub.health.last_error = f"{type(e).__name__}: {e}"
                self.status_pub.health.dropped += 1

    # ---------------------------------------------------------------- status
    def problems(self) -> list[str]:
        """``topic: problem`` for every DDS problem seen, one phrase each."""
        out = []
        for h in self.transport.health():
            out += [f"{h.topic} {p}" for p in h.problems()]
        if self.maps_ignored:
            out.append(f"{self.cfg.ros2.map_topic} {self.maps_ignored} new map(s) not used (first_map_only)")
        if self.map_errors:
            out.append(f"{self.cfg.ros2.map_topic} {self.map_errors} new map(s) unusable")
        if self.outputs is not None and self.outputs.no_odom:
            out.append(f"map->odom not published {self.outputs.no_odom}x (no odom->base pose at the scan's stamp)")
        return out

    def status_line(self) -> str:
        if self.runner is None:
            got = ", ".join(f"{inp.topic} {inp.health.messages}" for inp in self.inputs
                            if inp.health is not None and inp.health.messages)
            line = f"waiting for {self.startup.waiting_for or 'inputs'} | received: {got or 'nothing yet'}"
        else:
            r = self.runner
            now = time.monotonic()
            rates = " | ".join(f"{h.name} {h.rate_hz(now):4.1f}Hz" + {"ok": "", "waiting": "?", "silent": "!SILENT"}
                               [h.state] for h in r.health.values())
            p50, p99 = self.outputs.latency_percentiles() if self.outputs is not None else (math.nan, math.nan)
            pose = "pose --"
            if r.last_fix is not None:
                x, y, yaw = r.last_fix.pose
                pose = f"pose {x:7.2f} {y:7.2f} {math.degrees(yaw):6.1f}deg" + (" LOST" if self.loc.lost else "")
            line = (f"{rates} | scan->tf p50 {p50:4.1f} p99 {p99:4.1f} ms | {pose} | fixes {r.counters['fixes']} "
                    f"skip {r.counters['scans_skipped_backlog']}")
        probs = self.problems()
        return line + (" | DDS: " + "; ".join(probs) if probs else "")

    def diagnostics(self) -> dict:
        """The ``/fgloc/status`` message: one status per DDS endpoint and one for the pose."""
        from fgloc.io.ros import ros_header

        statuses = []
        now = time.time()
        for h in self.transport.health():
            probs = h.problems()
            stale = h.direction == "sub" and h.type in SENSOR_TYPES and h.messages > 0 and now - h.last_arrival > 2.0
            level = ERROR if (h.incompatible_qos or h.other_type) else WARN if probs else STALE if stale else OK
            values = {k: str(v) for k, v in h.as_dict().items() if k not in ("topic", "direction")}
            statuses.append({"level": level, "name": f"fgloc: {h.direction} {h.topic}",
                             "message": "; ".join(probs) or "ok", "hardware_id": h.topic,
                             "values": [{"key": k, "value": v} for k, v in values.items()]})
        statuses.append(self._pose_status())
        return {"header": ros_header(now, ""), "status": statuses}

    def _pose_status(self) -> dict:
        vals: dict[str, str] = {}
        if self.runner is None:
            level, msg = STALE, f"waiting for {self.startup.waiting_for or 'inputs'}"
        else:
            r, loc = self.runner, self.loc
            fix = r.last_fix
            if fix is None:
                level, msg = WARN, "no pose yet"
            elif loc.lost:
                level, msg = ERROR, "lost: searching globally"
            else:
                level, msg = OK, "tracking"
            if fix is not None:
                x, y, yaw = (float(v) for v in fix.pose)
                vals.update(x_m=f"{x:.4f}", y_m=f"{y:.4f}", yaw_deg=f"{math.degrees(yaw):.3f}",
                            stamp=f"{fix.stamp:.6f}")
                if fix.cov is not None:
                    vals["sigma_xy_m"] = f"{math.sqrt(max(fix.cov[0, 0], fix.cov[1, 1], 0.0)):.4f}"
            vals.update(fixes=str(r.counters["fixes"]), scans=str(r.counters["scans_fused"]),
                        scans_skipped_backlog=str(r.counters["scans_skipped_backlog"]),
                        localizer_errors=str(r.counters["localizer_errors"]))
            if self.outputs is not None:
                o = self.outputs
                p50, p99 = o.latency_percentiles()
                vals.update(scan_to_tf_p50_ms=f"{p50:.2f}", scan_to_tf_p99_ms=f"{p99:.2f}",
                            poses_published=str(o.published))
                if o.published:
                    vals["pose_published_stamp"] = f"{o._last_t:.6f}"
            router = getattr(r.session, "sources", None)
            if router is not None:
                from fgloc.localization.sources import status_line

                vals["sources"] = status_line(router.health())
        return {"level": level, "name": "fgloc: pose", "message": msg, "hardware_id": "fgloc",
                "values": [{"key": k, "value": v} for k, v in vals.items()]}

    def report(self) -> dict[str, Any]:
        """The DDS part of ``fgloc live``'s JSON summary."""
        out: dict[str, Any] = {"domain_id": self.transport.domain_id,
                               "endpoints": [h.as_dict() for h in self.transport.health()],
                               "problems": self.problems(), "startup_dropped": self.startup.dropped,
                               "map_changes": self.map_changes}
        if self.outputs is not None:
            out.update(self.outputs.report())
        return out

    def close(self) -> Any:
        """Stop receiving, close the session (fuses the backlog, closes the recording); its summary."""
        self.transport.close()
        if self.session is not None:
            return self.session.close()
        return None

