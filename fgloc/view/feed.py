"""What the view shows, taken from a running localizer: the sink interface and its feed.

:class:`ViewFeed` is a :class:`fgloc.localization.Session` sink: it sees every input
message (``on_message(topic, msg)``, before the localizer) and each localized scan
(``on_scan(stamp, scan, fix_or_reason, fused)``), and hands each view sink plain data:

* ``on_map(occ_map, stamp)`` once;
* ``on_scan(view)`` after each scan (a :class:`ScanView`): the scan, the front-end result
  (accepted, rejected, no fix, ... with the reason), the fused pose and covariance, and the
  frame transforms ``map -> odom -> base_link -> laser`` at the fused pose's stamp;
* ``on_particles(stamp, frame_id, poses)`` after each scan when a particle filter (AMCL) runs;
* ``on_trajectory(stamp, frame_id, poses)`` the fused trajectory so far (decimated),
  every second of log time or less often as it grows;
* ``on_health(stamp, health)`` once a second of log time: per-source rates and counts,
  gated fixes, the back-end's statistics and estimates (compass offset, ...);
* ``close()``.

The feed only reads the localizer's public state (``stats``, ``fixes``, ``last_reason``,
``backend.stats``, ``backend.compass_offset()``, a particle filter's ``particles``) and
never calls anything that could change it: the poses are the same with or without a
view.  It is cheap (a few counter reads and one SE(2) step per message); sinks that do
real work (encoding, sockets) do it elsewhere (:mod:`fgloc.view.server`: another process).

``odom -> base_link`` is the odometry's own pose when the messages carry one, else the
twist integrated as the localizer does; ``map -> odom = map->base (fused) (-) odom->base``
at the same stamp, as a ROS localizer publishes it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
from numpy.typing import NDArray

from fgloc.geometry import compose1, inverse1
from fgloc.geometry import exp as se2_exp
from fgloc.io.yamlio import yaml_ready
from fgloc.types import LaserScan, Odometry, PoseFix, StaticTransform
from fgloc.view.channels import BASE_FRAME, MAP_FRAME, ODOM_FRAME

if TYPE_CHECKING:
    from fgloc.localization.stats import LiveCounts

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


class ScanView:
    """One scan as the view shows it: ``fix`` the front-end's fix (accepted or rejected), if any;
    ``fused`` the fused pose after this scan (None before start); ``transforms`` parent -> child at
    ``fused.stamp``.

    ``transforms_of`` (instead of ``transforms``): what makes them, called at their first read (a
    sink that skips the scan, as the recorder does most scans the front-end did not match, never
    pays for them); the feed's maker works from the odometry it had when the view was made.  A
    view pickles with its transforms made."""

    __slots__ = ("_transforms", "_transforms_of", "fix", "fused", "reason", "scan", "stamp", "status")

    def __init__(self, stamp: float, scan: LaserScan, status: str, reason: str, fix: PoseFix | None,
                 fused: PoseFix | None, transforms: list[StaticTransform] | None = None,
                 transforms_of: Callable[[], list[StaticTransform]] | None = None) -> None:
        self.stamp = stamp
        self.scan = scan
        self.status = status
        self.reason = reason
        self.fix = fix
        self.fused = fused
        self._transforms = transforms if transforms is not None or transforms_of is not None else []
        self._transforms_of = transforms_of

    @property
    def transforms(self) -> list[StaticTransform]:
        if self._transforms is None:
            make, self._transforms_of = self._transforms_of, None
            self._transforms = make() if make is not None else []
        return self._transforms

    def __reduce__(self) -> tuple[Any, ...]:
        return ScanView, (self.stamp, self.scan, self.status, self.reason, self.fix, self.fused, self.transforms)

    def __repr__(self) -> str:
        return (f"ScanView(stamp={self.stamp!r}, status={self.status!r}, reason={self.reason!r}, fix={self.fix!r}, "
                f"fused={self.fused!r})")


class ViewSink(Protocol):
    """What a view output implements (the WebSocket server, the MCAP recorder)."""

    def on_map(self, occ_map: Any, stamp: float) -> None: ...

    def on_scan(self, view: ScanView) -> None: ...

    def on_particles(self, stamp: float, frame_id: str, poses: FloatArray) -> None: ...

    def on_trajectory(self, stamp: float, frame_id: str, poses: FloatArray) -> None: ...

    def on_health(self, stamp: float, health: dict[str, Any]) -> None: ...

    def close(self) -> None: ...

    # optional: ``wants_scan(status) -> bool`` (``status``: the scan's ACCEPTED / PREDICTED / ...):
    # False to skip this scan (a display thinned to its frame rate); the feed then does not even
    # build it, and sends the last skipped one at close


class TrajectoryDecimator:
    """The fused trajectory so far, one pose per ``min_step_m`` / ``min_turn_rad`` / ``max_gap_s``.

    ``due(stamp)``: time to publish it again: ``period_s`` of log time after the last time,
    or longer as it grows (``len / poses_per_s``), so a long run's messages stay small in sum.
    :meth:`poses` converts only the poses added since its last call (into an array it keeps).
    """

    def __init__(self, min_step_m: float = 0.05, min_turn_rad: float = math.radians(2.0), max_gap_s: float = 1.0,
                 period_s: float = 1.0, poses_per_s: float = 200.0) -> None:
        self.min_step_m, self.min_turn_rad, self.max_gap_s = min_step_m, min_turn_rad, max_gap_s
        self.period_s, self.poses_per_s = period_s, poses_per_s
        self._rows = np.zeros((0, 3))  # the poses converted so far
        self._new: list[tuple[float, float, float]] = []  # and those added since
        self._last: tuple[float, float, float, float] | None = None  # stamp, x, y, yaw of the last pose kept
        self._last_pub = -math.inf

    def __len__(self) -> int:
        return len(self._rows) + len(self._new)

    def add(self, stamp: float, pose: FloatArray) -> None:
        x, y, yaw = float(pose[0]), float(pose[1]), float(pose[2])
        if self._last is not None:
            lt, lx, ly, lyaw = self._last
            dyaw = abs(math.remainder(yaw - lyaw, 2.0 * math.pi))
            if math.hypot(x - lx, y - ly) < self.min_step_m and dyaw < self.min_turn_rad and \
                    stamp - lt < self.max_gap_s:
                return
        self._new.append((x, y, yaw))
        self._last = (float(stamp), x, y, yaw)

    def due(self, stamp: float) -> bool:
        period = max(self.period_s, (len(self._rows) + len(self._new)) / self.poses_per_s)
        if stamp - self._last_pub >= period:
            self._last_pub = stamp
            return True
        return False

    def poses(self) -> FloatArray:
        if self._new:
            self._rows = np.concatenate([self._rows, np.asarray(self._new, dtype=float).reshape(-1, 3)])
            self._new = []
        return self._rows.copy()


class ViewFeed:
    """Turns localizer callbacks into sink calls (see the module docstring).

    ``topics`` names the scan / odometry / IMU topics (a :class:`fgloc.io.topics.Topics` or
    anything with ``scan``, ``odom``, ``imu`` attributes; ROS defaults if None).
    """

    def __init__(self, loc: Any, sinks: Iterable[ViewSink], topics: Any = None, health_period_s: float = 1.0,
                 max_particles: int = 1000) -> None:
        from fgloc.localization.stats import LiveCounts

        self.loc = loc
        self._counts = LiveCounts.of  # the localizer's counters now (imported with the localizer)
        self.sinks: list[ViewSink] = list(sinks)
        self.scan_topic = getattr(topics, "scan", "/scan")
        self.odom_topic = getattr(topics, "odom", "/odom")
        self.imu_topic = getattr(topics, "imu", "/imu")
        self.health_period_s = float(health_period_s)
        self.max_particles = int(max_particles)
        self.mount: StaticTransform = loc.laser_mount
        self._laser_tf: StaticTransform | None = None  # base_link -> laser (the last laser frame's)
        self.odom_mode = bool(getattr(loc, "odom_mode", loc.map is None))
        self.frame = ODOM_FRAME if self.odom_mode else MAP_FRAME
        self.trajectory = TrajectoryDecimator()
        self.counts: dict[str, int] = {"scan": 0, "odom": 0, "imu": 0}
        self.status_counts: dict[str, int] = {}
        self._rate_mark: tuple[float, dict[str, int]] | None = None
        self._pending: tuple[LaserScan, tuple[LiveCounts, int]] | None = None
        self._odom_pose: FloatArray | None = None
        self._odom_t: float | None = None
        self._twist = np.zeros(3)
        self._last_health = -math.inf
        self._last_stamp = 0.0
        self._last_view: tuple[LaserScan, str, str, PoseFix | None, PoseFix | None] | None = None
        self._skipped_last: list[ViewSink] = []
        self._closed = False
        if loc.map is not None:
            for s in self.sinks:
                s.on_map(loc.map, 0.0)

    # ------------------------------------------------------------------ callbacks
    def on_message(self, topic: str, msg: object) -> None:
        """Every input message, before the localizer sees it."""
        if self._pending is not None:
            self._emit_scan(None, "not localized (a newer scan was already waiting)")
        if topic == self.odom_topic and isinstance(msg, Odometry):
            self.counts["odom"] += 1
            self._odometry(msg)
        elif topic == self.scan_topic and isinstance(msg, LaserScan):
            self.counts["scan"] += 1
            self._pending = (msg, self._snapshot())
        elif topic == self.imu_topic:
            self.counts["imu"] += 1

    def on_scan(self, stamp: float, scan: LaserScan, fix_or_reason: PoseFix | str, fused: PoseFix | None) -> None:
        """After each localized scan (the session sink protocol)."""
        if self._pending is None or self._pending[0] is not scan:
            self._pending = (scan, self._pending[1] if self._pending is not None else self._snapshot())
        self._emit_scan(fused, fix_or_reason)

    def close(self) -> None:
        """Flush the last scan, send the final trajectory and health, close every sink."""
        if self._closed:
            return
        self._closed = True
        try:
            if self._pending is not None:
                self._emit_scan(None, None)
            if self._skipped_last and self._last_view is not None:
                view = self._view(*self._last_view)  # the final state, for sinks that thinned it out
                for s in self._skipped_last:
                    s.on_scan(view)
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
        if not math.isfinite(t) or (self._odom_t is not None and t <= self._odom_t):
            return
        tw = msg.twist
        if len(tw) != 3 or not math.isfinite(float(tw[0]) + float(tw[1]) + float(tw[2])):
            return
        pose = msg.pose
        if pose is not None and len(pose) == 3 and math.isfinite(float(pose[0]) + float(pose[1]) + float(pose[2])):
            self._odom_pose = np.array(pose, dtype=float)
        elif self._odom_pose is None:
            self._odom_pose = np.zeros(3)
        elif self._odom_t is not None:
            self._odom_pose = compose1(self._odom_pose, se2_exp(np.asarray(tw, dtype=float) * (t - self._odom_t)))
        self._odom_t = t
        self._twist = tw

    def odom_pose_at(self, t: float) -> FloatArray | None:
        """``odom -> base_link`` at ``t`` (the last odometry carried on with its twist), or None."""
        return _odom_at(self._odom_pose, self._odom_t, self._twist, t)

    def transforms(self, fused: PoseFix | None, stamp: float, laser_frame: str) -> list[StaticTransform]:
        """``map -> odom``, ``odom -> base_link`` (when known) and ``base_link -> laser``."""
        return self._transforms_at((self._odom_pose, self._odom_t, self._twist), fused, stamp, laser_frame)

    def _transforms_at(self, odometry: tuple[Any, float | None, Any], fused: PoseFix | None, stamp: float,
                       laser_frame: str) -> list[StaticTransform]:
        """:meth:`transforms` with the odometry ``(pose, stamp, twist)`` the feed had then."""
        base = self.mount.parent or BASE_FRAME
        out: list[StaticTransform] = []
        if fused is not None:
            t = float(fused.stamp)
            pose = np.asarray(fused.pose, dtype=float)
            if self.odom_mode:
                out.append(StaticTransform(ODOM_FRAME, base, pose))
            else:
                odom = _odom_at(*odometry, t)
                if odom is None:  # no odometry (scans only): the map holds base_link directly
                    out.append(StaticTransform(MAP_FRAME, base, pose))
                else:
                    out.append(StaticTransform(MAP_FRAME, ODOM_FRAME, compose1(pose, inverse1(odom))))  # type: ignore[arg-type]
                    out.append(StaticTransform(ODOM_FRAME, base, odom))
        elif (odom := _odom_at(*odometry, stamp)) is not None:
            out.append(StaticTransform(ODOM_FRAME, base, odom))
        laser = self._laser_tf
        if laser is None or laser.parent != base or laser.child != laser_frame:  # the same one every scan
            laser = self._laser_tf = StaticTransform(base, laser_frame, np.asarray(self.mount.pose, dtype=float),
                                                     z=self.mount.z)
        out.append(laser)
        return out

    # ------------------------------------------------------------------ scans
    def _snapshot(self) -> tuple[LiveCounts, int]:
        """The localizer's counters and how many fixes it has made, now."""
        return self._counts(self.loc.stats), len(self.loc.fixes)

    def _status(self, before: tuple[LiveCounts, int], what: PoseFix | str | None) -> tuple[str, str, PoseFix | None]:
        c0, n_fixes0 = before
        c, n_fixes = self._snapshot()
        fix = what if isinstance(what, PoseFix) else None
        told = what if isinstance(what, str) else str(self.loc.last_reason or "")
        if c.scans == c0.scans:
            return SKIPPED, told or "scan skipped (bad or repeated stamp)", None
        if self.odom_mode:
            return ODOM_ONLY, told or "no map", None
        if fix is None and n_fixes > n_fixes0:
            fix = self.loc.fixes[-1]
        if fix is not None and c.fixes > c0.fixes:
            if c.rejected > c0.rejected:
                return REJECTED, told or "fix rejected by the back-end", fix
            if c.global_searches > c0.global_searches:
                return ACCEPTED, "global localization", fix
            if c.relocalizations > c0.relocalizations:
                return ACCEPTED, "relocalization", fix
            return ACCEPTED, "", fix
        if c.no_fix > c0.no_fix:
            return NO_FIX, told or "no fix", None
        if c.global_searches > c0.global_searches or told.startswith("global") or told.startswith("initial"):
            return SEARCHING, told or "global localization: no candidate yet", None
        if c.relocalizations > c0.relocalizations:
            return SEARCHING, told or "lost: global localization restarted", None
        return PREDICTED, told or "not matched (frontend_every): odometry prediction", None

    def _emit_scan(self, fused: PoseFix | None, fix: PoseFix | str | None) -> None:
        assert self._pending is not None
        scan, before = self._pending
        self._pending = None
        status, reason, fix = self._status(before, fix)
        self.status_counts[status] = self.status_counts.get(status, 0) + 1
        stamp = float(scan.stamp)
        if math.isfinite(stamp):
            self._last_stamp = max(self._last_stamp, stamp)
        wanting: list[ViewSink] = []
        self._skipped_last = []
        for s in self.sinks:
            wants = getattr(s, "wants_scan", None)
            (wanting if wants is None or wants(status) else self._skipped_last).append(s)
        self._last_view = (scan, status, reason, fix, fused)
        if wanting:
            view = self._view(*self._last_view)
            for s in wanting:
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

    def _view(self, scan: LaserScan, status: str, reason: str, fix: PoseFix | None,
              fused: PoseFix | None) -> ScanView:
        stamp = float(scan.stamp)
        odometry = (self._odom_pose, self._odom_t, self._twist)  # (the feed's odometry moves on)
        frame = scan.frame_id or self.mount.child
        return ScanView(stamp, scan, status, reason, fix, fused,
                        transforms_of=lambda: self._transforms_at(odometry, fused, stamp, frame))

    def _particles(self, stamp: float) -> None:
        fe = self.loc.frontend
        # a particle filter's belief (FrontendBase.is_particle_filter): its ``particles`` (N, 3)
        p = fe.particles if fe is not None and fe.is_particle_filter else None
        if not isinstance(p, np.ndarray) or p.ndim != 2 or p.shape[1] != 3 or len(p) == 0:
            return
        step = max(1, -(-len(p) // self.max_particles))
        sub = np.array(p[::step], dtype=float)
        for s in self.sinks:
            s.on_particles(stamp, MAP_FRAME, sub)

    # ------------------------------------------------------------------ health
    def rates_hz(self, stamp: float) -> dict[str, float | None]:
        """Messages per second of log time per source since the previous call (None: too soon)."""
        prev = self._rate_mark
        self._rate_mark = (stamp, dict(self.counts))
        if prev is None or not stamp - prev[0] > 0:
            return {k: None for k in self.counts}
        return {k: (n - prev[1].get(k, 0)) / (stamp - prev[0]) for k, n in self.counts.items()}

    def health(self, stamp: float) -> dict[str, Any]:
        """Per-source health at log time ``stamp`` (JSON-ready)."""
        st = self._counts(self.loc.stats)
        be = self.loc.backend
        skipped = st.skipped_reasons

        def skips(prefix: str) -> int:
            return int(sum(v for k, v in skipped.items() if str(k).startswith(prefix)))

        offset = be.compass_offset()
        rates = self.rates_hz(stamp)
        sources = {
            "scan": {"count": self.counts["scan"], "rate_hz": rates["scan"], "skipped": skips("scan"),
                     "fixes": st.fixes, "no_fix": st.no_fix,
                     "rejected": st.rejected, "status": dict(self.status_counts)},
            "odom": {"count": self.counts["odom"], "rate_hz": rates["odom"],
                     "skipped": skips("odometry"), "from_poses": st.odometry_from_poses},
            "imu": {"count": self.counts["imu"], "rate_hz": rates["imu"], "skipped": skips("compass"),
                    "compass_offset_deg": None if offset is None else math.degrees(float(offset))},
        }
        return json_ready({
            "stamp": stamp,
            "frame_id": self.frame,
            "sources": sources,
            "localizer": {"relocalizations": st.relocalizations,
                          "global_searches": st.global_searches,
                          "no_fix_reasons": dict(self.loc.no_fix_reasons),
                          "skipped_reasons": dict(skipped)},
            "backend": {"name": self.loc.backend_name, **dict(be.stats)},
            "frontend": self.loc.frontend_name,
            # the back-end's online calibration (compass offset, wheel scales, gyro biases, latency)
            "estimates": be.estimates().as_dict(),
        })


def _odom_at(pose: FloatArray | None, pose_t: float | None, twist: Any, t: float) -> FloatArray | None:
    """The odometry ``pose`` of stamp ``pose_t`` carried on to ``t`` with ``twist`` (at most
    ``ODOM_EXTRAPOLATE_MAX_S``), or None."""
    if pose is None or pose_t is None:
        return None
    dt = t - pose_t
    if dt == 0.0 or abs(dt) > ODOM_EXTRAPOLATE_MAX_S:
        return pose
    tw = twist
    return compose1(pose, se2_exp(np.array((float(tw[0]) * dt, float(tw[1]) * dt, float(tw[2]) * dt))))


def json_ready(v: Any) -> Any:
    """Numbers, strings, lists and dicts only (numpy scalars/arrays converted, NaN/inf -> None)."""
    return yaml_ready(v, _json_value)


def _json_value(v: Any) -> Any:
    t = type(v)
    if t is int or t is str or t is bool or v is None:  # the common cases first, by exact type
        return v
    if t is float:
        return v if math.isfinite(v) else None
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
