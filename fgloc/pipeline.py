"""The online localizer: a scan-to-map front-end feeding a back-end (EKF or smoother).

:class:`Localizer` is what ``fgloc run`` (offline, from a log) and ``fgloc live`` (a
robot) drive, one message at a time:

* ``on_odometry`` - wheel twist -> back-end (encoder factor / update), and the
  dead-reckoned odom pose used for the front-end's ``odom_delta``;
* ``on_compass`` - compass heading -> back-end (the back-end owns the compass offset);
* ``on_scan`` - the front-end matches the scan from the back-end's predicted pose; the
  fix (if any) and a keyframe at the scan stamp go to the back-end.  Returns the fix.

Start-up: with ``initial_pose`` the first scan is matched from it.  Without, the
localizer searches globally: AMCL spreads its particles (its own global mode) and the
first fix with a small covariance is taken; the other front-ends use a coarse
correlative search over the map's free space (:mod:`fgloc.backends.global_search`)
whose best candidates are refined by the front-end, best match wins.  After
``relocalize_after`` scans in a row without an accepted fix (kidnapping, or lost),
the same global search runs again and the back-end is reset to its result.

Without a map (``occ_map=None``) encoder and compass are fused alone in an ``odom``
frame that starts at the origin with the compass heading (as robot_localization's
odom-frame EKF does with an absolute IMU yaw); keyframes are placed at scan stamps when
there are scans, else every ``odom_keyframe_interval`` seconds.

Robustness: every input is checked; a NaN/inf stamp or value, or a stamp that goes
backwards on its own stream, is counted in ``stats['skipped']`` and ignored, never
raised.  Messages slightly out of order across streams are fine (the back-ends wait
for odometry up to a keyframe's stamp).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np

from fgloc.backends import make_backend
from fgloc.backends.base import Backend, FloatArray
from fgloc.config import FglocConfig, parse_config
from fgloc.config import load_config as _load_config
from fgloc.geometry import between, compose1, transform_points, wrap_angle
from fgloc.geometry import exp as se2_exp
from fgloc.geometry import log as se2_log
from fgloc.maps import OccupancyMap
from fgloc.types import CompassHeading, LaserScan, Odometry, PoseFix, StaticTransform, Trajectory


def load_config(path: str | Path | None = None) -> FglocConfig:
    """The effective configuration (kept for old callers: see :func:`fgloc.config.load_config`)."""
    return _load_config(path)


class Localizer:
    """Online localization from odometry, compass and scans (see the module docstring)."""

    def __init__(self, occ_map: OccupancyMap | None, laser_mount: StaticTransform,
                 backend: str = "smoother", frontend: str = "native",
                 initial_pose: np.ndarray | None = None, config: FglocConfig | Any = None) -> None:
        config = parse_config(config)
        self.config = config
        self.pcfg = config.pipeline
        self.map = occ_map
        self.laser_mount = laser_mount
        self.backend_name = backend
        self.frontend_name = frontend if occ_map is not None else "none"
        self.backend: Backend = make_backend(backend, config)
        self.frontend = None
        if occ_map is not None:
            from fgloc.frontends import make_frontend

            self.frontend = make_frontend(frontend, occ_map, laser_mount, config)
        self.initial_pose = None if initial_pose is None else np.asarray(initial_pose, dtype=float).reshape(3)
        self.odom_mode = occ_map is None
        self.stats: dict[str, Any] = {
            "scans": 0, "odometry": 0, "compass": 0, "fixes": 0, "no_fix": 0, "rejected": 0,
            "gated": 0, "skipped": 0, "skipped_reasons": {}, "relocalizations": 0, "global_searches": 0,
        }
        self.no_fix_reasons: dict[str, int] = {}
        self.fixes: list[PoseFix] = []
        self._last_stamp: dict[str, float] = {}
        self._odom_pose = np.zeros(3)
        self._odom_t: float | None = None
        self._last_twist = np.zeros(3)
        self._prev_odom_pose: tuple[float, FloatArray] | None = None
        self._odom_at_last_scan: FloatArray | None = None
        self._bad_streak = 0
        self._pending: tuple[FloatArray, FloatArray, int, float] | None = None  # relocalization candidate
        self._reloc_tick = 0
        self._global_tries = 0
        self._global: Any = None
        self._last_compass: tuple[float, float] | None = None
        self._first_odom_t: float | None = None
        self._last_kf_t = -math.inf
        self._scan_count = 0
        self._lost = initial_pose is None and not self.odom_mode
        if self._lost and self.frontend is not None and self.frontend_name == "amcl":
            self.frontend.reset(None)

    # ------------------------------------------------------------------ input checks
    def _skip(self, reason: str) -> None:
        self.stats["skipped"] += 1
        r = self.stats["skipped_reasons"]
        r[reason] = r.get(reason, 0) + 1

    def _monotonic(self, stream: str, t: float) -> bool:
        if not math.isfinite(t):
            self._skip(f"{stream}: non-finite stamp")
            return False
        last = self._last_stamp.get(stream)
        if last is not None and t <= last:
            self._skip(f"{stream}: time went backwards" if t < last else f"{stream}: repeated stamp")
            return False
        self._last_stamp[stream] = t
        return True

    # ------------------------------------------------------------------ inputs
    def on_odometry(self, msg: Odometry) -> None:
        t = float(msg.stamp)
        tw = np.asarray(msg.twist, dtype=float).reshape(-1)
        if tw.shape != (3,) or not math.isfinite(float(tw[0]) + float(tw[1]) + float(tw[2])):
            self._skip("odometry: non-finite twist")
            return
        if not self._monotonic("odometry", t):
            return
        self.stats["odometry"] += 1
        pose = None if msg.pose is None else np.asarray(msg.pose, dtype=float).reshape(-1)
        if pose is not None and (pose.shape != (3,) or not np.all(np.isfinite(pose))):
            pose = None
        cov = msg.twist_cov
        if cov is not None and not math.isfinite(float(np.sum(cov))):
            cov = None
        tw, cov = self._odometry_twist(t, tw, cov, pose)
        # dead-reckoned odom pose (for the front-end's odom_delta); twist held backwards
        if self._odom_t is not None:
            self._odom_pose = compose1(self._odom_pose, se2_exp(tw * (t - self._odom_t)))
        self._odom_t = t
        self._last_twist = tw
        if self._first_odom_t is None:
            self._first_odom_t = t
        self.backend.add_odometry(t, tw, cov)
        if self.odom_mode:
            self._odom_mode_step(t, scan=False)

    def _odometry_twist(self, t: float, tw: FloatArray, cov: FloatArray | None, pose: FloatArray | None
                        ) -> tuple[FloatArray, FloatArray | None]:
        """The body twist to integrate: the message's, or the dead-reckoned pose's differential.

        robot_localization's differential mode: when the source carries poses and its twist is
        disagrees with the pose increment (CARMEN logs that leave tv = rv = 0, or rv = 0 while
        the pose turns) by more than ``pose_delta_tolerance`` (+10 %), or ``pose_deltas: always``,
        the twist is ``log(between(prev_pose, pose)) / dt`` (held over ``(t_prev, t]`` like an
        encoder twist, so integrating it reproduces the pose increment exactly).  Its covariance
        then grows with the motion (``pose_delta_sigmas`` + ``pose_delta_rel`` * |twist|): the
        poses' stamps are often where the error is (bursty logger stamps).
        """
        prev = self._prev_odom_pose
        self._prev_odom_pose = None if pose is None else (t, pose)
        mode = str(self.pcfg.pose_deltas)
        if pose is None or prev is None or mode == "never":
            return tw, cov
        dt = t - prev[0]
        if not dt > 0:
            return tw, cov
        delta = between(prev[1], pose)
        if mode != "always":
            # auto: keep the twist while it agrees with the pose increment (a simulator, a good
            # driver); CARMEN logs leave tv = rv = 0 (intel, aces) or rv = 0 (fr079)
            d_tw = se2_exp(tw * dt)
            lin, rot = float(np.hypot(delta[0], delta[1])), abs(float(delta[2]))
            tol_lin = float(self.pcfg.pose_delta_tolerance_m) + 0.1 * lin
            tol_rot = math.radians(float(self.pcfg.pose_delta_tolerance_deg)) + 0.1 * rot
            if float(np.hypot(d_tw[0] - delta[0], d_tw[1] - delta[1])) <= tol_lin and \
                    abs(float(wrap_angle(d_tw[2] - delta[2]))) <= tol_rot:
                return tw, cov
        u = se2_log(delta) / dt
        self.stats["odometry_from_poses"] = self.stats.get("odometry_from_poses", 0) + 1
        s0 = np.asarray(self.pcfg.pose_delta_sigmas, dtype=float).reshape(3)
        rel = float(self.pcfg.pose_delta_rel)
        speed = float(np.hypot(u[0], u[1]))
        sig = s0 + rel * np.array([speed, speed, abs(float(u[2])) + speed])
        return u, np.diag(sig**2)

    def on_compass(self, msg: CompassHeading) -> None:
        t = float(msg.stamp)
        yaw = msg.yaw_rad if msg.yaw_rad is not None and math.isfinite(msg.yaw_rad) else None
        rate = msg.yaw_rate_radps if msg.yaw_rate_radps is not None and math.isfinite(msg.yaw_rate_radps) else None
        if yaw is None and rate is None:
            self._skip("compass: no finite heading or rate")
            return
        if not self._monotonic("compass", t):
            return
        self.stats["compass"] += 1
        if yaw is not None:
            self._last_compass = (t, float(yaw))
        self.backend.add_compass(t, yaw, float(msg.yaw_var), rate, float(msg.yaw_rate_var))

    def on_scan(self, msg: LaserScan) -> PoseFix | None:
        t = float(msg.stamp)
        if not self._monotonic("scan", t):
            return None
        self.stats["scans"] += 1
        if self.odom_mode:
            self._odom_mode_step(t, scan=True)
            return None
        assert self.frontend is not None
        matching = self.backend.initialized and not self._lost
        if matching:
            self._scan_count += 1
            if self._scan_count % max(1, int(self.pcfg.frontend_every)) != 0:
                # not matched: no keyframe either, the online pose is the odometry prediction
                self.backend.record_prediction(t)
                return None
        # odometry motion since the previous front-end call (for its de-skew / motion model)
        # the dead-reckoned odom pose *at the scan stamp*: the last odometry message carried on
        # (or back) with its twist, so slow or late odometry does not hand the front-end a
        # stale motion (0 or several scan periods of it) for its de-skew (AMCL keeps the
        # odometry as it came: its motion model and update thresholds were tuned on that)
        odom_now = self._odom_pose
        if self._odom_t is not None and self.frontend_name != "amcl" and \
                abs(t - self._odom_t) <= float(self.pcfg.odom_extrapolate_max_s):
            odom_now = compose1(self._odom_pose, se2_exp(self._last_twist * (t - self._odom_t)))
        odom_delta = None
        if self._odom_at_last_scan is not None:
            odom_delta = between(self._odom_at_last_scan, odom_now)
        self._odom_at_last_scan = np.array(odom_now, dtype=float)
        if not matching:
            return self._localize_globally(msg, odom_delta)
        guess, _ = self.backend.predict(t)
        res = self.frontend.match(msg, guess, odom_delta)
        fix = None
        if res.ok and res.pose is not None and res.cov is not None and np.all(np.isfinite(res.pose)) \
                and np.all(np.isfinite(res.cov)):
            fix = PoseFix(t, np.asarray(res.pose, dtype=float), np.asarray(res.cov, dtype=float),
                          quality=float(res.quality), source=self.frontend_name)
            self.fixes.append(fix)
            self.stats["fixes"] += 1
        else:
            self.stats["no_fix"] += 1
            reason = (res.reason or "no fix").split(":")[0][:60]
            self.no_fix_reasons[reason] = self.no_fix_reasons.get(reason, 0) + 1
        used = self.backend.add_keyframe(t, fix)
        if fix is not None and not used:
            self.stats["rejected"] += 1
        # a scan with too few returns (blackout, blocked laser) says nothing about being lost;
        # neither does AMCL skipping an update (its motion thresholds) or converging again
        # after its own recovery: AMCL counts only when it gives a fix the back-end rejects
        if self.frontend_name == "amcl":
            informative = fix is not None
        else:
            informative = fix is not None or int(np.count_nonzero(msg.valid_mask())) >= 30
        if used:
            self._bad_streak = 0
            self._pending = None
        elif informative:
            self._bad_streak += 1
        if self._bad_streak >= int(self.pcfg.relocalize_after):
            if self.frontend_name == "amcl":
                self._lost = True
                self._global_tries = 0
                self.stats["relocalizations"] += 1
                self.frontend.reset(None)
            else:
                self._check_relocalization(msg, res, guess, odom_delta)
        return fix

    def _check_relocalization(self, msg: LaserScan, local: Any, guess: FloatArray,
                              odom_delta: FloatArray | None) -> None:
        """Tracking has had no accepted fix for ``relocalize_after`` scans: look for a better place.

        Tracking goes on meanwhile.  A global candidate (every ``relocalize_search_every``-th
        such scan) becomes *pending* only when it is consistent and unambiguous: quality at
        least ``relocalize_min_quality``, ``relocalize_margin`` better than the tracked pose's match
        (unless it is the tracked match itself), and no other candidate more than 1 m / 20 deg
        away within ``relocalize_ambiguity`` of it.  A pending pose is carried along by odometry
        and must match again on ``relocalize_confirm`` further scans spanning at least
        ``relocalize_confirm_s`` (scans logged in a burst are not independent evidence) before
        the back-end is reset to it; one failed match drops it.  So repetitive buildings (similar rooms, corridors)
        and fixes merely rejected for a while do not make the robot jump.
        """
        assert self.frontend is not None
        t = float(msg.stamp)
        if self._pending is not None:
            pose = compose1(self._pending[0], odom_delta) if odom_delta is not None else self._pending[0]
            res = self.frontend.match(msg, pose, None)
            if res.ok and res.pose is not None and res.cov is not None and \
                    float(res.quality) >= float(self.pcfg.relocalize_min_quality):
                count = self._pending[2] + 1
                t_first = self._pending[3]
                self._pending = (np.asarray(res.pose, dtype=float), np.asarray(res.cov, dtype=float), count, t_first)
                if count > int(self.pcfg.relocalize_confirm) and \
                        t - t_first >= float(self.pcfg.relocalize_confirm_s):
                    self.stats["relocalizations"] += 1
                    self._pending = None
                    self._start(t, np.asarray(res.pose, dtype=float),
                                np.asarray(res.cov, dtype=float) + np.diag([1e-6, 1e-6, 1e-6]))
            else:
                self._pending = None
            return
        self._reloc_tick += 1
        if (self._reloc_tick - 1) % max(1, int(self.pcfg.relocalize_search_every)) != 0:
            return
        cands = self._global_candidates(msg)
        if not cands:
            return
        best_q, best = cands[0]
        if best_q < float(self.pcfg.relocalize_min_quality):
            return
        local_q = float(getattr(local, "quality", 0.0) or 0.0)
        near_local = local.ok and local.pose is not None and \
            _close(best.pose, np.asarray(local.pose, dtype=float), 0.3, math.radians(5.0))
        if not near_local and best_q < local_q + float(self.pcfg.relocalize_margin):
            return
        amb = float(self.pcfg.relocalize_ambiguity)
        for q, c in cands[1:]:
            if q >= best_q - amb and not _close(c.pose, best.pose, 1.0, math.radians(20.0)):
                self.stats["ambiguous_relocalizations"] = self.stats.get("ambiguous_relocalizations", 0) + 1
                return
        self._pending = (best.pose.copy(), best.cov.copy(), 1, t)

    # ------------------------------------------------------------------ start-up / recovery
    def _initial_cov(self) -> FloatArray:
        sxy = float(self.pcfg.initial_sigma_xy_m)
        syaw = math.radians(float(self.pcfg.initial_sigma_yaw_deg))
        return np.diag([sxy**2, sxy**2, syaw**2])

    def _start(self, t: float, pose: FloatArray, cov: FloatArray) -> None:
        if self.backend.initialized:
            self.backend.reset(t, pose, cov)
        else:
            self.backend.initialize(t, pose, cov)
        self._lost = False
        self._bad_streak = 0
        self._pending = None
        self._reloc_tick = 0
        if self.frontend is not None and self.frontend_name == "amcl":
            self.frontend.reset(pose)

    def _localize_globally(self, msg: LaserScan, odom_delta: FloatArray | None) -> PoseFix | None:
        assert self.frontend is not None
        t = float(msg.stamp)
        if self.initial_pose is not None and not self.backend.initialized:
            res = self.frontend.match(msg, self.initial_pose, odom_delta)
            if res.ok and res.pose is not None and res.cov is not None:
                fix = PoseFix(t, np.asarray(res.pose, dtype=float), np.asarray(res.cov, dtype=float),
                              quality=float(res.quality), source=self.frontend_name)
                self.fixes.append(fix)
                self.stats["fixes"] += 1
                self._start(t, fix.pose, np.maximum(fix.cov, 0) + np.diag([1e-6, 1e-6, 1e-6]))
                return fix
            self._start(t, self.initial_pose, self._initial_cov())
            return None
        self._global_tries += 1
        if self.frontend_name == "amcl":
            guess = self.backend.predict(t)[0] if self.backend.initialized else np.zeros(3)
            res = self.frontend.match(msg, guess, odom_delta)
            if res.ok and res.pose is not None and res.cov is not None:
                sxy = math.sqrt(max(res.cov[0, 0], res.cov[1, 1]))
                syaw = math.sqrt(res.cov[2, 2])
                if sxy <= float(self.pcfg.global_max_sigma_xy_m) and \
                        syaw <= math.radians(float(self.pcfg.global_max_sigma_yaw_deg)):
                    fix = PoseFix(t, np.asarray(res.pose, dtype=float), np.asarray(res.cov, dtype=float),
                                  quality=float(res.quality), source=self.frontend_name)
                    self.fixes.append(fix)
                    self.stats["fixes"] += 1
                    self._start(t, fix.pose, fix.cov + np.diag([1e-6, 1e-6, 1e-6]))
                    return fix
            if self.backend.initialized:
                self.backend.add_keyframe(t, None)
            return None
        gfix = self._global_search(msg)
        if gfix is not None:
            self.fixes.append(gfix)
            self.stats["fixes"] += 1
            self._start(t, gfix.pose, gfix.cov + np.diag([1e-6, 1e-6, 1e-6]))
            return gfix
        if self.backend.initialized:
            self.backend.add_keyframe(t, None)
        return None

    def _global_search(self, msg: LaserScan) -> PoseFix | None:
        cands = self._global_candidates(msg)
        if not cands or cands[0][0] < float(self.pcfg.global_min_quality):
            return None
        return cands[0][1]

    def _global_candidates(self, msg: LaserScan) -> list[tuple[float, PoseFix]]:
        """Front-end-refined global search candidates, best quality first."""
        from fgloc.backends.global_search import GlobalSearch

        assert self.frontend is not None and self.map is not None
        if self._global is None:
            self._global = GlobalSearch(self.map, self.pcfg.global_search)
        self.stats["global_searches"] += 1
        pts = msg.points()
        if len(pts) < 10:
            return []
        pts_base = transform_points(self.laser_mount.pose, pts)
        # the compass (once its offset is known) rules out headings, e.g. the mirror image
        # of a symmetric hall
        heading = None
        off = self.backend.compass_offset()
        if off is not None and self._last_compass is not None and \
                abs(float(msg.stamp) - self._last_compass[0]) < 1.0:
            heading = float(wrap_angle(self._last_compass[1] - off))
        max_dyaw = math.radians(float(self.pcfg.global_compass_tolerance_deg))
        out: list[tuple[float, PoseFix]] = []
        for cand, _score in self._global.search(pts_base):
            if heading is not None and abs(float(wrap_angle(cand[2] - heading))) > max_dyaw:
                continue
            res = self.frontend.match(msg, cand, None)
            if not (res.ok and res.pose is not None and res.cov is not None):
                continue
            q = float(res.quality)
            out.append((q, PoseFix(float(msg.stamp), np.asarray(res.pose, dtype=float),
                                   np.asarray(res.cov, dtype=float), quality=q, source=self.frontend_name)))
        out.sort(key=lambda qc: -qc[0])
        return out

    # ------------------------------------------------------------------ odom-only mode
    def _odom_mode_step(self, t: float, scan: bool) -> None:
        if not self.backend.initialized:
            # wait up to 0.5 s for a compass heading to align the odom frame with it
            if self._last_compass is None and (self._first_odom_t is None or t - self._first_odom_t < 0.5):
                return
            yaw = self._last_compass[1] if self._last_compass is not None else 0.0
            self.backend.set_compass_offset(0.0)
            self.backend.initialize(t, np.array([0.0, 0.0, yaw]), np.diag([1e-6, 1e-6, 1e-6]))
            self._last_kf_t = t
            return
        if scan or (self.stats["scans"] == 0 and t - self._last_kf_t >= float(self.pcfg.odom_keyframe_interval_s)):
            self.backend.add_keyframe(t, None)
            self._last_kf_t = t

    # ------------------------------------------------------------------ outputs
    def current(self) -> PoseFix | None:
        """Latest fused pose and covariance, predicted to the newest odometry stamp."""
        cur = self.backend.current()
        if cur is None:
            return None
        t, pose, cov = cur
        if self._odom_t is not None and self._odom_t > t:
            pose, cov = self.backend.predict(self._odom_t)
            t = self._odom_t
        return PoseFix(t, pose, cov, source=self.backend_name, frame_id="odom" if self.odom_mode else "map")

    def online_trajectory(self) -> Trajectory:
        """Fused pose at each scan (keyframe) time, as known online."""
        tr = self.backend.online_trajectory()
        tr.frame_id = "odom" if self.odom_mode else "map"
        return tr

    def finish(self) -> Trajectory:
        """Smoothed trajectory (fixed-lag or batch; the EKF's online one for the EKF)."""
        tr = self.backend.finish()
        tr.frame_id = "odom" if self.odom_mode else "map"
        self.stats["gated"] = int(self.backend.stats.get("fixes_rejected", 0))
        self.stats["backend"] = dict(self.backend.stats)
        if self.no_fix_reasons:
            self.stats["no_fix_reasons"] = dict(self.no_fix_reasons)
        return tr

    def fixes_trajectory(self) -> Trajectory:
        """The front-end's fixes as a trajectory (map frame)."""
        if not self.fixes:
            return Trajectory(np.zeros(0), np.zeros((0, 3)))
        return Trajectory.from_unsorted(np.array([f.stamp for f in self.fixes]),
                                        np.array([f.pose for f in self.fixes]))


def _close(a: FloatArray, b: FloatArray, dist_m: float, dyaw_rad: float) -> bool:
    return float(np.hypot(a[0] - b[0], a[1] - b[1])) <= dist_m and abs(float(wrap_angle(a[2] - b[2]))) <= dyaw_rad


def run_messages(loc: Localizer, messages: Iterable[tuple[str, object]], topics: Any = None,
                 on_message: Callable[[str, object], None] | None = None,
                 on_fused: Callable[[PoseFix, PoseFix | None], None] | None = None) -> Trajectory:
    """Feed ``(topic, message)`` pairs (as ``LogReader.messages`` or ``SimResult.messages`` give)
    to ``loc`` and return ``loc.finish()``.

    ``topics`` (a :class:`fgloc.io.log.Topics`, default names if None) says which topic is
    the odometry, compass and scan; ``/ground_truth`` and unknown topics are ignored.
    ``on_message(topic, msg)`` sees every message; ``on_fused(fused, fix)`` is called after
    each scan with the fused pose and the front-end fix (for writing ``/fused_pose``).
    """
    scan_t = getattr(topics, "scan", "/scan")
    odom_t = getattr(topics, "odom", "/odom")
    imu_t = getattr(topics, "imu", "/imu")
    for topic, msg in messages:
        if on_message is not None:
            on_message(topic, msg)
        if topic == odom_t and isinstance(msg, Odometry):
            loc.on_odometry(msg)
        elif topic == imu_t and isinstance(msg, CompassHeading):
            loc.on_compass(msg)
        elif topic == scan_t and isinstance(msg, LaserScan):
            fix = loc.on_scan(msg)
            if on_fused is not None:
                cur = loc.current()
                if cur is not None:
                    on_fused(cur, fix)
    return loc.finish()
