"""Start-up and recovery of the :class:`~fgloc.localization.localizer.Localizer` (:class:`Recovery`,
one of its bases): the start pose or the global search, (re)starting the back-end on a fix, being lost,
an operator's new start pose, a new map.

Core maths only: no I/O.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from fgloc.backends.base import FloatArray
from fgloc.geometry import between1
from fgloc.localization.gate import GateVerdict, JumpGate
from fgloc.localization.monitor import LOST, MapAgreement
from fgloc.localization.relocalization import Relocalizer, close, place_near
from fgloc.localization.status import PoseStatus
from fgloc.maps import OccupancyMap
from fgloc.types import LaserScan, PoseFix, StaticTransform

if TYPE_CHECKING:
    from fgloc.config import FglocConfig

EPS_COV = np.diag([1e-6, 1e-6, 1e-6])  # added to a fix's covariance when the back-end is (re)started on it


class Recovery(PoseStatus):
    """Start-up and recovery of :class:`~fgloc.localization.localizer.Localizer` (its ``__init__`` sets
    the state below)."""

    config: FglocConfig
    map: OccupancyMap | None
    laser_mount: StaticTransform
    frontend: Any
    frontend_name: str
    reloc: Relocalizer | None
    gate: JumpGate | None
    agreement: MapAgreement | None
    last_gate: GateVerdict | None
    _gate_prediction: tuple[FloatArray, FloatArray] | None
    guess: Callable[[float], FloatArray]
    _keep_fix: Callable[[PoseFix], None]
    _reinit: FloatArray | None
    _global_tries: int
    _failed_search: tuple[float, FloatArray] | None  # (t, odometry pose) of the last global search that found nothing
    _bad_streak: int
    _t_bad_since: float | None
    _dead_reckoned_since: float | None
    _reacquiring: bool
    _pose_confirmed: bool
    _ever_converged: bool

    def reinitialize(self, pose: FloatArray, cov: FloatArray | None = None) -> None:
        """Start again from ``pose`` (an operator's estimate in the map: RViz's 2D Pose Estimate on
        /initialpose): the next scan is matched from it as from an initial pose, and the back-end is
        restarted on that fix (on ``pose`` with ``cov``, default the initial-pose prior, when none)."""
        if self.odom_mode:
            return
        self.initial_pose = np.asarray(pose, dtype=float).reshape(3)
        self._reinit = self._initial_cov() if cov is None else np.asarray(cov, dtype=float).reshape(3, 3)
        self._lost = True
        self.stats["reinitializations"] = self.stats.get("reinitializations", 0) + 1

    def replace_map(self, occ_map: OccupancyMap, frontend: Any = None) -> None:
        """Localize on ``occ_map`` from the next scan on (a map server's new map): its front-end
        (``frontend``, built by the caller off the fusion thread, else here) and the relocalizer on it.
        The pose and the back-end go on; :meth:`reinitialize` starts again from a pose on the new map
        (a particle filter front-end starts there too, or spreads its particles while lost)."""
        if self.odom_mode:
            raise ValueError("an odom-frame session has no map to replace")
        if frontend is None:
            from fgloc.frontends import make_frontend

            frontend = make_frontend(self.frontend_name, occ_map, self.laser_mount, self.config)
        self.map = occ_map
        self.frontend = frontend
        self.reloc = Relocalizer(self.pcfg, occ_map, self.laser_mount, frontend, self.backend, self.stats)
        self._failed_search = None  # a new map: search it at once
        if self._lost and frontend.supports_global:
            frontend.reset(None)
        self.stats["map_changes"] = self.stats.get("map_changes", 0) + 1

    def _initial_cov(self) -> FloatArray:
        sxy = self.pcfg.initial_sigma_xy_m
        syaw = math.radians(self.pcfg.initial_sigma_yaw_deg)
        return np.diag([sxy**2, sxy**2, syaw**2])

    def _declare_lost(self, t: float) -> None:
        self._lost = True
        if self.agreement is not None:
            self.agreement.reset()
        self._reacquiring = False
        self._global_tries = 0
        self._failed_search = None
        self.stats["lost_events"] += 1
        if self._lost_since is None:
            self._lost_since = self._t_bad_since if self._t_bad_since is not None else t

    def _start(self, t: float, pose: FloatArray, cov: FloatArray, converged: bool = True) -> None:
        """(Re)start the back-end at ``pose``; ``converged``: a fix (or a confirmed relocalization) put it
        there, not a start pose the map has not confirmed."""
        self._converged = converged
        self._t_started = t
        if converged:
            self._t_used = t
            if not self._ever_converged:
                self._first_convergence(t, np.asarray(pose, dtype=float))
            self._ever_converged = True
        if self._lost_since is not None:
            self._lost_total_s += max(0.0, t - self._lost_since)
            # the poses since the localizer went wrong were not where they said
            self.monitor.amend(self._lost_since, t, LOST, "lost: the pose was wrong until a relocalization")
            self._lost_since = None
        self._t_held_since = None
        self._rejected_run = 0
        if self.gate is not None:
            self.gate.reset()
        if self.agreement is not None:
            self.agreement.restarted()
        self._t_bad_since = None
        self._dead_reckoned_since = None
        self._reacquiring = False
        self._pose_confirmed = False
        if self.backend.initialized:
            self.backend.reset(t, pose, cov)
        else:
            self.backend.initialize(t, pose, cov)
        self._lost = False
        self._bad_streak = 0
        if self.reloc is not None:
            self.reloc.reset()
        if self.frontend is not None and self.frontend.is_particle_filter:
            self.frontend.reset(pose)

    def _agreement_lost(self, t: float, msg: LaserScan, res: Any, odom_delta: FloatArray | None) -> bool:
        """The scan has not fit the map at the fused pose for ``integrity.agreement_lost_s``: the front-end tracks
        a wrong place its fixes cannot tell (a particle filter after a kidnapping), the poses since the last
        measurement that fit were wrong.  A front-end with a global mode searches globally; for the others the
        relocalizer looks for a confirmed better place (``res``, ``odom_delta``: the scan's match and motion).
        Whether the pose was started anew (or the search begun)."""
        assert self.agreement is not None and self.reloc is not None
        if self.backend.initialized and self.gate is not None and self.map is not None:
            # a pose that drifted a few centimetres off beside a place alike (dead reckoning past held fixes), not a
            # kidnapping: the agreement climbs from it to a place the scan fits as well as the run's good stretch
            pose, cov = self.backend.predict(t)
            near, a = place_near(self.map, self.laser_mount, msg, pose, self.gate.sigma_m)
            good = self.agreement.expected()
            if good is not None and a >= self.icfg.agreement_low * good:
                self.stats["agreement_reacquired"] = self.stats.get("agreement_reacquired", 0) + 1
                s2 = self.gate.sigma_m**2  # the map's resolution over what the pose claimed
                self._start(t, near, np.asarray(cov, dtype=float) + np.diag([s2, s2, 0.0]) + EPS_COV)
                return True
        self.stats["agreement_lost"] = self.stats.get("agreement_lost", 0) + 1
        since = self.agreement.wrong_since
        if self.frontend.supports_global:
            if self._lost_since is None:
                self._lost_since = since
            self._declare_lost(t)
            self.stats["relocalizations"] += 1
            self.frontend.reset(None)
            return True
        found = self.reloc.check(msg, res, odom_delta)
        if found is None:
            return False
        self.stats["relocalizations"] += 1
        if self._lost_since is None:
            self._lost_since = since
        self._start(t, found.pose, found.cov + EPS_COV)
        return True

    def _held_run_confirms(self, t: float) -> bool:
        """The pose has not been confirmed by a fix since it was (re)started, and the gate has held more than
        ``relocalize_confirm`` fixes in a row that follow each other as the odometry says, spanning at least
        ``relocalize_confirm_s`` (what a relocalization candidate needs to be taken)."""
        if self._pose_confirmed or self.gate is None:
            return False
        n, t0 = self.gate.held_run
        return n > self.pcfg.relocalize_confirm and t - t0 >= self.pcfg.relocalize_confirm_s

    def _agreement_check(self, t: float, msg: LaserScan) -> float:
        """The scan's agreement with the map at the fused pose, when due (monitor.py's :class:`MapAgreement`):
        how long (s) it has been low."""
        ag = self.agreement
        if ag is None or self._lost or not self._converged or not self.backend.initialized:
            return 0.0
        if not ag.due(t):
            return 0.0 if ag.after_start else ag.low_for(t)
        cur = self.backend.current(covariance=False)
        pose = cur[1] if cur is not None and float(cur[0]) >= t else self.backend.predict(t)[0]
        good = (self._rejected_run == 0 and self._t_held_since is None and self._t_used is not None
                and t - self._t_used < self.icfg.degraded_after_s)
        ag.check(t, msg, pose, good)
        return 0.0 if ag.after_start else ag.low_for(t)

    def _map_confirms_rejected(self, fix: PoseFix, msg: LaserScan) -> bool:
        """A fix the gate passed and the back-end rejected: whether the map confirms it over the back-end's
        pose (the gate's verdict when it judged so; for a fix it took as following the previous fix, from
        beyond its prediction, judged now)."""
        v, pred = self.last_gate, self._gate_prediction
        if self.gate is None or v is None:
            return False
        if v.confirmed:
            return True
        if v.d2 <= self.icfg.gate_chi2 or pred is None:
            return False
        a_pred, a_fix = self.gate.agreement(fix, pred[0], pred[1], msg)
        return math.isfinite(a_pred) and math.isfinite(a_fix) and self.gate.map_confirms(a_pred, a_fix)

    def _accept(self, fix: PoseFix) -> PoseFix:
        self._keep_fix(fix)
        self.stats["fixes"] += 1
        self.stats["fixes_used"] = self.stats.get("fixes_used", 0) + 1
        return fix

    def _start_confirmed(self, msg: LaserScan, fix: PoseFix) -> bool:
        """Whether the scan matcher, matching ``msg`` from the start pose, finds a fix within three sigma of the
        start prior of ``fix`` (a particle filter's first fix from that start)."""
        from fgloc.frontends import make_frontend

        assert self.initial_pose is not None and self.map is not None
        matcher = make_frontend("native", self.map, self.laser_mount, self.config)
        check = matcher.match(msg, self.initial_pose, None).to_fix(float(msg.stamp), matcher.name)
        return check is not None and close(check.pose, fix.pose, 3 * self.pcfg.initial_sigma_xy_m,
                                           math.radians(3 * self.pcfg.initial_sigma_yaw_deg))

    def _localize_globally(self, msg: LaserScan, odom_delta: FloatArray | None) -> PoseFix | None:
        fe = self.frontend
        t = float(msg.stamp)
        if self.initial_pose is not None and (not self.backend.initialized or self._reinit is not None):
            reinit, self._reinit = self._reinit, None
            res = fe.match(msg, self.initial_pose, odom_delta)
            fix = res.to_fix(t, fe.name)
            if fix is not None and fe.is_particle_filter and fe.supports_global and \
                    not self._start_confirmed(msg, fix):
                # a particle filter seeded at the start finds its seed whether or not the scan fits there:
                # a start the scan matcher does not confirm is searched for globally, and its poses are lost
                # until the search converges (where it is not the start: the start did not fit the map)
                self.last_reason = "initial pose: the scan does not confirm it, searching the map"
                self._start(t, self.initial_pose, self._initial_cov() if reinit is None else reinit, converged=False)
                self._declare_lost(t)
                fe.reset(None)
                return None
            if fix is not None:
                self._accept(fix)
                self._start(t, fix.pose, np.maximum(fix.cov, 0) + EPS_COV)
                return fix
            self.last_reason = f"initial pose: {res.why}"
            self._start(t, self.initial_pose, self._initial_cov() if reinit is None else reinit, converged=False)
            return None
        self._global_tries += 1
        if fe.supports_global:
            guess = self.guess(t) if self.backend.initialized else np.zeros(3)
            res = fe.match(msg, guess, odom_delta)
            fix = res.to_fix(t, fe.name)
            if fix is not None:
                sxy = math.sqrt(max(fix.cov[0, 0], fix.cov[1, 1]))
                syaw = math.sqrt(fix.cov[2, 2])
                if sxy <= self.pcfg.global_max_sigma_xy_m and \
                        syaw <= math.radians(self.pcfg.global_max_sigma_yaw_deg):
                    self._accept(fix)
                    self._start(t, fix.pose, fix.cov + EPS_COV)
                    return fix
                self.last_reason = "global localization: not converged yet"
            else:
                self.last_reason = f"global localization: {res.why}"
            if self.backend.initialized:
                self.backend.add_keyframe(t, None)
            else:
                # a pose anyway, as nav2's amcl publishes its cloud's mean from the first update on: the
                # back-end starts there with the cloud's covariance; the localizer stays lost (global
                # search goes on, the front-end keeps its cloud) until a converged fix
                pose = fix.pose if fix is not None else res.info.get("estimate")
                cov = fix.cov if fix is not None else res.info.get("estimate_cov")
                if pose is not None and cov is not None and np.all(np.isfinite(pose)) and np.all(np.isfinite(cov)):
                    self.backend.initialize(t, np.asarray(pose, dtype=float), np.asarray(cov, dtype=float) + EPS_COV)
            return None
        assert self.reloc is not None
        if self._search_waits(t):
            self.last_reason = "global localization: the last search found nothing, waiting for motion"
        else:
            gfix = self.reloc.search(msg)
            if gfix is not None:
                self._failed_search = None
                self._accept(gfix)
                self._start(t, gfix.pose, gfix.cov + EPS_COV)
                return gfix
            self._failed_search = (t, np.array(self.odom.pose_at(t), dtype=float))
            self.last_reason = "global localization: no candidate good enough"
        if self.backend.initialized:
            self.backend.add_keyframe(t, None)
        return None

    def _search_waits(self, t: float) -> bool:
        """Whether a global search would see what the last one, which found nothing, saw: the odometry has
        moved less than ``global_retry_move_m`` and turned less than ``global_retry_turn_deg`` since, and
        less than ``global_retry_s`` passed (a wrong map searched on every scan took 5 s per second of log)."""
        if self._failed_search is None:
            return False
        t0, odom0 = self._failed_search
        cfg = self.pcfg
        d = between1(odom0, np.asarray(self.odom.pose_at(t), dtype=float))
        return bool(t - t0 < cfg.global_retry_s and math.hypot(d[0], d[1]) < cfg.global_retry_move_m
                    and abs(d[2]) < math.radians(cfg.global_retry_turn_deg))
