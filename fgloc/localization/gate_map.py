"""The jump gate's evidence from the map (:mod:`fgloc.localization.gate`): how well the scan lies on the map at
a fix against anywhere near a pose the odometry says (the prediction, or an anchor carried on), the evidence the
matcher did not produce itself.

The agreement near a pose is the best :func:`scan_agreement` of a few poses within
:data:`NEIGHBOURHOOD_SIGMAS` of its covariance (:func:`neighbourhood`); for a fix that departed from the
odometry's path, each side is also climbed (:func:`climb`, at most :data:`CLIMB_STEPS` steps, no further than
halfway to the other) and two agreements within :data:`TIE_SIGMAS` standard errors of the beams' mean difference
are a tie.  Core maths only: no I/O.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from fgloc.localization.agreement import (
    agreement_sigma,
    agreements,
    climb,
    finest_steps,
    neighbourhood,
    tied_agreements,
)
from fgloc.maps import OccupancyMap
from fgloc.types import LaserScan, PoseFix, StaticTransform

if TYPE_CHECKING:
    from fgloc.localization.monitor import IntegrityConfig

FloatArray = np.ndarray

#: the prediction's agreement is the best within this many sigmas of its covariance (neighbourhood())
NEIGHBOURHOOD_SIGMAS = 3.0
#: a fix that departed from the odometry's path is taken only where the map explains the scan better at it than
#: near the path by more than this many standard errors of the beams' mean difference (less is a tie)
TIE_SIGMAS = 2.0
#: ... each judged at the best pose the agreement climbs to from it in at most this many steps
CLIMB_STEPS = 4


class MapJudge:
    """The map's side in the jump gate's questions (module docstring): its agreement with a scan near a pose
    and at a fix.  :class:`fgloc.localization.gate.JumpGate` is one."""

    def __init__(self, cfg: IntegrityConfig, occ_map: OccupancyMap, laser_mount: StaticTransform) -> None:
        self.cfg = cfg
        self.map = occ_map
        self.laser_mount = laser_mount
        self.sigma_m = agreement_sigma(occ_map, cfg.agreement_sigma_m)

    def agreement(self, fix: PoseFix, pred: FloatArray, pred_cov: FloatArray, scan: LaserScan,
                  points: FloatArray | None = None) -> tuple[float, float]:
        """``(near the prediction, at the fix)``: the best :func:`scan_agreement` within
        :data:`NEIGHBOURHOOD_SIGMAS` of the prediction's covariance, and the agreement at the fix.
        ``points``: ``scan.points()`` when the caller has them."""
        pts = scan.points() if points is None else points
        near = self._near(pred, pred_cov, pts)
        a = agreements(self.map, self.laser_mount, scan, np.vstack([near, np.asarray(fix.pose, dtype=float)]),
                       self.sigma_m, pts)
        return float(np.max(a[:-1])), float(a[-1])

    def _sided(self, fix: PoseFix, pred: FloatArray, pred_cov: FloatArray, scan: LaserScan
               ) -> tuple[float, float, float]:
        """The map's agreement with the scan ``(near the prediction, near the fix)`` and what the two cannot be
        told apart within (:func:`tied_agreements`, :data:`TIE_SIGMAS`).  Near the prediction: the best of
        :meth:`agreement`'s neighbourhood and of the pose the agreement climbs to from it (:func:`climb`); near
        the fix: where it climbs to from the fix; each no further than halfway to the other (the coarse
        neighbourhood of a large slip allowance misses an odometry's pose a few centimetres off)."""
        pts = scan.points()
        if len(pts) < 2:
            a_pred, a_fix = self.agreement(fix, pred, pred_cov, scan, pts)
            return a_pred, a_fix, 0.0
        pred, fix_pose = np.asarray(pred, dtype=float), np.asarray(fix.pose, dtype=float)
        reach = 0.5 * math.hypot(float(fix_pose[0] - pred[0]), float(fix_pose[1] - pred[1]))
        steps = finest_steps(self.sigma_m, pts)
        odo, at_fix = (climb(self.map, self.laser_mount, p, reach, self.sigma_m, pts, steps, CLIMB_STEPS)
                       for p in (pred, fix_pose))
        return tied_agreements(self.map, self.laser_mount, np.vstack([self._near(pred, pred_cov, pts), odo]),
                               at_fix, self.sigma_m, pts, TIE_SIGMAS)

    def _near(self, pred: FloatArray, pred_cov: FloatArray, pts: FloatArray) -> FloatArray:
        """The poses near the prediction :meth:`agreement` judges (:func:`neighbourhood`, the prediction in
        the middle)."""
        # the neighbourhood at least as fine as the agreement can tell apart
        return neighbourhood(pred, np.asarray(pred_cov, dtype=float), NEIGHBOURHOOD_SIGMAS,
                             *finest_steps(self.sigma_m, pts))

    def map_prefers_fix(self, fix: PoseFix, pred: FloatArray, pred_cov: FloatArray, scan: LaserScan) -> bool:
        """Whether the map explains ``scan`` better at the fix than anywhere near the prediction (``a_fix >
        a_pred`` of :meth:`agreement`, or either not finite): judged first against the prediction itself,
        where the answer is usually settled, then against the whole neighbourhood."""
        pts = scan.points()
        if len(pts):
            a = agreements(self.map, self.laser_mount, scan,
                           np.vstack([np.asarray(pred, dtype=float), np.asarray(fix.pose, dtype=float)]), self.sigma_m,
                           pts)
            a_pred, a_fix = float(a[0]), float(a[1])
            if math.isfinite(a_pred) and math.isfinite(a_fix):
                if a_pred >= a_fix:
                    return False
                near = self._near(pred, pred_cov, pts)  # the prediction in the middle: asked already
                mid = len(near) // 2
                if self.sigma_m > 0:
                    # every agreement finite: one pose near the prediction at least as good as the fix settles it,
                    # usually the prediction turned (next to it in the neighbourhood), asked first
                    turned = near[[mid - 2, mid - 1, mid + 1, mid + 2]]
                    if float(np.max(agreements(self.map, self.laser_mount, scan, turned, self.sigma_m, pts))) >= a_fix:
                        return False
                    others = np.delete(near, np.s_[mid - 2:mid + 3], axis=0)
                else:
                    others = np.delete(near, mid, axis=0)
                a_near = float(np.max(agreements(self.map, self.laser_mount, scan, others, self.sigma_m, pts)))
                return not math.isfinite(a_near) or a_fix > a_near
        a_pred, a_fix = self.agreement(fix, pred, pred_cov, scan, pts)
        return not (math.isfinite(a_pred) and math.isfinite(a_fix)) or a_fix > a_pred

    def map_confirms(self, a_pred: float, a_fix: float) -> bool:
        """Whether the map explains the scan clearly better at the fix than anywhere near the prediction
        (``integrity.confirm_agreement``): evidence the matcher did not produce itself."""
        return bool(a_pred <= a_fix * (1.0 - self.cfg.confirm_agreement))


__all__ = ["CLIMB_STEPS", "MapJudge", "NEIGHBOURHOOD_SIGMAS", "TIE_SIGMAS"]
