"""The status of every pose, the run-level verdicts and the dead-reckoned poses of the
:class:`~fgloc.localization.localizer.Localizer` (:class:`PoseStatus`, one of its bases): what
:mod:`fgloc.localization.monitor` records and judges, read off the localizer's state.

Core maths only: no I/O.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from fgloc.backends.base import Backend, FloatArray
from fgloc.localization.divergence import FixCourse, MapJumps, PathDivergence
from fgloc.localization.gate import agreement_sigma
from fgloc.localization.monitor import DEGRADED, LOST, OK, SUSPECT, ConsistencyMonitor, DeadReckoning, MapAgreement

if TYPE_CHECKING:
    from fgloc.localization.config import PipelineConfig
    from fgloc.localization.monitor import IntegrityConfig
    from fgloc.localization.odometry import OdometryTracker
    from fgloc.maps import OccupancyMap
    from fgloc.types import PoseFix

#: the map does not fit the log: lost at least this share of the run, and fixes accepted on fewer than
#: this share of the scans matched (a right map with a wrong start relocalizes and tracks; a building
#: the map lacks is dead-reckoned, not lost)
MISMATCH_LOST_SHARE = 0.5
MISMATCH_MATCHED_SHARE = 0.1
#: a no-fix reason (its kind, localizer.reason_kind) of a particle filter that did not update for its motion
#: thresholds (AMCL's update_min_d / update_min_a): no match was tried on that scan
WAITING_FOR_MOTION = "waiting for motion"
#: a back-end's heading_diverged_s counter that grew within this long (log s): its heading diverges now
HEADING_CHECK_S = 1.0
HEADING_DIVERGED = "heading diverged: the fused heading follows none of its heading sources"
#: placements the odometry did not drive to, each ending a global search, while at least this share of the laser's
#: ranges fit the map's at the poses called ok (the median over the run, coverage.py range_fit): a map with places
#: alike, not a map that does not fit (the right map: 0.75-0.98 in simulation, Radish and Stage logs; a mirrored or
#: rescaled map whose placements jump: 0.12-0.51)
AMBIGUOUS_FIT = 0.7
#: the fixes' course off the odometry's by more than this (deg, the median over the run's straight stretches,
#: divergence.py FixCourse): the laser is mounted turned from where its tf says
COURSE_OFF_DEG = 2.0
#: what a map that does not fit may also be: a laser mounted upside down (its scan mirrored) fits no map either
MOUNT_HINT = " Or is the laser mounted as its tf says (not upside down: its scan would be mirrored)?"


class PoseStatus:
    """The pose status, verdicts and dead reckoning of :class:`~fgloc.localization.localizer.Localizer`
    (its ``__init__`` sets the state below)."""

    backend: Backend
    backend_name: str
    stats: dict[str, Any]
    pcfg: PipelineConfig
    icfg: IntegrityConfig
    monitor: ConsistencyMonitor
    odom: OdometryTracker
    odom_mode: bool
    initial_pose: FloatArray | None
    last_reason: str
    pose_listener: Callable[[float], None] | None
    dead_reckoning: DeadReckoning | None
    agreement: MapAgreement | None
    map: OccupancyMap | None
    #: the fused path against the odometry's since the last fix taken (divergence.py; made at the first pose)
    path_divergence: PathDivergence | None = None
    #: the map's placements against the odometry's motion between them (divergence.py; made at the first pose)
    map_jumps: MapJumps | None = None
    #: the fixes' course against the odometry's (divergence.py; made at the first pose)
    fix_course: FixCourse | None = None
    #: the localizer was searching the whole map (lost) at the last pose recorded
    _searching: bool = False
    fixes: list[PoseFix]
    no_fix_reasons: dict[str, int]
    _divergence: tuple[float, float, float] | None
    _worst_divergence: tuple[float, float, float, float, float] | None
    _divergence_t: float
    _heading_diverged_s: float
    _heading_diverged_t: float
    _last_scan_t: float | None
    _first_scan_t: float | None
    _last_kf_t: float
    _last_dr_t: float
    _last_compass: tuple[float, float] | None
    _t_used: float | None
    _t_started: float | None
    _t_held_since: float | None
    _rejected_run: int  # fixes the gate passed and the back-end rejected since it last took one
    _converged: bool
    _lost: bool
    _lost_since: float | None
    _lost_total_s: float

    def _first_convergence(self, t: float, pose: FloatArray) -> None:
        """The map confirmed a pose for the first time at ``t``: if it is not where ``--initial-pose`` said
        (beyond 3 sigma of its prior), that start did not fit the map, and every pose before is lost;
        without one, the poses a global search published before it converged are lost (said when any)."""
        p0 = self.initial_pose
        if p0 is None:
            n = sum(1 for x in self.monitor.t if x < t)
            if n:  # a global search whose pose was published before it converged (AMCL's cloud mean)
                self.monitor.amend(-math.inf, t, LOST, "lost: global localization had not converged")
                self.monitor.verdict("global_start", f"global localization converged at t = {t:.1f} s ({n} pose(s) "
                                     "before are marked lost)", False)
            return
        d = float(np.hypot(pose[0] - p0[0], pose[1] - p0[1]))
        a = abs(math.degrees(float(np.angle(np.exp(1j * (pose[2] - p0[2]))))))
        if d <= 3 * self.pcfg.initial_sigma_xy_m and a <= 3 * self.pcfg.initial_sigma_yaw_deg:
            return
        self.monitor.amend(-math.inf, t, LOST, "lost: the initial pose does not fit the map")
        n = sum(1 for x in self.monitor.t if x < t)
        self.monitor.verdict(
            "initial_pose", f"the initial pose ({p0[0]:.2f} m, {p0[1]:.2f} m, {math.degrees(p0[2]):.0f} deg) does "
            f"not fit the map: the scans matched {d:.2f} m / {a:.0f} deg from it, at t = {t:.1f} s "
            f"({n} pose(s) before are marked lost)", False)

    def _check_divergence(self, t: float) -> None:
        """Odom frame, at most once a second: how far the fused pose is from dead reckoning."""
        dr = self.dead_reckoning
        if dr is None or t - self._divergence_t < 1.0:
            return
        self._divergence_t = t
        cur = self.backend.current(covariance=False)
        d = None if cur is None else dr.divergence(cur[1])
        if d is None:
            return
        limit = max(self.icfg.divergence_min_m, self.icfg.divergence_share * dr.distance_m)
        self._divergence = (d, dr.distance_m, limit) if d > limit else None
        if d > limit and (self._worst_divergence is None or d / limit > self._worst_divergence[0]):
            self._worst_divergence = (d / limit, d, dr.distance_m, limit, t)

    def _record_status(self, t: float) -> None:
        """The status of the pose at scan stamp ``t`` (monitor.py)."""
        self._map_placement(t)
        self._fix_course(t)
        status, why = self.pose_status(t)
        self.monitor.record(t, status, why)
        self._searching = self._lost or not self.backend.initialized

    def pose_status(self, t: float) -> tuple[str, str]:
        """``(status, why)`` of the pose now (``t``: the newest stamp), see :mod:`fgloc.localization.monitor`."""
        if self.odom_mode:
            if not self.backend.initialized:
                return LOST, "no pose yet"
            self._check_divergence(t)
            if self._divergence is not None:
                d, dist, limit = self._divergence
                return SUSPECT, f"{d:.1f} m from odometry + IMU dead reckoning after {dist:.0f} m driven"
            if self._heading_diverging(t):
                return SUSPECT, HEADING_DIVERGED
            return OK, ""
        silent = self._last_scan_t is not None and t - self._last_scan_t >= self.icfg.laser_silent_after_s
        if not self.backend.initialized:
            return LOST, "no pose yet: searching the map"
        if self._lost:
            return LOST, "lost: searching the map"
        if not self._converged:
            return LOST, "not converged: the start pose is not confirmed by the map yet"
        since = t - (self._t_used if self._t_used is not None else t)
        mj = self.map_jumps
        if mj is not None and mj.repeated:
            if self._places_alike() is not None:  # what the run's verdict will say (_assess)
                return SUSPECT, (f"could not tell where in the map the robot is: its global search settled "
                                 f"{mj.events} times where the odometry did not take the robot")
            return SUSPECT, (f"the map does not fit: it put the robot {mj.events} times where its odometry did not "
                             "take it")
        div = self._path_diverged(t)
        if div is not None:
            d, path, s = div
            return SUSPECT, (f"the fused pose left the odometry's path: {d:.2f} m from where it took the last fix "
                             f"{s:.1f} s ago, the odometry drove {path:.2f} m")
        ag = self.agreement
        if ag is not None and ag.low_for(t) >= self.icfg.agreement_suspect_s:
            return SUSPECT, (f"the scan has not fit the map at this pose for {ag.low_for(t):.1f} s (agreement "
                             f"{ag.last or 0.0:.2f}, {ag.expected() or 0.0:.2f} while it was right)")
        if self._t_held_since is not None and t - self._t_held_since >= self.icfg.suspect_after_s:
            return SUSPECT, f"the map has pointed elsewhere for {t - self._t_held_since:.1f} s"
        turned = self._laser_turned()
        if turned is not None:
            a, n = turned
            return SUSPECT, (f"the laser looks turned {a:+.1f} deg from its tf: the fixes move at {-a:+.1f} deg to "
                             f"the odometry's course (median over {n} straight stretches)")
        if self._heading_diverging(t):
            return SUSPECT, HEADING_DIVERGED
        if silent:
            assert self._last_scan_t is not None
            return DEGRADED, f"dead reckoning: no scan for {t - self._last_scan_t:.1f} s"
        if self._rejected_run:
            # the map gave a fix the jump gate found no jump, the back-end does not follow it: the pose is
            # its dead reckoning, and the map disagrees with it
            return DEGRADED, (f"dead reckoning for {since:.1f} s: the back-end rejected the map's last "
                              f"{self._rejected_run} fix(es)")
        if since >= self.icfg.degraded_after_s:
            return DEGRADED, f"dead reckoning for {since:.1f} s: {self.last_reason or 'no fix'}"
        return OK, ""

    def _map_placement(self, t: float) -> None:
        """The pose at ``t`` against the odometry (divergence.py :class:`MapJumps`): a placement when the back-end
        took a fix or was (re)started on one at ``t`` (out of a global search when the pose before was lost)."""
        if self.map is None or self.odom_mode or self.stats["odometry"] == 0:
            return
        mj = self.map_jumps
        if mj is None:
            mj = self.map_jumps = MapJumps(self.icfg.odometry_slip)
        odom = self.odom.pose_at(t)
        if self._t_used is None or self._t_used != t:
            mj.odometry(odom)
            return
        pose: FloatArray | None = None
        if self._t_started != t and self.fixes and self.fixes[-1].stamp == t:
            pose = self.fixes[-1].pose
        else:
            cur = self.backend.current(covariance=False)
            pose = None if cur is None else cur[1]
        if pose is None:
            mj.odometry(odom)
        else:
            mj.place(t, pose, odom, self._searching)

    def _fix_course(self, t: float) -> None:
        """A fix the back-end took at ``t`` against the odometry's motion (divergence.py :class:`FixCourse`)."""
        if self.map is None or self.odom_mode or self.stats["odometry"] == 0 or self._t_used != t:
            return
        fc = self.fix_course
        if fc is None:
            fc = self.fix_course = FixCourse()
        if self._t_started == t:
            fc.restart()
        elif self.fixes and self.fixes[-1].stamp == t:
            fc.fix(self.fixes[-1].pose, self.odom.pose_at(t))

    def _laser_turned(self) -> tuple[float, int] | None:
        """``(deg, stretches)``: how far the laser looks turned from its tf (the fixes' course against the
        odometry's, beyond :data:`COURSE_OFF_DEG`), else None."""
        fc = self.fix_course
        off = None if fc is None else fc.offset()
        if off is None or abs(math.degrees(off[0])) <= COURSE_OFF_DEG:
            return None
        return -math.degrees(off[0]), off[1]

    def _unusable(self, kind: str, lost_why: str, message: str) -> None:
        """A finding that makes the run unusable: every pose lost (``lost_why``), the verdict ``kind`` (a map that
        does not fit with :data:`MOUNT_HINT`)."""
        self.monitor.amend(-math.inf, math.inf, LOST, lost_why)
        self.monitor.verdict(kind, message + (MOUNT_HINT if kind == "map_mismatch" else ""), True)

    def _places_alike(self) -> tuple[float, int] | None:
        """Whether the map's jumps (divergence.py :class:`MapJumps`) are a map with places alike: every one ended a
        global search, and the map's ranges fit the laser's at the poses called ok (coverage.py range_fit, the
        median share of the beams that fit at least :data:`AMBIGUOUS_FIT`): that share and how many scans; else
        None."""
        mj, ag = self.map_jumps, self.agreement
        if mj is None or ag is None or not mj.jumps or not all(searched for _, searched in mj.jumps):
            return None
        n = len(ag.range_samples)
        if n < ag.RANGE_MIN_SAMPLES:
            return None
        share = float(np.median([s for _, s in ag.range_samples]))
        return (share, n) if share >= AMBIGUOUS_FIT else None

    def _path_diverged(self, t: float) -> tuple[float, float, float] | None:
        """The fused pose at ``t`` further from the last fix the back-end took than the odometry drove since
        (divergence.py); ``(m from it, m driven, s since)`` until the back-end takes a fix or restarts."""
        if self.stats["odometry"] == 0 or self.map is None:
            return None
        pd = self.path_divergence
        if pd is None:
            pd = self.path_divergence = PathDivergence(
                self.icfg.odometry_slip, agreement_sigma(self.map, self.icfg.agreement_sigma_m), self.icfg.gate_chi2)
        online = self.backend.online_after(t - 1e-3)  # the pose just recorded at t (stamps near 1e9 s: no 1e-9)
        if not online or online[-1][0] < t - 1e-6:
            return None
        _, pose, cov = online[-1]
        return pd.step((self._t_used, self._t_started), t, pose, cov, self.odom.pose)

    def _heading_diverging(self, t: float) -> bool:
        """The back-end says its fused heading follows none of its heading sources: the log time it
        counts as diverging (its ``heading_diverged_s`` counter, a smoother's heading check) grew within
        the last second."""
        total = float(self.backend.stats.get("heading_diverged_s", 0.0) or 0.0)
        if total > self._heading_diverged_s:
            self._heading_diverged_s = total
            self._heading_diverged_t = t
        return t - self._heading_diverged_t <= HEADING_CHECK_S

    def _odom_mode_step(self, t: float, scan: bool) -> None:
        if not self.backend.initialized:
            # wait up to 0.5 s for a compass heading to align the odom frame with it
            first = self.odom.first_t
            if self._last_compass is None and (first is None or t - first < 0.5):
                return
            yaw = self._last_compass[1] if self._last_compass is not None else 0.0
            self.backend.set_compass_offset(0.0)
            self.backend.initialize(t, np.array([0.0, 0.0, yaw]), np.diag([1e-6, 1e-6, 1e-6]))
            self._last_kf_t = t
            if self.dead_reckoning is not None:
                self.dead_reckoning.start(t, np.array([0.0, 0.0, yaw]))
            self._record_status(t)
            return
        if scan or (self.stats["scans"] == 0 and t - self._last_kf_t >= self.pcfg.odom_keyframe_interval_s):
            self.backend.add_keyframe(t, None)
            self._last_kf_t = t
            if not scan:  # a wheels + IMU log: its poses told to the sinks too
                self._pose_added(t)
        else:
            self._dead_reckon(t)

    def _laser_silent(self, t: float) -> bool:
        """No scan yet, or none for ``integrity.laser_silent_after_s``."""
        last = self._last_scan_t
        return last is None or t - last >= self.icfg.laser_silent_after_s

    def _dead_reckon(self, t: float) -> None:
        """Odometry at ``t``: while the laser is silent, a dead-reckoned pose every
        ``integrity.dead_reckoning_period_s``: the back-end's prediction (its covariance grows with the
        odometry's), in the online trajectory and told to the sinks; the back-end's graph is left as it is."""
        if not self.backend.initialized or self._last_scan_t is None or not self._laser_silent(t):
            return
        if t - self._last_dr_t < self.icfg.dead_reckoning_period_s:
            return
        self.backend.record_prediction(t)
        self._last_dr_t = t
        self.stats["dead_reckoned_poses"] = self.stats.get("dead_reckoned_poses", 0) + 1
        self._pose_added(t)

    def _pose_added(self, t: float) -> None:
        """A pose without a scan at ``t``: its status, and :attr:`pose_listener` (the session's sinks)."""
        self._record_status(t)
        if self.pose_listener is not None:
            self.pose_listener(t)

    @property
    def lost(self) -> bool:
        """Searching globally: no pose yet, or no accepted fix for ``lost_after_s``."""
        return self._lost

    def lost_time_s(self) -> float:
        """Seconds spent lost so far (up to the last scan when lost now)."""
        total = self._lost_total_s
        if self._lost_since is not None and self._last_scan_t is not None:
            total += max(0.0, self._last_scan_t - self._lost_since)
        return total

    def _assess(self) -> None:
        """The run-level verdicts (monitor.py): the scan stopped fitting the map at the fused pose (the
        localizer searched again; said); no scan ever matched the map; in the odom frame, a
        fused path that ends far from dead reckoning; a back-end whose heading diverged from all its
        heading sources for a while (said; its poses are suspect, counted towards
        ``integrity.max_bad_share``)."""
        bs = self.backend.stats
        diverged_s = float(bs.get("heading_diverged_s", 0.0) or 0.0)
        if diverged_s > 0:
            worst = bs.get("heading_divergence_worst_deg")
            self.monitor.verdict(
                "heading_diverged", f"the {self.backend_name}'s heading followed none of its heading sources for "
                f"{diverged_s:.1f} s in {int(bs.get('heading_divergence_spans', 1) or 1)} span(s)"
                + (f" (worst {float(worst):.1f} deg off the nearest)" if worst is not None else "")
                + "; its poses there are suspect", False)
        pd = self.path_divergence
        if pd is not None and pd.events and pd.worst is not None:
            d, path, s = pd.worst
            self.monitor.verdict(
                "path_diverged", f"the fused pose left the odometry's path {pd.events} time(s) (worst: {d:.1f} m from "
                f"where the {self.backend_name} took its last fix {s:.1f} s before, the odometry drove {path:.1f} m): "
                "the back-end diverged, its poses until the next fix it took are suspect", False)
        n_lost = int(self.stats.get("agreement_lost", 0) or 0)
        if n_lost:
            self.monitor.verdict(
                "agreement", f"the scan stopped fitting the map at the fused pose {n_lost} time(s) for "
                f"{self.icfg.agreement_lost_s:.1f} s (a front-end tracking a wrong place; integrity.agreement_low): "
                "the localizer searched again, the poses since it last fit are lost", False)
        if self.odom_mode:
            self._divergence_t = -math.inf
            if self._last_kf_t > -math.inf:
                self._check_divergence(self._last_kf_t)
            if self._worst_divergence is not None:
                _, d, dist, limit, t = self._worst_divergence
                t0 = self.dead_reckoning.t0 if self.dead_reckoning is not None else None
                into = t - (t0 if t0 is not None else t)
                self.monitor.verdict(
                    "diverging", f"the fusion diverged from odometry + IMU dead reckoning: {d:.1f} m apart "
                    f"{into:.1f} s into the run after {dist:.0f} m driven (more than {limit:.1f} m, "
                    "integrity.divergence_share); "
                    "check the sources' configuration (each source's mount and components)", True)
            return
        used = int(self.stats.get("fixes_used", 0))
        scans = int(self.stats["scans"])
        if used == 0 and scans > 0:
            found = f"0 of {self.stats['fixes']} fixes accepted" if self.stats["fixes"] else "no fix"
            self.monitor.verdict(
                "no_fix", f"no scan matched the map: {found} in {scans} scans, every pose is dead reckoning (does "
                "this map fit this log? is the laser's mount right?)", True)
            return
        span = (self._last_scan_t - self._first_scan_t) if self._first_scan_t is not None and \
            self._last_scan_t is not None else 0.0
        lost_share = self.lost_time_s() / span if span > 0 else 0.0
        matched = max(scans / self.pcfg.frontend_every, 1.0)
        # scans a particle filter waited for motion on (nav2's update_min_d 0.25 m: most of a slow robot's) tried
        # no match: they say nothing about the map
        waiting = sum(n for kind, n in self.no_fix_reasons.items() if WAITING_FOR_MOTION in kind)
        where = f"{scans} scans ({100 * used / matched:.1f} % of those matched)"
        if waiting:
            matched = max(float(self.stats["fixes"]) + float(self.stats["no_fix"]) - waiting, 1.0)
            where = (f"the {matched:.0f} of {scans} scans a match was tried on ({100 * used / matched:.1f} %; the "
                     f"front-end waited for motion on {waiting})")
        ag = self.agreement
        mj = self.map_jumps
        if lost_share >= MISMATCH_LOST_SHARE and used < MISMATCH_MATCHED_SHARE * matched:
            # the fixes it did accept were places in another building: no pose of the run is known
            self._unusable("map_mismatch", "lost: this map does not fit this log",
                f"this map does not fit this log: the scans matched it {used} times in {where} and "
                f"the localizer was lost {100 * lost_share:.0f} % of the run (is it the map of this building, its "
                "right version?)")
        elif ag is not None and ag.never_fit():
            # a front-end that converges anywhere (a particle filter) gave fixes the back-end took, but the scan
            # lay nowhere near the map's walls at the poses they made: places in another building
            self._unusable("map_mismatch", "lost: this map does not fit this log",
                f"this map does not fit this log: the scan lay on its walls (agreement "
                f"{ag.MISFIT:.2f} or more) in {ag.judged_checks - ag.misfit_checks} of {ag.judged_checks} checks at "
                "the fused pose (is it the map of this building, its right version?)")
        elif mj is not None and mj.repeated and mj.worst is not None and mj.closest_s is not None:
            # a kidnapping moves the robot once; a map whose geometry is not the building's (mirrored, at another
            # scale, another building) relocalizes it again and again, or turns it where its wheels went straight
            tj, e_m, e_rad, path = mj.worst
            into = tj - (self._first_scan_t if self._first_scan_t is not None else tj)
            alike = self._places_alike()
            if alike is not None:
                # every jump ended a global search, and the map fits the scans where the poses were right: a map
                # with places alike (a symmetric room) the search could not tell apart, not a map that does not fit
                share, n = alike
                self._unusable("ambiguous", "lost: could not tell where in the map the robot is",
                    f"could not tell where in the map the robot is: its global search settled "
                    f"{mj.events} times where the odometry did not take the robot, two of them {mj.closest_s:.1f} s "
                    f"apart (worst {e_m:.1f} m / {math.degrees(e_rad):.0f} deg off the odometry's motion {into:.1f} s "
                    f"into the run), while the map fits the laser where the poses were ok ({100 * share:.0f} % of "
                    f"its ranges within 10 % of the map's, median over {n} scans): the map has places alike; "
                    + ("give an initial pose (--initial-pose)" if self.initial_pose is None else
                       "the robot was lost after its initial pose, and a global search cannot tell them apart"))
                return
            self._unusable("map_mismatch", "lost: this map does not fit this log",
                f"this map does not fit this log: it put the robot {mj.events} times where its "
                f"odometry did not take it, two of them {mj.closest_s:.1f} s apart (a kidnapping does it once; worst "
                f"{e_m:.1f} m / {math.degrees(e_rad):.0f} deg off the odometry's motion {into:.1f} s into the run, "
                f"{path:.1f} m driven since the placement before) (is it the map of this building, its right "
                "version, at its scale?)")
        elif ag is not None and (rm := ag.range_misfit()) is not None:
            # the front-end fit the scan somewhere (a particle filter converges anywhere), but ray-cast from the
            # poses the localizer called ok most of the map's ranges are not the laser's
            share, k = rm
            ratio = f"its distances are {k:.1f} times the laser's: " if abs(math.log(k)) > math.log(1.5) else ""
            self._unusable("map_mismatch", "lost: this map does not fit this log",
                f"this map does not fit this log: {ratio}ray-cast in it from the poses called ok, "
                f"{100 * share:.0f} % of the laser's ranges are within 10 % of the map's (median over "
                f"{len(ag.range_samples)} scans; a right map: 60 % and more): check the map's resolution (is it "
                "the map of this building?)")
        elif ag is not None and (bw := ag.beyond_walls()) is not None:
            # the front-end tracked a place where the scan fits in part (a near-symmetric building's map mirrored:
            # the corridors fit), but where the map has walls the laser kept seeing further: they are not there
            share, n = bw
            self._unusable("map_mismatch", "lost: this map does not fit this log",
                f"this map does not fit this log: ray-cast in it from the poses called ok, "
                f"{100 * share:.0f} % of the laser's ranges end more than 10 % beyond the map's walls (median over "
                f"{n} scans; a right map with people and moved furniture: 10 % or less): the laser sees through "
                "walls the map has (is it the map of this building, not mirrored, its right version?)")
        turned = self._laser_turned()
        if turned is not None and not any(v.unusable for v in self.monitor.verdicts):
            # the map confirmed the positions, but the heading of every one is the laser's, turned on its bracket
            a, n = turned
            self.monitor.amend(-math.inf, math.inf, SUSPECT,
                               f"suspect: the laser looks turned {a:+.1f} deg from its tf")
            self.monitor.verdict(
                "laser_mount", f"the laser's mount does not fit its tf: driving straight, the fixes moved at "
                f"{-a:+.1f} deg to the odometry's course (median over {n} stretches of {FixCourse.MIN_M:.0f} m or "
                f"more): the laser looks turned {a:+.1f} deg (counter-clockwise +) from where the tf base_link -> "
                "laser says, every pose's heading as far off (check the mount: --static-transform, the URDF)", True)
