"""The online localizer: a scan-to-map front-end feeding a back-end (EKF or smoother).

:class:`Localizer` is what a :class:`~fgloc.localization.session.Session` drives (``fgloc
run`` offline, ``fgloc live`` on a robot, the benches), one message at a time:

* ``on_odometry`` - wheel twist -> back-end (encoder factor / update); the dead-reckoned
  odom pose for the front-end's ``odom_delta`` (:mod:`fgloc.localization.odometry`);
* ``on_compass`` - compass heading -> back-end (the back-end owns the compass offset);
* ``on_scan`` - tracking: the front-end matches the scan from the back-end's predicted
  pose; the fix (if any) and a keyframe at the scan stamp go to the back-end.  Returns
  the fix; :attr:`last_reason` says why there was none.

Start-up: with ``initial_pose`` the first scan is matched from it.  Without, the
localizer searches globally: a front-end with its own global mode (``supports_global``,
AMCL) spreads its particles and the first fix with a small covariance is taken; for the
others the correlative search of :mod:`fgloc.localization.relocalization` runs, its best
candidates refined by the front-end.  After ``relocalize_after`` scans in a row without
an accepted fix (kidnapping, or lost), the relocalizer looks again and the back-end is
reset to a confirmed candidate.

Without a map (``occ_map=None``) encoder and compass are fused alone in an ``odom`` frame
that starts at the origin with the compass heading (as robot_localization's odom-frame EKF
does with an absolute IMU yaw); keyframes are placed at scan stamps when there are scans,
else every ``odom_keyframe_interval_s``.

Robustness: every input is checked; a NaN/inf stamp or value, or a stamp that goes
backwards on its own stream, is counted in ``stats['skipped']`` and ignored, never raised.
Messages slightly out of order across streams are fine (the back-ends wait for odometry up
to a keyframe's stamp).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from fgloc.backends import make_backend
from fgloc.backends.base import Backend, Capability, FloatArray
from fgloc.geometry import between1, compose1
from fgloc.geometry import exp as se2_exp
from fgloc.localization.clock import OdometryClock
from fgloc.localization.coverage import UNMAPPED_SHARE, unmapped_share
from fgloc.localization.gate import GateVerdict, JumpGate, OdometryCoverage, agreement_sigma
from fgloc.localization.monitor import ConsistencyMonitor, DeadReckoning, MapAgreement
from fgloc.localization.odometry import OdometryTracker
from fgloc.localization.recovery import EPS_COV, Recovery
from fgloc.localization.relocalization import Relocalizer, close
from fgloc.maps import OccupancyMap
from fgloc.types import CompassHeading, LaserScan, Odometry, PoseFix, StaticTransform, Trajectory

if TYPE_CHECKING:
    from fgloc.config import FglocConfig

COMPASS_TRUST_FIXES = 3  # accepted tracking fixes before the compass offset filters global candidates
#: the scan-agreement monitor's distance scale, in the jump gate's (the map's cell): it asks whether the pose is
#: wrong, not a few centimetres or a tenth of a degree off (a far wall's endpoints move with the heading)
AGREEMENT_MONITOR_SCALE = 2.0
MAX_REASON_KINDS = 8  # the no-fix summary lists at most this many kinds, the rest as "other"
def reason_kind(reason: str) -> str:
    """The kind of a no-fix reason: details in parentheses dropped (nested ones whole), numbers as N
    ("update thresholds not met (moved 0.064 m ...)" -> "update thresholds not met")."""
    r = str(reason)
    while (inner := re.sub(r"\([^()]*\)", "", r)) != r:  # the innermost first
        r = inner
    r = re.sub(r"\(.*", "", r).replace(")", "")  # an unclosed one: to the end
    r = re.sub(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?", "N", r)
    r = re.sub(r"\s+", " ", r)
    r = re.sub(r" ([,;:])", r"\1", r).strip(" :,;.")
    return r[:70] or "no fix"


def group_reasons(counts: dict[str, int], max_kinds: int = MAX_REASON_KINDS) -> dict[str, int]:
    """The most frequent kinds, the rest summed as ``other (k kinds)``; most frequent first."""
    items = sorted(counts.items(), key=lambda kv: -kv[1])
    out = dict(items[:max_kinds])
    rest = items[max_kinds:]
    if rest:
        out[f"other ({len(rest)} kinds)"] = sum(v for _, v in rest)
    return out


class Localizer(Recovery):
    """Online localization from odometry, compass and scans (see the module docstring).

    ``config``: the :class:`~fgloc.config.FglocConfig` (``None``: the defaults; a mapping is
    checked like a YAML file).  ``frontend_name`` is ``"none"`` without a map.
    """

    def __init__(self, occ_map: OccupancyMap | None, laser_mount: StaticTransform,
                 backend: str = "smoother", frontend: str = "native",
                 initial_pose: np.ndarray | None = None, config: FglocConfig | Any = None) -> None:
        from fgloc.config import parse_config

        config = parse_config(config)
        self.config = config
        self.pcfg = config.pipeline
        self.map = occ_map
        self.laser_mount = laser_mount
        self.backend_name = backend
        self.backend: Backend = make_backend(backend, config)
        self._measures_velocity = Capability.MEASURES_VELOCITY in self.backend.capabilities  # (the EKF's; asked once)
        self.frontend: Any = None
        if occ_map is not None:
            from fgloc.frontends import make_frontend

            self.frontend = make_frontend(frontend, occ_map, laser_mount, config)
        self.frontend_name = self.frontend.name if self.frontend is not None else "none"
        self.initial_pose = None if initial_pose is None else np.asarray(initial_pose, dtype=float).reshape(3)
        self.odom_mode = occ_map is None
        self.stats: dict[str, Any] = {
            "scans": 0, "odometry": 0, "compass": 0, "fixes": 0, "no_fix": 0, "rejected": 0,
            "gated": 0, "skipped": 0, "skipped_reasons": {}, "relocalizations": 0, "global_searches": 0,
        }
        self.no_fix_reasons: dict[str, int] = {}
        self.fixes: list[PoseFix] = []
        self.history_s: float | None = None  # keep_history()
        self.last_reason = ""
        self.odom = OdometryTracker(self.pcfg)
        # a slow odometry's stamps on the scans' clock (clock.py: its offset estimated from the fixes), for
        # a back-end that integrates the increments between keyframes (not the EKF, which filters at them)
        self.clock = OdometryClock() if (config.smoother.odom_clock and occ_map is not None
                                         and Capability.ODOMETRY_CLOCK in self.backend.capabilities) else None
        self.reloc: Relocalizer | None = None
        if self.frontend is not None and occ_map is not None:
            self.reloc = Relocalizer(self.pcfg, occ_map, laser_mount, self.frontend, self.backend, self.stats)
        # no jumps (gate.py) and a status for every pose (monitor.py)
        self.icfg = config.integrity
        self.monitor = ConsistencyMonitor(self.icfg)
        self.gate = JumpGate(self.icfg, occ_map, laser_mount) if occ_map is not None and self.icfg.gate else None
        self.odometry_coverage = OdometryCoverage(self.icfg.odometry_gap_s)  # the odometry's stamps, for the gate
        # the scan's agreement with the map at the fused pose, against this run's own good level (monitor.py)
        self.agreement = None if occ_map is None else MapAgreement(
            self.icfg, occ_map, laser_mount,
            AGREEMENT_MONITOR_SCALE * agreement_sigma(occ_map, self.icfg.agreement_sigma_m))
        self.last_gate: GateVerdict | None = None  # the gate's verdict on the last scan's fix (None: not judged)
        self._gate_prediction: tuple[FloatArray, FloatArray] | None = None  # the prediction it judged against
        self._cov_t = -math.inf  # stamp of the last back-end covariance the gate asked for
        self._guess_prediction: tuple[float, tuple[FloatArray, FloatArray]] | None = None  # guess(): (t, predict(t))
        self._timing_unknown: bool | None = None  # what the back-end was last told of the odometry's timing
        self._t_used: float | None = None  # stamp of the last fix the back-end accepted
        self._t_held_since: float | None = None  # first fix of the current run of held / rejected ones
        self._rejected_run = 0  # fixes the gate passed and the back-end rejected since it last took one
        self._converged = False  # the pose was started from a fix, or a fix was accepted since
        # odom frame: the fused path against odometry + IMU dead reckoning (a diverging configuration)
        self.dead_reckoning = DeadReckoning() if self.odom_mode else None
        self._divergence: tuple[float, float, float] | None = None  # (m, m driven, limit m) when over the limit
        self._worst_divergence: tuple[float, float, float, float, float] | None = None  # ratio, m, driven, limit, t
        self._divergence_t = -math.inf
        self._ever_converged = False
        self._heading_diverged_s = 0.0  # the back-end's heading_diverged_s counter when last seen growing
        self._heading_diverged_t = -math.inf  # ... and the stamp then
        self.stats["held_jumps"] = self.stats["confirmed_jumps"] = 0
        #: called with the stamp of each pose added without a scan (a silent laser): Session tells its sinks
        self.pose_listener: Callable[[float], None] | None = None
        self._last_stamp: dict[str, float] = {}
        self._odom_at_last_scan: FloatArray | None = None
        self._last_matched_t: float | None = None
        self._bad_streak = 0
        self._global_tries = 0
        self._failed_search = None
        self._last_compass: tuple[float, float] | None = None
        self._last_kf_t = -math.inf
        self._last_dr_t = -math.inf
        self._scan_count = 0
        self._lost = initial_pose is None and not self.odom_mode
        self._reinit: FloatArray | None = None  # reinitialize(): the prior of the pose to start again from
        self._t_bad_since: float | None = None  # first informative scan of the current no-fix streak
        self._dead_reckoned_since: float | None = None  # first scan outside the map since the last used fix
        self._reacquiring = False  # back on the map after dead reckoning: fixes checked globally
        self._lost_since: float | None = None  # start of the current lost interval
        self._lost_total_s = 0.0
        self._used_fixes = 0  # fixes the back-end accepted while tracking
        # a fix accepted since the last (re)start: only a confirmed pose dead-reckons through unmapped space
        self._pose_confirmed = False
        self._t_started: float | None = None  # when the pose was last (re)started
        self._last_scan_t: float | None = None
        self._first_scan_t: float | None = None
        self.stats["lost_events"] = 0
        if self._lost and self.frontend is not None and self.frontend.supports_global:
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
        pose = None if msg.pose is None else np.asarray(msg.pose, dtype=float).reshape(-1)
        self.odometry_values(float(msg.stamp), np.asarray(msg.twist, dtype=float).reshape(-1), msg.twist_cov, pose)

    def odometry_values(self, t: float, tw: FloatArray, cov: FloatArray | None, pose: FloatArray | None,
                        cov_finite: bool | None = None) -> None:
        """:meth:`on_odometry` on a message's values (``cov_finite``: whether ``cov`` is all finite, if known)."""
        t_raw = t
        twl = tw.tolist() if tw.shape == (3,) else None
        if twl is None or not math.isfinite(sum(twl)):
            self._skip("odometry: non-finite twist")
            return
        if not self._monotonic("odometry", t):
            return
        if self.clock is not None:
            t = self.clock.stamp(t_raw)
        self.stats["odometry"] += 1
        self.odometry_coverage.add(t)
        if self.odom.t is not None and t <= self.odom.t:
            # at or before the stamp carried to after a burst (carry_to): the next increment covers it
            self.stats["odometry_folded"] = self.stats.get("odometry_folded", 0) + 1
            return
        tw, cov = self.odom.step(t, tw, cov, pose, cov_finite, twl)  # (the pose's and covariance's checks)
        if self.clock is not None:
            self.clock.add_odometry(t_raw, float(self.odom.pose[2]))
            # stamps in bursts: no offset places them, the back-end carries their timing variance
            unknown = self.clock.slow and not self.clock.regular
            if unknown != self._timing_unknown:
                self._timing_unknown = unknown
                self.backend.set_odometry_timing_unknown(unknown)
        if self.odom.from_poses:
            self.stats["odometry_from_poses"] = self.odom.from_poses
        vm: tuple[FloatArray, FloatArray | None] | None = (tw, cov)
        if self._measures_velocity:  # the EKF: a bursty source's velocity (a smoother integrates its increments)
            vm = self.odom.velocity_measurement()
            if vm is None:  # the first burst of a stream: no velocity known, none measured
                self.stats["odometry_burst_skipped"] = self.stats.get("odometry_burst_skipped", 0) + 1
            elif vm[0] is not tw:
                tw, cov = vm
                self.stats["odometry_burst_velocities"] = self.stats.get("odometry_burst_velocities", 0) + 1
        if vm is not None:
            self.backend.add_odometry(t, tw, cov)
        if self.dead_reckoning is not None:
            self.dead_reckoning.odometry(t, tw)
        if self.odom_mode:
            self._odom_mode_step(t, scan=False)
        elif self._last_scan_t is not None and t - self._last_scan_t >= self.icfg.laser_silent_after_s:
            self._dead_reckon(t)  # the laser silent: a dead-reckoned pose when due

    def on_compass(self, msg: CompassHeading) -> None:
        self.compass_values(float(msg.stamp), msg.yaw_rad, msg.yaw_var, msg.yaw_rate_radps, msg.yaw_rate_var)

    def compass_values(self, t: float, yaw: float | None, yaw_var: float, rate: float | None, rate_var: float) -> None:
        """:meth:`on_compass` on a reading's values (yaw and rate None when not given)."""
        yaw = yaw if yaw is not None and math.isfinite(yaw) else None
        rate = rate if rate is not None and math.isfinite(rate) else None
        if yaw is None and rate is None:
            self._skip("compass: no finite heading or rate")
            return
        if not self._monotonic("compass", t):
            return
        self.stats["compass"] += 1
        if self.dead_reckoning is not None:
            self.dead_reckoning.reading(t, yaw, rate)
        if yaw is not None:
            self._last_compass = (t, float(yaw))
            if self.reloc is not None:
                self.reloc.last_compass = self._last_compass
        self.backend.add_compass(t, yaw, float(yaw_var), rate, float(rate_var))

    def on_scan(self, msg: LaserScan) -> PoseFix | None:
        """Track one scan; the front-end's fix, or None (:attr:`last_reason` says why)."""
        t = float(msg.stamp)
        self.last_reason = ""
        self.last_gate = None
        if not self._monotonic("scan", t):
            self.last_reason = "scan skipped (bad or repeated stamp)"
            return None
        fix = self._on_scan(msg, t)
        self._record_status(t)
        return fix

    def _on_scan(self, msg: LaserScan, t: float) -> PoseFix | None:
        self.stats["scans"] += 1
        self._last_scan_t = t
        if self._first_scan_t is None:
            self._first_scan_t = t
        if self.backend.initialized and not self._measures_velocity:
            # after a burst of odometry stamps a back-end that integrates the increments (the smoother)
            # is handed the plausible velocity up to this scan: its prediction here, its gate on this
            # scan's fix and its online pose hold that, not the burst's twist
            carried = self.odom.carry_to(t)
            if carried is not None:
                self.backend.add_odometry(t, carried[0], carried[1])
                self.stats["odometry_carried"] = self.odom.carried
        if self.odom_mode:
            self._odom_mode_step(t, scan=True)
            self.last_reason = "no map"
            return None
        if self._lost and self._lost_since is None:
            self._lost_since = t  # no pose yet: lost from the first scan until the first fix
        fe = self.frontend
        matching = self.backend.initialized and not self._lost
        if matching:
            self._scan_count += 1
            if self._scan_count % self.pcfg.frontend_every != 0:
                # not matched: no keyframe either, the online pose is the odometry prediction
                self.backend.record_prediction(t)
                self.last_reason = "not matched (frontend_every)"
                return None
        # odometry motion since the previous front-end call (for its de-skew / motion model): a particle filter
        # keeps it as it came (its motion model and thresholds were tuned on that), the others at the scan stamp
        odom_now = self.odom.pose if fe.is_particle_filter else self.odom.pose_at(t)
        odom_delta = None  # a particle filter without any odometry yet: its motion is unknown (None)
        if self._odom_at_last_scan is not None and (self.stats["odometry"] or not fe.is_particle_filter):
            odom_delta = between1(self._odom_at_last_scan, odom_now)
            if not fe.is_particle_filter and self._last_matched_t is not None:
                # as the back-end believes it moved (the odometry's scales, a gyro's rotation)
                corrected = self.backend.motion_correction(self._last_matched_t, t, odom_delta)
                if self.gate is not None:  # the gate asks for it again when its previous fix is the last scan's
                    self.gate.known_motion = (self._last_matched_t, t, odom_delta.tobytes(), np.array(corrected, float))
                odom_delta = corrected
        self._odom_at_last_scan = np.array(odom_now, dtype=float)
        self._last_matched_t = t
        if not matching:
            gfix = self._localize_globally(msg, odom_delta)
            if gfix is None:  # a scan without a fix while not localized: counted with its reason
                self.stats["no_fix"] += 1
                kind = reason_kind(self.last_reason)
                self.no_fix_reasons[kind] = self.no_fix_reasons.get(kind, 0) + 1
            return gfix
        guess = self.guess(t)
        res = fe.match(msg, guess, odom_delta)
        fix = res.to_fix(t, fe.name)
        # no fix where the map has nothing (an unmapped wing): dead reckoning, not evidence of being lost
        unmapped = False
        if fix is None and self._pose_confirmed and not fe.is_particle_filter and self.map is not None:
            share = unmapped_share(self.map, self.laser_mount, msg, guess)
            unmapped = share > UNMAPPED_SHARE
        if unmapped and self._dead_reckoned_since is None:
            self._dead_reckoned_since = t
        elif not unmapped and self._dead_reckoned_since is not None and not fe.is_particle_filter and \
                int(np.count_nonzero(msg.valid_mask())) >= 30:
            if t - self._dead_reckoned_since >= self.pcfg.lost_after_s:
                self._reacquiring = True
                self.stats["reacquisitions"] = self.stats.get("reacquisitions", 0) + 1
            self._dead_reckoned_since = None
        res_why = res.why
        if self._reacquiring and fix is not None and self.reloc is not None:
            # back where the map speaks after lost_after_s of dead reckoning through space it does not
            # have: the odometry may have drifted past the front-end's window, whose best match near
            # the guess is then a wrong place (mit-csail: fixes 1-2.6 m off with centimetre sigmas).
            # A tracking fix that an unambiguous global candidate beats by relocalize_margin is held
            # back; one the best candidate agrees with ends the re-acquisition
            cands = self.reloc.candidates(msg)
            if cands and cands[0][0] >= self.pcfg.global_min_quality and not self.reloc.ambiguous(cands):
                best_q, best = cands[0]
                if close(best.pose, fix.pose, 0.3, math.radians(5.0)):
                    self._reacquiring = False
                elif best_q >= fix.quality + self.pcfg.relocalize_margin:
                    self.stats["held_fixes"] = self.stats.get("held_fixes", 0) + 1
                    fix = None
                    res_why = (f"re-acquiring the map after dead reckoning: a place {best_q:.2f} explains the "
                               "scan better than the tracked one")
        if fix is not None:
            self._keep_fix(fix)
            self.stats["fixes"] += 1
        else:
            self.stats["no_fix"] += 1
            self.last_reason = res_why
            if unmapped:
                self.stats["unmapped_scans"] = self.stats.get("unmapped_scans", 0) + 1
                self.last_reason = (f"outside the map: the beams end in unmapped space ({100 * share:.0f} %), "
                                    f"dead reckoning ({res.why})")
            kind = reason_kind(self.last_reason)
            self.no_fix_reasons[kind] = self.no_fix_reasons.get(kind, 0) + 1
        held = False
        if fix is not None and self.gate is not None:
            fitted = not (fe.is_particle_filter and fe.estimate == "refined" and not res.info.get("refined"))
            verdict = self._gate(t, fix, msg, None if fe.is_particle_filter else odom_now, fitted)
            if not verdict.take:
                held = True
                self.stats["held_jumps"] += 1
                self.last_reason = verdict.why
                if self._held_run_confirms(t):
                    # a pose no fix has confirmed since it was (re)started (a particle cloud that converged on
                    # the wrong mode) holds every right fix after it: a run of them that follow each other as
                    # the odometry says, as long as a relocalization is confirmed, says the start was wrong
                    self.stats["held_run_restarts"] = self.stats.get("held_run_restarts", 0) + 1
                    self.stats["relocalizations"] += 1
                    if self._lost_since is None:
                        self._lost_since = self._t_started
                    self.stats["fixes_used"] = self.stats.get("fixes_used", 0) + 1
                    self._start(t, fix.pose, fix.cov + EPS_COV)
                    return fix
            elif verdict.confirmed:
                self.stats["confirmed_jumps"] += 1
        kf_fix = None if held else fix
        used = self.backend.add_keyframe(t, kf_fix)
        if used and kf_fix is not None and self.clock is not None:
            self.clock.add_fix(t, float(kf_fix.pose[2]))
        if kf_fix is not None and not used:
            self.stats["rejected"] += 1
            self.last_reason = "fix rejected by the back-end"
        if self.gate is not None and kf_fix is not None:
            # the gate passed it: the fixes that follow it as the odometry says are no jumps, whether the
            # back-end used it or its own tighter gate held it, within limits (JumpGate.settled; gate.py)
            self.gate.settled(used, self._pose_confirmed, msg)
        if kf_fix is not None and not used and self._map_confirms_rejected(kf_fix, msg):
            # a jump the map confirms (gate.py) is no outlier for the back-end's own gate to veto: a filter
            # sure of a wrong place (started on a particle cloud that converged there) rejects every right
            # fix after it.  The back-end starts again at the fix, the poses since it last took one were wrong
            self.stats["confirmed_restarts"] = self.stats.get("confirmed_restarts", 0) + 1
            self.stats["relocalizations"] += 1
            if self._lost_since is None and self._t_used is not None:
                self._lost_since = self._t_used
            self._start(t, kf_fix.pose, kf_fix.cov + EPS_COV)
            used = True
        if used:
            self._rejected_run = 0
        elif kf_fix is not None:
            self._rejected_run += 1
        if used:
            self._t_used = t
            self._converged = True
            self._ever_converged = True
            self._t_held_since = None
            self.stats["fixes_used"] = self.stats.get("fixes_used", 0) + 1
            if self.last_gate is not None:
                self.monitor.add_nis(self.last_gate.d2)
        elif fix is None:
            if not fe.is_particle_filter:  # a particle filter's scan without an update is no evidence either way
                self._t_held_since = None
        elif self._t_held_since is None:
            self._t_held_since = t  # the map points elsewhere than the back-end goes
        # a scan with too few returns (blackout, blocked laser) says nothing about being lost; neither does a
        # particle filter skipping an update (its motion thresholds) or converging again after its own recovery
        # (it counts only when the back-end rejects its fix), nor a fix the jump gate held back (gate.py)
        if held:
            informative = False
        elif fe.is_particle_filter:
            informative = fix is not None
        else:
            informative = fix is not None or (int(np.count_nonzero(msg.valid_mask())) >= 30 and not unmapped)
        if used:
            self._bad_streak = 0
            self._t_bad_since = None
            self._dead_reckoned_since = None
            assert self.reloc is not None
            self.reloc.pending = None
            self._used_fixes += 1
            self._pose_confirmed = True
            self.reloc.trust_compass = self._used_fixes >= COMPASS_TRUST_FIXES
        elif informative:
            self._bad_streak += 1
            if self._t_bad_since is None:
                self._t_bad_since = t
        if self._agreement_check(t, msg) >= self.icfg.agreement_lost_s and \
                self._agreement_lost(t, msg, res, odom_delta):
            return fix
        if self._bad_streak >= self.pcfg.relocalize_after:
            if fe.supports_global:
                self._declare_lost(t)
                self.stats["relocalizations"] += 1
                fe.reset(None)
            elif self._t_bad_since is not None and t - self._t_bad_since >= self.pcfg.lost_after_s:
                # no accepted fix for lost_after_s: tracking is hopeless (a wrong initial pose, a
                # kidnapping the relocalization could not confirm): search globally as at start-up
                self._declare_lost(t)
            else:
                assert self.reloc is not None
                found = self.reloc.check(msg, res, odom_delta)
                if found is not None:
                    self.stats["relocalizations"] += 1
                    if self._lost_since is None:  # the pose was wrong since the streak began
                        self._lost_since = self._t_bad_since
                    self._start(t, found.pose, found.cov + EPS_COV)
        return fix

    def _gate(self, t: float, fix: PoseFix, msg: LaserScan, odom_pose: FloatArray | None = None,
              fitted: bool = True) -> GateVerdict:
        """The jump gate's verdict on ``fix`` at scan stamp ``t`` (gate.py); ``odom_pose``: the odometry's there."""
        assert self.gate is not None
        guessed, self._guess_prediction = self._guess_prediction, None
        if (t - self._cov_t >= self.icfg.covariance_period_s or t < self._cov_t) and \
                Capability.STATE_COVARIANCE not in self.backend.capabilities:
            # a smoother's marginal on demand (else the gate judges against the start prior the whole run): it
            # starts the prediction's covariance (a filter's is its state: the guess's prediction stands)
            self.backend.current(covariance=True)
            self._cov_t = t
            guessed = None
        # the guess's prediction when it was the back-end's at this stamp (nothing was fed in since)
        pred, pred_cov = guessed[1] if guessed is not None and guessed[0] == t else self.backend.predict(t)
        self._gate_prediction = (pred, pred_cov)
        # the motion since the last accepted fix is known where the odometry's stamps cover it (gate.py)
        prev = self.gate.previous
        t_from = prev.t if prev is not None else self._t_used if self._t_used is not None else t
        if odom_pose is None:
            odom_pose = self.odom.pose_at(t)
        verdict = self.gate.check(fix, pred, pred_cov, msg, odom_pose, t, self.backend.motion_correction,
                                  motion_known=self.stats["odometry"] > 0,
                                  motion_covered=self.odometry_coverage.covers(min(t_from, t), t), fitted=fitted)
        self.last_gate = verdict
        return verdict

    def guess(self, t: float) -> FloatArray:
        """The pose guess for the front-end at scan stamp ``t``: the back-end's prediction.

        After a burst of odometry stamps (:attr:`OdometryTracker.burst`: the last twist came from a
        pose increment far shorter than the odometry's period, intel's 240 m/s over 169 us) the
        back-end's prediction holds that twist past its last odometry stamp; then the guess is the
        back-end's pose at the last stamp it has (the last odometry message's, or its own newer
        state's), carried on to ``t`` with the tracker's plausible velocity
        (:meth:`OdometryTracker.extrapolation_twist`, as the back-end believes it moved:
        :meth:`Backend.motion_correction`) over at most ``odom_extrapolate_max_s`` (as the odom pose)."""
        odom_t = self.odom.t
        self._guess_prediction = None
        if not self.odom.burst or odom_t is None or t <= odom_t:
            self._guess_prediction = (t, self.backend.predict(t))
            return self._guess_prediction[1][0]
        cur = self.backend.current(covariance=False)
        t_a = odom_t if cur is None else max(odom_t, float(cur[0]))
        if t <= t_a:
            self._guess_prediction = (t, self.backend.predict(t))
            return self._guess_prediction[1][0]
        pose_a, _ = self.backend.predict(t_a)
        dt = min(t - t_a, self.pcfg.odom_extrapolate_max_s)
        if not dt > 0:
            return pose_a
        d = se2_exp(self.odom.extrapolation_twist() * dt)
        d = self.backend.motion_correction(t_a, t_a + dt, d)
        self.stats["burst_guesses"] = self.stats.get("burst_guesses", 0) + 1
        return compose1(pose_a, d)

    # ------------------------------------------------------------------ outputs
    def current(self, covariance: bool = True, at: float | None = None) -> PoseFix | None:
        """Latest fused pose and covariance, predicted to the newest odometry stamp, or to ``at`` (the
        scan just fused) when that is newer: with the odometry silent the pose of each scan is still
        its own, never the last keyframe's again.  ``covariance=False``: the back-end's last computed
        covariance (plus the odometry noise since), not a fresh marginal (see
        :class:`fgloc.localization.session.Session`)."""
        cur = self.backend.current(covariance)
        if cur is None:
            return None
        t, pose, cov = cur
        newest = max(self.odom.t if self.odom.t is not None else -math.inf,
                     at if at is not None and math.isfinite(at) else -math.inf)
        if newest > t:
            pose, cov = self.backend.predict(newest)
            t = newest
        cov = self.backend.output_covariance(t, pose, cov)
        return PoseFix(t, pose, cov, source=self.backend_name, frame_id="odom" if self.odom_mode else "map",
                       status=self.monitor.current[0])

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
            self.stats["no_fix_reasons"] = group_reasons(self.no_fix_reasons)
        if self.clock is not None:
            self.stats["odom_clock"] = self.clock.summary()
        if not self.odom_mode:
            self.stats["lost_s"] = self.lost_time_s()
            self.stats["ended_lost"] = bool(self._lost)
        self._assess()
        self.stats["status"] = self.monitor.summary(tr.stamps)
        return tr

    def keep_history(self, seconds: float | None) -> None:
        """Keep the run-long records (the accepted fixes, the back-end's online trajectory and smoothed
        keyframes) only ``seconds`` back; None: the whole run.  A live session that writes none of them
        runs for days in bounded memory (:meth:`finish` then smooths the last ``seconds``)."""
        self.history_s = seconds
        self.backend.history_s = seconds
        self.monitor.history_s = seconds

    def _keep_fix(self, fix: PoseFix) -> None:
        self.fixes.append(fix)
        h = self.history_s
        if h is not None and fix.stamp - self.fixes[0].stamp > 2.0 * h:  # amortized: once twice the history
            self.fixes = [f for f in self.fixes if f.stamp >= fix.stamp - h]

    def fixes_trajectory(self) -> Trajectory:
        """The front-end's fixes as a trajectory (map frame)."""
        if not self.fixes:
            return Trajectory(np.zeros(0), np.zeros((0, 3)))
        return Trajectory.from_unsorted(np.array([f.stamp for f in self.fixes]),
                                        np.array([f.pose for f in self.fixes]))
