"""No jumps: a fix that moves the robot further than odometry and covariance allow is held back.

A fix is taken when it agrees with what the odometry says since the last fix it passed, either way:

* with the back-end's prediction at the scan stamp (the fused pose carried on by the odometry, with its
  covariance): ``d2 = e^T (P_pred + R_fix)^-1 e`` of the position within ``integrity.gate_chi2``; or
* with the previous fix, when the gate passed it (and the back-end used it, or its own tighter gate held it
  before any fix had confirmed the back-end's pose) and it was sure of its position (its position sigma, in
  every direction, within twice the prediction's and the allowance below for the motion since the fix before;
  and, when the prediction took it, within the gate of the prediction's covariance and that allowance alone,
  and not where its own covariance, vaguer along the offset than the map's resolution, covers it with that
  resolution where the prediction's with it does not: a fix the prediction took only for its own vagueness, a
  matcher unsure between two places, is no position to follow, however far a slow laser's robot moved between
  two fixes), carried on by the odometry's motion since (:meth:`Backend.motion_correction`: a gyro's turn where
  it covers it), with an allowance for an odometry that slips or scrubs beyond what it reports:
  ``integrity.odometry_slip`` times the distance and the turn it reported in between (the odometry motion model
  of AMCL and most particle filters).  A back-end whose online
  estimate lags the fixes (a smoother outvoted by odometry that slips 30 %) does not make the fixes that follow
  each other as the wheels roughly say look like jumps; nor does a back-end that rejects fixes (an EKF sure of
  a start it has not moved from) make a run of fixes that agree with each other look like one: a gate that held
  them all would lose the robot.

The odometry's motion counts only where its stamps (not their arrival) cover the time since the previous fix
(:class:`OdometryCoverage`, no gap over ``integrity.odometry_gap_s``). Odometry that arrives late (its newest stamp
behind the scan's), stops (a dead wheel driver) or is absent for a stretch leaves the odometry pose extrapolated or
frozen there: a wrong fix must not pass as explained by a motion nobody measured, nor a right one be held because
the frozen odometry says the robot stood still. Then the fix follows the previous one as the fixes used over the
last quarter second moved (their own velocity, :meth:`JumpGate.fix_velocity`), with the same slip allowance; the
prediction and the map's confirmation judge it as always.

A fix that agrees with neither is a jump the odometry does not explain. It is taken only on evidence the matcher did
not produce itself: the scan's agreement with the map (:func:`scan_agreement`, the mean Gaussian likelihood of its
beam endpoints on the map's distance field) must be clearly better at the fix than anywhere near the prediction
(``integrity.confirm_agreement``; the best of a few poses within 3 sigma of the prediction's covariance,
:func:`neighbourhood`): the map itself says the odometry is wrong, unless the agreement climbs from the prediction
(halfway to the fix at most) to a place it explains the scan as well as at the fix: a prediction further off than it
claims (dead reckoning past held fixes) beside a place alike. The fix is then taken there. Otherwise the fix is held
back (the back-end dead-reckons), and the next fix has no previous one to follow: it must agree with the prediction,
or the map must confirm it.

So a run of consistent wrong fixes does not pull the trajectory: in a world that changed since its
map (a row of shelves along a mapped wall, seen 0.3 m closer) the matcher lands on the same wrong
place scan after scan; the first of them jumps 0.3 m from the fix before it while the wheels moved
6 cm, and each following one is 0.3 m from the prediction, which the held fixes do not move, while
the map explains the scan about as well near the prediction as at the fix.  A kidnapping beyond the
front-end's window leaves no fix to judge (the relocalizer handles it).

A run of held fixes stays one jump while it lasts.  A fix that follows the last held one as the odometry
says is judged with the prediction's covariance from when the run's first fix was held: the fixes kept to
the odometry since, so what the prediction's covariance grew by dead reckoning meanwhile is no evidence
for them (else a run 0.2 m off passes after a few seconds, once the covariance has grown by a centimetre).
And a fix the gate passed that a back-end whose pose fixes had confirmed rejects (its own, tighter gate:
the EKF's has no map-resolution floor) is held with the run it followed unless the map explains the scan
better at the fix than anywhere near the prediction, beyond a tie (:meth:`JumpGate.rejected`); the fixes after it do
not follow it in (else each of them is rejected in turn, and a particle filter front-end whose fixes the
back-end keeps rejecting is searched for globally, which in a building that looks alike in several places
can end in the wrong one).  Where the map sides with the fix, the back-end may be the one that drifted
(wheels slipping under an EKF sure of them): the fixes follow it as before.

Nor does a creep: fixes that move a few centimetres a scan off the odometry's path, each following the
last within the slip allowance, and a back-end that follows them (a smoother whose own gate takes what
this one passes), so that neither the prediction nor the previous fix ever objects.  Every fix is also
measured against an anchor, a fix the map sided with, carried on by the odometry since: one further from
it than the two fixes' covariances and half the map's distance scale allow (the finest the scan's
agreement tells apart) is taken only where the map explains the scan better at the fix than anywhere
near the anchor carried on (within the slip allowance: an odometry that slipped leaves that pose where
the map explains the scan worse than at a right fix, and the anchor moves to the fix).  Otherwise it is
held as a jump.  At most once a second the map judges a fix that did not depart as well, and the anchor
moves to it when the map sides with it, so the odometry's drift since the anchor stays small.

Both tests add the map's own resolution (its cell or declared accuracy, the distance scale of :func:`scan_agreement`)
to the covariances: a jump smaller than the map can tell apart is no jump (an odometry whose stamps come in bursts,
as in the Radish logs, is often a few centimetres off between two scans while its covariance claims millimetres).
Not for a particle filter's fix whose scan fit was not kept (``estimate: refined``, the fit's maximum beyond the
cloud): the cloud's mean and spread, no place the scan fits the map; a cloud moving from a wrong place to the right
one passes between the two, a jump the floor would pass (0.15-0.2 m from a sure prediction): the prediction judges
it by the covariances alone.  The gate judges positions: a heading the fixes correct (an odometry that turned a
few degrees wrong, as real wheels do in every turn) is left to the back-end's own weighting.

One gate for every back-end: the localizer applies it before :meth:`Backend.add_keyframe`.
Core maths only: no I/O.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from fgloc.geometry import between1, between_values, compose1, mahalanobis2_2x2, wrap_scalar
from fgloc.localization.agreement import agreement_sigma, agreements, neighbourhood, scan_agreement
from fgloc.localization.gate_map import MapJudge
from fgloc.localization.gate_records import FixRecord, HeldRun
from fgloc.localization.odometry_coverage import OdometryCoverage
from fgloc.localization.relocalization import place_near
from fgloc.maps import OccupancyMap
from fgloc.types import LaserScan, PoseFix, StaticTransform

if TYPE_CHECKING:
    from fgloc.localization.monitor import IntegrityConfig

FloatArray = np.ndarray

#: a fix whose position sigma is within this many of the prediction's (and the slip allowance) is sure
#: enough for the next fix to follow it
SURE_SIGMAS = 2.0
#: the fixes' own motion (JumpGate.fix_velocity) over the fixes used in the last this many seconds ...
VELOCITY_SPAN_S = 0.25
#: ... when they span at least this long
VELOCITY_MIN_SPAN_S = 0.1
#: the anchor of the fixes' departure from the odometry moves to a fix the map sides with at most this often
ANCHOR_REFRESH_S = 1.0


def innovation(fix: PoseFix, pred: FloatArray, pred_cov: FloatArray) -> tuple[FloatArray, float]:
    """``(e, d2)``: the fix minus the prediction (heading wrapped) and the squared Mahalanobis distance
    of its position under ``pred_cov + fix.cov`` (inf when that is singular or not finite)."""
    e = np.asarray(fix.pose, dtype=float) - np.asarray(pred, dtype=float)
    e[2] = wrap_scalar(float(e[2]))
    return e, _mahalanobis2(e, np.asarray(pred_cov, dtype=float) + np.asarray(fix.cov, dtype=float))


def slip_allowance(delta: FloatArray | None, slip: float) -> FloatArray:
    """``diag((s d)^2, (s d)^2, (s dtheta)^2)``: what an odometry that reported the motion ``delta``
    ``[dx, dy, dtheta]`` may be off by when it slips by the fraction ``s`` of it."""
    if delta is None:
        return np.zeros((3, 3))
    d = float(math.hypot(float(delta[0]), float(delta[1])))
    return np.diag([(slip * d) ** 2, (slip * d) ** 2, (slip * float(delta[2])) ** 2])


@dataclass
class GateVerdict:
    """What :meth:`JumpGate.check` decided about one fix."""

    take: bool
    d2: float                      # squared Mahalanobis distance of the fix's position from the prediction's
    jump_m: float                  # its distance from the prediction
    jump_deg: float
    agree_pred: float | None = None  # best scan_agreement near the prediction (only computed beyond the gate)
    agree_fix: float | None = None   # ... and at the fix
    why: str = ""
    confirmed: bool = False        # taken beyond the gate because the map confirmed it
    d2_previous: float | None = None  # ... from the previous fix carried by the odometry (None: no previous, or
    #                                   the prediction took the fix)
    covered: bool = True           # the odometry's stamps covered the time since the previous fix


Motion = Callable[[float, float, FloatArray], FloatArray]


class JumpGate(MapJudge):
    """Holds back fixes that jump further than odometry and covariance allow (module docstring).

    The localizer calls :meth:`check` for every fix while tracking, :meth:`accepted` when it handed the
    fix the gate passed to the back-end, and :meth:`reset` when it (re)starts the pose or a fix was not used."""

    def __init__(self, cfg: IntegrityConfig, occ_map: OccupancyMap, laser_mount: StaticTransform) -> None:
        super().__init__(cfg, occ_map, laser_mount)
        self.previous: FixRecord | None = None
        self._pending: FixRecord | None = None  # what the fix just passed becomes when the back-end takes it
        self._last_odom: FloatArray | None = None  # the odometry pose at the last fix judged
        self._taken: tuple[float, FloatArray] | None = None  # the fix just passed (stamp, pose)
        self._recent: deque[tuple[float, FloatArray]] = deque()  # fixes passed and used over VELOCITY_SPAN_S
        self._held: HeldRun | None = None  # the current run of held fixes
        #: the fix passed last, its motion, coverage, the prediction and its covariance, and the run of held
        #: fixes it followed (for rejected())
        self._judged: tuple[FixRecord, Motion | None, bool, FloatArray, FloatArray, HeldRun | None] | None = None
        #: ``(t0, t1, delta bytes, corrected)``: the caller's ``motion(t0, t1, delta)`` for the scan being judged
        self.known_motion: tuple[float, float, bytes, FloatArray] | None = None
        self._anchor: FixRecord | None = None  # the fix the fixes' departure from the odometry is measured from
        self._anchor_next: FixRecord | None = None  # ... what it becomes when the fix just passed is used
        self._anchor_checked = -math.inf  # when the map last judged a fix against it
        #: ``(anchor, stamp, odometry pose, motion, stamp, odometry pose, increment)``: the odometry's motion since
        #: the anchor up to the fix before the last one the departure test judged (in the anchor's frame), and the
        #: last one's stamp, odometry pose and increment since (as the odometry reported it)
        self._carry: tuple[FixRecord, float, FloatArray, FloatArray, float, FloatArray,
                           tuple[float, float, float]] | None = None

    def reset(self) -> None:
        """No previous fix to follow (the pose was started anew, or the last fix was not used)."""
        self.previous = None
        self._pending = None
        self._last_odom = None
        self._taken = None
        self._recent.clear()
        self._held = None
        self._judged = None
        self._anchor = None
        self._anchor_next = None
        self._anchor_checked = -math.inf
        self._carry = None

    def settled(self, used: bool, pose_confirmed: bool, scan: LaserScan) -> None:
        """What the back-end did with the fix :meth:`check` passed last (``scan``'s): :meth:`accepted` when it
        used it or no fix had confirmed its pose yet (an EKF sure of a start it has not moved from rejects
        right fixes), else :meth:`rejected`."""
        if used or not pose_confirmed:
            self.accepted()
        else:
            self.rejected(scan)

    def rejected(self, scan: LaserScan) -> bool:
        """The back-end, confirmed by the fixes it took before, rejected the fix :meth:`check` passed last
        (``scan``'s).  Unless the map explains the scan better at the fix than anywhere near the prediction by
        more than a tie (each side climbed, :meth:`MapJudge._sided`: a hair's difference at a place alike is not
        the map siding with the fix; where it sides, the back-end may be the one that drifted: as
        :meth:`accepted`), the fix counts as held: the next
        fix has none to follow, and one that follows it as the odometry says continues the run of held fixes
        it followed, judged as that run's first fix was.  Whether it was held."""
        judged = self._judged
        if judged is None:
            self.accepted()
            return False
        cur, motion, covered, pred, pred_cov, run = judged
        fix = PoseFix(cur.t, cur.pose, cur.cov)
        a_pred, a_fix, tie = self._sided(fix, pred, pred_cov, scan)
        if math.isfinite(a_pred) and math.isfinite(a_fix) and a_fix > a_pred + tie:
            self.accepted()
            return False
        self._judged = None
        self._pending = None
        self._taken = None
        self._anchor_next = None
        self.previous = None
        self._held = self._held_follows(fix, cur.odom, cur.t, motion, covered, pred_cov[:2, :2].copy(), run)
        return True

    def accepted(self) -> None:
        """The fix :meth:`check` passed last went to the back-end: the next one may follow it."""
        self.previous = self._pending
        self._pending = None
        self._judged = None
        if self._anchor_next is not None:
            self._anchor = self._anchor_next
            self._anchor_next = None
        if self._taken is not None:
            self._recent.append(self._taken)
            while len(self._recent) > 2 and self._taken[0] - self._recent[1][0] >= VELOCITY_SPAN_S:
                self._recent.popleft()
            self._taken = None

    def fix_velocity(self) -> FloatArray | None:
        """The motion per second the fixes used last showed (``[vx, vy, w]`` in the older one's frame, over
        at least :data:`VELOCITY_MIN_SPAN_S`), None when they span less."""
        if len(self._recent) < 2:
            return None
        (t0, p0), (t1, p1) = self._recent[0], self._recent[-1]
        if t1 - t0 < VELOCITY_MIN_SPAN_S:
            return None
        return np.asarray(between1(p0, p1), dtype=float) / (t1 - t0)

    def check(self, fix: PoseFix, pred: FloatArray, pred_cov: FloatArray, scan: LaserScan,
              odom_pose: FloatArray, t: float, motion: Motion | None = None,
              motion_known: bool = True, motion_covered: bool = True, fitted: bool = True) -> GateVerdict:
        """Take or hold ``fix`` (stamp ``t``) against the back-end's prediction ``(pred, pred_cov)`` there
        and the previous fix; ``odom_pose``: the dead-reckoned odometry pose at ``t``;
        ``motion(t0, t1, delta)``: the odometry's increment as the back-end believes it happened;
        ``motion_known`` False: no odometry came yet (a scan-only robot), the prediction stands where
        the last fix was while the robot moves, and a fix is held only when the map prefers the
        prediction to it.  ``motion_covered`` False: the odometry's stamps do not cover the time since
        the previous fix (odometry late, stopped or absent for a while: :class:`OdometryCoverage`), so
        the fix follows the previous one as the fixes used last moved (:meth:`fix_velocity`), not as
        the odometry's extrapolated or frozen pose says.  ``fitted`` False: the fix is a particle filter's
        cloud mean whose scan fit was not kept (module docstring): the prediction judges it without the map's
        resolution."""

        self._pending = None
        self._taken = None
        self._judged = None
        self._anchor_next = None
        R = np.asarray(fix.cov, dtype=float)
        P = np.asarray(pred_cov, dtype=float)
        covered = motion_known and motion_covered
        # a fix that follows the run of held fixes as the odometry says is the same jump as the run's first:
        # the fixes kept to the odometry since, so the prediction's covariance grown by dead reckoning is no
        # evidence for them; it is judged with the prediction's covariance at the run's start
        run = self._held
        follows_run = run is not None and self._follows(run.last, fix, odom_pose, t, motion, covered)
        P_pos = run.pred_pos_cov if follows_run and run is not None else P[:2, :2]
        # scalar maths on the position blocks (numpy's 2x2 solve and eigvalsh cost ~20 us a call each);
        # a jump smaller than the map can tell apart (its cell or declared accuracy) is no jump: the
        # floor diag(sigma_m^2, sigma_m^2, 0) on the covariances
        s2 = self.sigma_m**2
        (r00, r01), (r10, r11) = R[:2, :2].tolist()
        (p00, p01), (p10, p11) = P_pos.tolist()
        fx, fy, fyaw = np.asarray(fix.pose, dtype=float).reshape(3).tolist()
        e0, e1 = fx - float(pred[0]), fy - float(pred[1])
        f2 = s2 if fitted else 0.0  # a cloud's mean is no place the map put the robot (module docstring)
        d2 = mahalanobis2_2x2(e0, e1, (p00 + f2) + r00, p01 + r01, p10 + r10, (p11 + f2) + r11)
        jump_m = float(math.hypot(e0, e1))
        jump_deg = math.degrees(abs(wrap_scalar(fyaw - float(pred[2]))))
        take = d2 <= self.cfg.gate_chi2
        d2_prev: float | None = None
        slip = self.cfg.odometry_slip
        # what the odometry may have slipped since the last fix judged (for the fix's sureness, below)
        last = self._last_odom
        allow = 0.0 if last is None else (slip * math.hypot(*between_values(last, odom_pose)[:2])) ** 2
        odom_c = self._last_odom = np.array(odom_pose, dtype=float)  # (copies read, never written: shared below)
        prev = self.previous
        # the previous fix is asked only when the prediction does not take the fix (it can only add a take)
        vel = None if covered or take else self.fix_velocity()
        if not take and prev is not None and (vel is not None or covered):
            if vel is not None:  # the odometry does not cover the time since: the fixes' own motion
                delta = vel * max(0.0, t - prev.t)
            else:
                delta = between1(prev.odom, odom_pose)
                if motion is not None and t > prev.t:
                    delta = self._motion(motion, prev.t, t, delta)
            cx, cy, _ = compose1(prev.pose, delta).tolist()
            (c00, c01), (c10, c11) = prev.cov[:2, :2].tolist()
            sl = (slip * math.hypot(float(delta[0]), float(delta[1]))) ** 2
            d2_prev = mahalanobis2_2x2(fx - cx, fy - cy, ((r00 + c00) + s2) + sl, r01 + c01, r10 + c10,
                                        ((r11 + c11) + s2) + sl)
            # the previous fix decides only where the back-end left it, not the fix: when the prediction
            # agrees with the previous fix carried on (the same motion: no slip between them) better than
            # the fix does, the prediction already holds that fix, with everything else the back-end knows
            d2_lag = mahalanobis2_2x2(cx - float(pred[0]), cy - float(pred[1]), (p00 + c00) + s2, p01 + c01,
                                      p10 + c10, (p11 + c11) + s2)
            take = take or (d2_prev <= self.cfg.gate_chi2 and d2_prev < d2_lag)
        if take and motion_known:
            departed = self._departure(fix, odom_c, t, motion, covered, scan)
            if departed is not None:
                self.previous = None
                self._held = self._held_follows(fix, odom_pose, t, motion, covered, P[:2, :2].copy(), run,
                                                follows_run)
                return GateVerdict(False, d2, jump_m, jump_deg, departed[0], departed[1], why=departed[2],
                                   d2_previous=d2_prev, covered=motion_covered)
        if take:
            self._held = None
            pose_c = np.array(fix.pose, dtype=float)
            self._taken = (float(t), pose_c)
            # SURE_SIGMAS^2 (P + allowance) - R positive semi-definite (its lower triangle, as eigvalsh reads it)
            k2 = SURE_SIGMAS**2
            m00, m10, m11 = k2 * (p00 + allow) - r00, k2 * p10 - r10, k2 * (p11 + allow) - r11
            cur = FixRecord(pose_c, R.copy(), odom_c, float(t))
            self._judged = (cur, motion, covered, np.array(pred, dtype=float), P.copy(), run if follows_run else None)
            # ... and, when the prediction took it, not only by its own vagueness (a matcher unsure between two
            # places, 0.3 m off with a 0.1 m sigma: within the prediction's covariance and the allowance alone,
            # and not where its own covariance covers an offset the prediction's does not, each with the map's
            # resolution, while the fix is vaguer along its offset than that resolution (the matcher's vagueness,
            # not the map's, covers it: a fix 0.33 m off along a 0.175 m sigma and 0.036 m across a 5 mm one):
            # a slow laser's longer motion between two fixes widens the allowance, not what such a fix knows)
            chi2 = self.cfg.gate_chi2
            ee = e0 * e0 + e1 * e1
            vague = ee > 0.0 and (e0 * e0 * r00 + e0 * e1 * (r01 + r10) + e1 * e1 * r11) > s2 * ee
            near = d2_prev is not None or (
                mahalanobis2_2x2(e0, e1, p00 + s2 + allow, p01, p10, p11 + s2 + allow) <= chi2
                and not (vague and mahalanobis2_2x2(e0, e1, p00 + s2, p01, p10, p11 + s2) > chi2
                         and mahalanobis2_2x2(e0, e1, r00 + s2, r01, r10, r11 + s2) <= chi2))
            if near and m00 >= 0.0 and m11 >= 0.0 and m00 * m11 - m10 * m10 >= 0.0:
                # a fix about as sure of its position as the prediction in every direction is the next one's
                # to follow; after a vaguer one (a matcher unsure between two places) the next has none
                self._pending = cur
            return GateVerdict(True, d2, jump_m, jump_deg, d2_previous=d2_prev, covered=motion_covered)
        a_pred, a_fix = self.agreement(fix, pred, P, scan)
        v = GateVerdict(False, d2, jump_m, jump_deg, a_pred, a_fix, d2_previous=d2_prev, covered=motion_covered)
        if not (math.isfinite(a_pred) and math.isfinite(a_fix)):
            v.take = True  # nothing to judge by: as without the gate
        elif not motion_known and a_fix >= a_pred:
            v.take = True
            v.why = (f"no odometry: a move of {jump_m:.2f} m / {jump_deg:.1f} deg the map explains at least as well "
                     f"(agreement {a_fix:.2f} at the fix, at most {a_pred:.2f} near the last pose)")
        elif self.map_confirms(a_pred, a_fix):
            v.take = v.confirmed = True
            v.why = (f"a jump of {jump_m:.2f} m / {jump_deg:.1f} deg the map confirms (agreement {a_fix:.2f} at "
                     f"the fix, at most {a_pred:.2f} near the odometry's prediction)")
            there, a_there = place_near(self.map, self.laser_mount, scan, pred, self.sigma_m, 0.5 * jump_m)
            if a_there >= a_fix:  # a prediction off by more than it claims: the place near it (module docstring)
                v.why = f"taken {math.hypot(*(there - pred)[:2]):.2f} m from the prediction where the map fits as well"
                fix.pose = there
        else:
            v.why = (f"held back: a jump of {jump_m:.2f} m / {jump_deg:.1f} deg from the odometry's prediction "
                     f"(d2 {d2:.0f}) that the map does not confirm (agreement {a_fix:.2f} at the fix, "
                     f"{a_pred:.2f} near the prediction)")
        if v.take:
            self._held = None
            pose_c = np.array(fix.pose, dtype=float)
            self._taken = (float(t), pose_c)
            self._pending = FixRecord(pose_c, R.copy(), odom_c, float(t))
            if motion_known:
                self._anchor_next = self._pending
            self._judged = (self._pending, motion, covered, np.array(pred, dtype=float), P.copy(),
                            run if follows_run else None)
        else:
            self.previous = None
            self._held = self._held_follows(fix, odom_pose, t, motion, covered, P[:2, :2].copy(), run,
                                            follows_run)
        return v

    def _departure(self, fix: PoseFix, odom_pose: FloatArray, t: float, motion: Motion | None, covered: bool,
                   scan: LaserScan) -> tuple[float, float, str] | None:
        """Whether the fixes departed from the odometry's motion since the anchor (the last fix the odometry
        could not explain that the map sided with, or the first): ``fix`` further from the anchor carried
        on by the odometry than their covariances and the map's resolution allow, while the map explains the
        scan at least as well near that pose (within the slip allowance) as at the fix.  Then ``(agreement
        near the anchor carried on, at the fix, why)``: the fix is held.  None: it may be taken (the anchor
        becomes the fix where the map sided with it, or where no odometry covers the time since).
        ``odom_pose``: :meth:`check`'s copy of the odometry pose (read, never written: the anchor keeps it)."""
        anchor = self._anchor
        if anchor is None or not covered or not t > anchor.t:
            self._anchor_next = self._as_previous(fix, odom_pose, t)
            return None
        delta = self._carried_motion(anchor, odom_pose, t, motion)
        carried = compose1(anchor.pose, delta)
        s2 = self.sigma_m**2
        (f00, f01), (f10, f11) = np.asarray(fix.cov, dtype=float)[:2, :2].tolist()
        (a00, a01), (a10, a11) = anchor.cov[:2, :2].tolist()
        ex, ey = float(fix.pose[0]) - float(carried[0]), float(fix.pose[1]) - float(carried[1])
        # beyond what the map's agreement tells apart (half its distance scale, as agreement()'s neighbourhood):
        # the map, not the floor, judges a departure
        q = s2 / 4.0
        d2 = mahalanobis2_2x2(ex, ey, (f00 + a00) + q, f01 + a01, f10 + a10, (f11 + a11) + q)
        departed = d2 > self.cfg.gate_chi2
        if not departed and t - max(anchor.t, self._anchor_checked) < ANCHOR_REFRESH_S:
            return None
        self._anchor_checked = float(t)
        cur = self._as_previous(fix, odom_pose, t)
        # the pose the odometry says, within what it may have slipped since the anchor
        near_cov = anchor.cov + slip_allowance(delta, self.cfg.odometry_slip)
        if not departed:
            if self.map_prefers_fix(fix, carried, near_cov, scan):
                self._anchor_next = cur
            return None
        a_odo, a_fix, tie = self._sided(fix, carried, near_cov, scan)
        if not (math.isfinite(a_odo) and math.isfinite(a_fix)) or a_fix > a_odo + tie:
            self._anchor_next = cur
            return None
        dist = math.hypot(float(delta[0]), float(delta[1]))
        side = "does not side with them" if a_fix <= a_odo else "cannot tell them from it"
        why = (f"held back: the fixes left the odometry's path by {math.hypot(ex, ey):.2f} m over {dist:.1f} m "
               f"driven since {t - anchor.t:.1f} s (d2 {d2:.0f}), and the map {side} "
               f"(agreement {a_fix:.2f} near the fix, {a_odo:.2f} near the odometry's)")
        return a_odo, a_fix, why

    @staticmethod
    def _as_previous(fix: PoseFix, odom_pose: FloatArray, t: float) -> FixRecord:
        """``fix`` as an anchor or previous fix (its own copies of the pose and covariance; ``odom_pose`` shared:
        :meth:`check`'s copy, read, never written)."""
        return FixRecord(np.array(fix.pose, dtype=float), np.array(fix.cov, dtype=float), odom_pose, float(t))

    def _carried_motion(self, anchor: FixRecord, odom_pose: FloatArray, t: float, motion: Motion | None
                        ) -> FloatArray:
        """The odometry's motion from ``anchor`` to ``t`` (``odom_pose`` then) in the anchor's frame, as the
        back-end believes it happened, carried on fix by fix: the motion up to the fix before the last one
        judged against the same anchor, then the increment to the last one (asked again now: a gyro's readings
        cover it since), then the one since (``motion`` of it: the caller's own, :attr:`known_motion`, when
        the last fix judged was the last scan's)."""
        c = self._carry
        if c is None or c[0] is not anchor or not t > c[4]:
            c = (anchor, anchor.t, anchor.odom, np.zeros(3), anchor.t, anchor.odom, (0.0, 0.0, 0.0))
        _, t0, odom0, before, t1, odom1, last = c
        if t1 > t0:  # the last increment settled
            inc = np.array(last)
            if motion is not None:
                inc = motion(t0, t1, inc)
            t0, odom0, before = t1, odom1, compose1(before, inc)
        raw = between_values(odom0, odom_pose)
        inc = np.array(raw)
        if motion is not None:
            inc = self._motion(motion, t0, float(t), inc)
        self._carry = (anchor, t0, odom0, before, float(t), odom_pose, raw)
        return compose1(before, inc)

    def _follows(self, prev: FixRecord, fix: PoseFix, odom_pose: FloatArray, t: float, motion: Motion | None,
                 covered: bool) -> bool:
        """Whether ``fix`` follows ``prev`` as the odometry says (``prev`` carried on by it, the slip allowance
        and the map's resolution as in the previous-fix test)."""
        if not covered or not t > prev.t:
            return False
        delta = between1(prev.odom, odom_pose)
        if motion is not None:
            delta = self._motion(motion, prev.t, t, delta)
        cx, cy, _ = compose1(prev.pose, delta).tolist()
        sl = (self.cfg.odometry_slip * math.hypot(float(delta[0]), float(delta[1]))) ** 2 + self.sigma_m**2
        S = np.asarray(fix.cov, dtype=float)[:2, :2] + prev.cov[:2, :2]
        d2 = mahalanobis2_2x2(float(fix.pose[0]) - cx, float(fix.pose[1]) - cy, float(S[0, 0]) + sl,
                              float(S[0, 1]), float(S[1, 0]), float(S[1, 1]) + sl)
        return d2 <= self.cfg.gate_chi2

    def _held_follows(self, fix: PoseFix, odom_pose: FloatArray, t: float, motion: Motion | None, covered: bool,
                      pred_pos_cov: FloatArray, run: HeldRun | None, follows: bool | None = None) -> HeldRun:
        """The run of held fixes (:attr:`held_run`) after ``fix`` was held: lengthened when it follows the last
        held one as the odometry says (:meth:`_follows`; ``follows`` when already known), else a new one
        starting at it with the prediction's position covariance ``pred_pos_cov``."""
        cur = FixRecord(np.array(fix.pose, dtype=float), np.array(fix.cov, dtype=float),
                        np.array(odom_pose, dtype=float), float(t))
        if run is not None:
            if follows is None:
                follows = self._follows(run.last, fix, odom_pose, t, motion, covered)
            if follows:
                return HeldRun(cur, run.n + 1, run.t0, run.pred_pos_cov)
        return HeldRun(cur, 1, float(t), pred_pos_cov)

    def _motion(self, motion: Motion, t0: float, t1: float, delta: FloatArray) -> FloatArray:
        """``motion(t0, t1, delta)``; :attr:`known_motion`'s answer when it is for the same."""
        k = self.known_motion
        if k is not None and k[0] == t0 and k[1] == t1 and k[2] == delta.tobytes():
            return k[3].copy()
        return motion(t0, t1, delta)

    @property
    def held_run(self) -> tuple[int, float]:
        """``(fixes, first stamp)`` of the current run of held fixes that follow each other as the odometry
        says (``(0, nan)``: none; a fix taken ends it)."""
        return (0, math.nan) if self._held is None else (self._held.n, self._held.t0)


def _mahalanobis2(e: FloatArray, S: FloatArray) -> float:
    """The squared Mahalanobis distance of the position part of ``e`` under the position block of ``S``."""
    return mahalanobis2_2x2(float(e[0]), float(e[1]), float(S[0, 0]), float(S[0, 1]), float(S[1, 0]), float(S[1, 1]))


__all__ = ["GateVerdict", "JumpGate", "OdometryCoverage", "agreement_sigma", "agreements", "innovation",
           "neighbourhood", "scan_agreement", "slip_allowance"]
