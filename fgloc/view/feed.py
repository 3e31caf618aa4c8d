"""What the view shows, taken from a running localizer: the sink interface and its feed.

:class:`ViewFeed` watches a :class:`fgloc.pipeline.Localizer` through the callbacks the
run loops already have (``on_message(topic, msg)`` before a message is fused,
``on_fused(fused, fix)`` after each scan) and hands each sink plain data:

* ``on_map(occ_map, stamp)`` once;
* ``on_scan(view)`` after each scan: the scan, the front-end result (accepted, rejected,
  no fix, ... with the reason), the fused pose and covariance, and the frame transforms
  ``map -> odom -> base_link -> laser`` at the fused pose's stamp;
* ``on_particles(stamp, frame_id, poses)`` after each scan when AMCL runs;
* ``on_trajectory(stamp, frame_id, poses)`` the fused trajectory so far (decimated),
  every second of log time or less often as it grows;
* ``on_health(stamp, health)`` once a second of log time: per-source rates and counts,
  gated fixes, the back-end's statistics and estimates (compass offset, ...);
* ``close()``.

The feed only reads the localizer's public state (``stats``, ``no_fix_reasons``,
``fixes``, ``backend.stats``, ``backend.compass_offset()``, AMCL's ``particles``) and
never calls anything that could change it: the poses are the same with or without a
view.  It is cheap (a few dict reads and one SE(2) step per message); sinks that do
real work (encoding, sockets) do it on their own thread (:mod:`fgloc.view.server`).

``odom -> base_link`` is the odometry's own pose when the messages carry one, else the
twist integrated as the localizer does; ``map -> odom = map->base (fused) (-) odom->base``
at the same stamp, as a ROS localizer publishes it.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from fgloc.geometry import compose, compose1, inverse
from fgloc.geometry import exp as se2_exp
from fgloc.types import LaserScan, Odometry, PoseFix, StaticTransform
from fgloc.view.channels import BASE_FRAME, MAP_FRAME, ODOM_FRAME

FloatArray = NDArray[np.float64]

# front-end result of one scan (ScanView.status)
ACCEPTED = "accepted"        # a fix the back-end used
REJECTED = "rejected"        # a fix the back-end gated out
NO_FIX = "no_fix"            # the front-end matched but gave no fix (reason: why)
PREDICTED = "predicted"      # not matched (every n-th scan is): the odometry prediction
SEARCHING = "searching"      # lost / not started: global localization found nothing yet
SKIPPED = "skipped"          # the localizer refused the scan (bad or repeated stamp)
ODOM_ONLY = "odom_only"      # no map: scans only place keyframes

ODOM_EXTRAPOLATE_MAX_S = 0.5  # carry the last odometry to a stamp at most this far
RATE_WINDOW_S = 2.0           # per-source rates over this much log time


@dataclass
class ScanView:
    """One scan as the view shows it."""

    stamp: float
    scan: LaserScan
    status: str
    reason: str
    fix: PoseFix | None                 # the front-end's fix (accepted or rejected), if any
    fused: PoseFix | None               # the fused pose after this scan (None before start)
    transforms: list[StaticTransform] = field(default_factory=list)  # parent -> child at fused.stamp


class ViewSink(Protocol):
    """What a view output implements (the WebSocket server, the MCAP recorder)."""

    def on_map(self, occ_map: Any, stamp: float) -> None: ...

    def on_scan(self, view: ScanView) -> None: ...

    def on_particles(self, stamp: float, frame_id: str, poses: FloatArray) -> None: ...

    def on_trajectory(self, stamp: float, frame_id: str, poses: FloatArray) -> None: ...

    def on_health(self, stamp: float, health: dict[str, Any]) -> None: ...

    def close(self) -> None: ...


class TrajectoryDecimator:
    """The fused trajectory so far, one pose per ``min_step_m`` / ``min_turn_rad`` / ``max_gap_s``.

    ``due(stamp)``: time to publish it again: ``period_s`` of log time after the last time,
    or longer as it grows (``len / poses_per_s``), so a long run's messages stay small in sum.
    """

    def __init__(self, min_step_m: float = 0.05, min_turn_rad: float = math.radians(2.0), max_gap_s: float = 1.0,
                 period_s: float = 1.0, poses_per_s: float = 200.0) -> None:
        self.min_step_m, self.min_turn_rad, self.max_gap_s = min_step_m, min_turn_rad, max_gap_s
        self.period_s, self.poses_per_s = period_s, poses_per_s
        self._stamps: list[float] = []
        self._poses: list[tuple[float, float, float]] = []
        self._last_pub = -math.inf

    def __len__(self) -> int:
        return len(self._poses)

    def add(self, stamp: float, pose: FloatArray) -> None:
        x, y, yaw = float(pose[0]), float(pose[1]), float(pose[2])
        if self._poses:
            lx, ly, lyaw = self._poses[-1]
            dyaw = abs(math.remainder(yaw - lyaw, 2.0 * math.pi))
            if math.hypot(x - lx, y - ly) < self.min_step_m and dyaw < self.min_turn_rad and \
                    stamp - self._stamps[-1] < self.max_gap_s:
                return
        self._stamps.append(float(stamp))
        self._poses.append((x, y, yaw))

    def due(self, stamp: float) -> bool:
        period = max(self.period_s, len(self._poses) / self.poses_per_s)
        if stamp - self._last_pub >= period:
            self._last_pub = stamp
            return True
        return False

    def poses(self) -> FloatArray:
        return np.asarray(self._poses, dtype=float).reshape(-1, 3)


class ViewFeed:
    """Turns localizer callbacks into sink calls (see the module docstring).

    ``topics`` names the scan / odometry / IMU topics (a :class:`fgloc.io.log.Topics` or
    anything with ``scan``, ``odom``, ``imu`` attributes; ROS defaults if None).
    """

    def __init__(self, loc: Any, sinks: Iterable[ViewSink], topics: Any = None, health_period_s: float = 1.0,
                 max_particles: int = 1000) -> None:
        self.loc = loc
        self.sinks: list[ViewSink] = list(sinks)
        self.scan_topic = getattr(topics, "scan", "/scan")
        self.odom_topic = getattr(topics, "odom", "/odom")
        self.imu_topic = getattr(topics, "imu", "/imu")
        self.health_period_s = float(health_period_s)
        self.max_particles = int(max_particles)
        self.mount: StaticTransform = loc.laser_mount
        self.odom_mode = bool(getattr(loc, "odom_mode", loc.map is None))
        self.frame = ODOM_FRAME if self.odom_mode else MAP_FRAME
        self.trajectory = TrajectoryDecimator()
        self.counts: dict[str, int] = {"scan": 0, "odom": 0, "imu": 0}
        self.status_counts: dict[str, int] = {}
        self._arrivals: dict[str, deque[float]] = {k: deque() for k in self.counts}
        self._pending: tuple[LaserScan, dict[str, Any]] | None = None
        self._odom_pose: FloatArray | None = None
        self._odom_t: float | None = None
        self._twist = np.zeros(3)
        self._last_health = -math.inf
        self._last_stamp = 0.0
        self._particles_id: int | None = None
        self._closed = False
        if loc.map is not None:
            for s in self.sinks:
                s.on_map(loc.map, 0.0)

    # ------------------------------------------------------------------ callbacks
    def on_message(self, topic: str, msg: object) -> None:
        """Every input message, before the localizer sees it."""
        if self._pending is not None:
            self._emit_scan(None, None)  # the previous scan gave no fused pose (not started)
        if topic == self.scan_topic and isinstance(msg, LaserScan):
            self._count("scan", msg.stamp)
            self._pending = (msg, self._snapshot())
        elif topic == self.odom_topic and isinstance(msg, Odometry):
            self._count("odom", msg.stamp)
            self._odometry(msg)
        elif topic == self.imu_topic:
            self._count("imu", getattr(msg, "stamp", math.nan))

    def on_fused(self, fused: PoseFix, fix: PoseFix | None = None) -> None:
        """After each scan, with the fused pose (``Localizer.current()``) and the scan's fix."""
        if self._pending is None:
            return
        self._emit_scan(fused, fix)

    def close(self) -> None:
        """Flush the last scan, send the final trajectory and health, close every sink."""
        if self._closed:
            return
        self._closed = True
        try:
            if self._pending is not None:
                self._emit_scan(None, None)
            if len(self.trajectory):
                for s in self.sinks:
                    s.on_trajectory(self._last_stamp, self.frame, self.trajectory.poses())
            health = self.health(self._last_stamp)
            for s in self.sinks:
                s.on_health(self._last_stamp, health)
        finally:
            for s in self.sinks:
                s.close()

    # ------------------------------------------------------------------ odometry
    def _odometry(self, msg: Odometry) -> None:
        t = float(msg.stamp)
        tw = np.asarray(msg.twist, dtype=float).reshape(-1)
        if not math.isfinite(t) or tw.shape != (3,) or not np.all(np.isfinite(tw)):
            return
        if self._odom_t is not None and t <= self._odom_t:
            return
        pose = None if msg.pose is None else np.asarray(msg.pose, dtype=float).reshape(-1)
        if pose is not None and pose.shape == (3,) and np.all(np.isfinite(pose)):
            self._odom_pose = pose.copy()
        elif self._odom_pose is None:
            self._odom_pose = np.zeros(3)
        elif self._odom_t is not None:
            self._odom_pose = compose1(self._odom_pose, se2_exp(tw * (t - self._odom_t)))
        self._odom_t = t
        self._twist = tw

    def odom_pose_at(self, t: float) -> FloatArray | None:
        """``odom -> base_link`` at ``t`` (the last odometry carried on with its twist), or None."""
        if self._odom_pose is None or self._odom_t is None:
            return None
        dt = t - self._odom_t
        if dt == 0.0 or abs(dt) > ODOM_EXTRAPOLATE_MAX_S:
            return self._odom_pose
        return compose1(self._odom_pose, se2_exp(self._twist * dt))

    def transforms(self, fused: PoseFix | None, stamp: float, laser_frame: str) -> list[StaticTransform]:
        """``map -> odom``, ``odom -> base_link`` (when known) and ``base_link -> laser``."""
        base = self.mount.parent or BASE_FRAME
        out: list[StaticTransform] = []
        if fused is not None:
            t = float(fused.stamp)
            pose = np.asarray(fused.pose, dtype=float)
            if self.odom_mode:
                out.append(StaticTransform(ODOM_FRAME, base, pose))
            else:
                odom = self.odom_pose_at(t)
                if odom is None:  # no odometry (scans only): the map holds base_link directly
                    out.append(StaticTransform(MAP_FRAME, base, pose))
                else:
                    out.append(StaticTransform(MAP_FRAME, ODOM_FRAME, compose(pose, inverse(odom))))
                    out.append(StaticTransform(ODOM_FRAME, base, odom))
        elif (odom := self.odom_pose_at(stamp)) is not None:
            out.append(StaticTransform(ODOM_FRAME, base, odom))
        out.append(StaticTransform(base, laser_frame, np.asarray(self.mount.pose, dtype=float), z=self.mount.z))
        return out

    # ------------------------------------------------------------------ scans
    def _snapshot(self) -> dict[str, Any]:
        st = self.loc.stats
        return {"scans": st.get("scans", 0), "fixes": st.get("fixes", 0), "no_fix": st.get("no_fix", 0),
                "rejected": st.get("rejected", 0), "global_searches": st.get("global_searches", 0),
                "skipped": st.get("skipped", 0), "relocalizations": st.get("relocalizations", 0),
                "n_fixes": len(getattr(self.loc, "fixes", ())),
                "no_fix_reasons": dict(getattr(self.loc, "no_fix_reasons", {}) or {}),
                "skipped_reasons": dict(st.get("skipped_reasons", {}) or {})}

    def _status(self, before: dict[str, Any], fix: PoseFix | None) -> tuple[str, str, PoseFix | None]:
        after = self._snapshot()
        if after["scans"] == before["scans"]:
            return SKIPPED, _grown_key(before["skipped_reasons"], after["skipped_reasons"]) or "refused", None
        if self.odom_mode:
            return ODOM_ONLY, "no map", None
        if after["n_fixes"] > before["n_fixes"]:
            fix = self.loc.fixes[-1]
        if after["fixes"] > before["fixes"]:
            if after["rejected"] > before["rejected"]:
                return REJECTED, "gated by the back-end (inconsistent with the fused estimate)", fix
            if after["global_searches"] > before["global_searches"]:
                return ACCEPTED, "global localization", fix
            if after["relocalizations"] > before["relocalizations"]:
                return ACCEPTED, "relocalization", fix
            return ACCEPTED, "", fix
        if after["no_fix"] > before["no_fix"]:
            return NO_FIX, _grown_key(before["no_fix_reasons"], after["no_fix_reasons"]) or "no fix", None
        if after["global_searches"] > before["global_searches"]:
            return SEARCHING, "global localization: no candidate yet", None
        if after["relocalizations"] > before["relocalizations"]:
            return SEARCHING, "lost: global localization restarted", None
        return PREDICTED, "not matched (frontend_every): odometry prediction", None

    def _emit_scan(self, fused: PoseFix | None, fix: PoseFix | None) -> None:
        assert self._pending is not None
        scan, before = self._pending
        self._pending = None
        status, reason, fix = self._status(before, fix)
        self.status_counts[status] = self.status_counts.get(status, 0) + 1
        stamp = float(scan.stamp)
        if math.isfinite(stamp):
            self._last_stamp = max(self._last_stamp, stamp)
        view = ScanView(stamp, scan, status, reason, fix, fused,
                        self.transforms(fused, stamp, scan.frame_id or self.mount.child))
        for s in self.sinks:
            s.on_scan(view)
        if fused is not None:
            self.trajectory.add(float(fused.stamp), fused.pose)
            if self.trajectory.due(stamp):
                poses = self.trajectory.poses()
                for s in self.sinks:
                    s.on_trajectory(stamp, self.frame, poses)
        self._particles(stamp)
        if stamp - self._last_health >= self.health_period_s:
            self._last_health = stamp
            health = self.health(stamp)
            for s in self.sinks:
                s.on_health(stamp, health)

    def _particles(self, stamp: float) -> None:
        fe = getattr(self.loc, "frontend", None)
        p = getattr(fe, "particles", None) if self.loc.frontend_name == "amcl" else None
        if not isinstance(p, np.ndarray) or p.ndim != 2 or p.shape[1] != 3 or len(p) == 0:
            return
        step = max(1, -(-len(p) // self.max_particles))
        sub = np.array(p[::step], dtype=float)
        for s in self.sinks:
            s.on_particles(stamp, MAP_FRAME, sub)

    # ------------------------------------------------------------------ health
    def _count(self, source: str, stamp: float) -> None:
        self.counts[source] += 1
        if not math.isfinite(stamp):
            return
        q = self._arrivals[source]
        q.append(float(stamp))
        while q and q[0] < stamp - RATE_WINDOW_S:
            q.popleft()

    def rate_hz(self, source: str, now: float) -> float:
        q = self._arrivals[source]
        n = sum(1 for t in q if now - RATE_WINDOW_S < t <= now)
        return n / RATE_WINDOW_S

    def health(self, stamp: float) -> dict[str, Any]:
        """Per-source health at log time ``stamp`` (JSON-ready)."""
        st = self.loc.stats
        be = getattr(self.loc, "backend", None)
        skipped = st.get("skipped_reasons", {}) or {}

        def skips(prefix: str) -> int:
            return int(sum(v for k, v in skipped.items() if str(k).startswith(prefix)))

        offset = be.compass_offset() if be is not None and hasattr(be, "compass_offset") else None
        sources = {
            "scan": {"count": self.counts["scan"], "rate_hz": self.rate_hz("scan", stamp), "skipped": skips("scan"),
                     "fixes": int(st.get("fixes", 0)), "no_fix": int(st.get("no_fix", 0)),
                     "rejected": int(st.get("rejected", 0)), "status": dict(self.status_counts)},
            "odom": {"count": self.counts["odom"], "rate_hz": self.rate_hz("odom", stamp),
                     "skipped": skips("odometry"), "from_poses": int(st.get("odometry_from_poses", 0))},
            "imu": {"count": self.counts["imu"], "rate_hz": self.rate_hz("imu", stamp), "skipped": skips("compass"),
                    "compass_offset_deg": None if offset is None else math.degrees(float(offset))},
        }
        return json_ready({
            "stamp": stamp,
            "frame_id": self.frame,
            "sources": sources,
            "localizer": {"relocalizations": st.get("relocalizations", 0),
                          "global_searches": st.get("global_searches", 0),
                          "no_fix_reasons": dict(getattr(self.loc, "no_fix_reasons", {}) or {}),
                          "skipped_reasons": dict(skipped)},
            "backend": {"name": getattr(self.loc, "backend_name", ""),
                        **(dict(be.stats) if be is not None and isinstance(getattr(be, "stats", None), dict) else {})},
            "frontend": getattr(self.loc, "frontend_name", ""),
        })


def _grown_key(before: dict[str, Any], after: dict[str, Any]) -> str | None:
    for k, v in after.items():
        if v != before.get(k, 0):
            return str(k)
    return None


def json_ready(v: Any) -> Any:
    """Numbers, strings, lists and dicts only (numpy scalars/arrays converted, NaN/inf -> None)."""
    if isinstance(v, dict):
        return {str(k): json_ready(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [json_ready(x) for x in v]
    if isinstance(v, np.ndarray):
        return json_ready(v.tolist())
    if isinstance(v, bool | np.bool_):
        return bool(v)
    if isinstance(v, int | np.integer):
        return int(v)
    if isinstance(v, float | np.floating):
        f = float(v)
        return f if math.isfinite(f) else None
    if v is None or isinstance(v, str):
        return v
    return str(v)
