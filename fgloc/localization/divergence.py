"""The fused path against the odometry's since the last fix the back-end took: a back-end that diverged.

Between two fixes the map confirmed, the fused pose is dead reckoning: the pose of the last fix the
back-end took carried on by the motion the odometry measured.  A back-end that leaves that path (a
filter handed a velocity it should not believe, a solver that failed) puts the pose somewhere no
scan and no wheel put it; its covariance may even grow to cover it, and while the front-end then
finds nothing at the wrong pose (a scan cast from a place the map has nothing at looks like an
unmapped wing) nothing else contradicts it.  :class:`PathDivergence` tells: the fused pose's
distance ``D`` from the pose it had at the last fix it took (or where it was last restarted) against
the path length ``L`` the odometry reported since (its poses at its own stamps, not carried on to the
scan's with its last twist: that twist may be the very one the back-end should not have believed),
with the jump gate's slip model
(:mod:`fgloc.localization.gate`): ``e = D - L`` is what no driving explains; its variance is that of an
odometry slipping by ``integrity.odometry_slip`` of the distance, ``(slip L)^2``, plus the map's
resolution and the two poses' own covariances along ``e``.  ``e^2 / var`` beyond ``integrity.gate_chi2``
is a divergence; it lasts until the back-end takes a fix or is restarted (every pose carried on from a
wrong one is as wrong).

The distance, not the displacement vector, is compared: a heading the back-end corrected (a gyro's
turn against the wheels') bends the path and leaves its length; only a pose further than the robot
drove is judged.  Beyond the odometry's newest stamp (odometry late, stalled or stopped) the back-end
carries its own velocity on: the path length stays, the covariance it reports grows with its
extrapolation and is the allowance.

Core maths only: no I/O.
"""

from __future__ import annotations

import math

import numpy as np

from fgloc.backends.base import FloatArray


class PathDivergence:
    """The fused pose against the odometry's path length since the last fix the back-end took (module
    docstring).  :meth:`step` once per pose (its stamp, fused pose and covariance, the odometry's pose at its
    newest stamp)."""

    def __init__(self, slip: float, sigma_m: float, chi2: float) -> None:
        self.slip = float(slip)
        self.s2 = float(sigma_m) ** 2
        self.chi2 = float(chi2)
        self._epoch: object = None  # what the anchor belongs to (the last fix taken, the last restart)
        #: (t, x, y, cov xx, xy, yy) then, as floats (the anchor moves with every fix the back-end takes)
        self._anchor: tuple[float, float, float, float, float, float] | None = None
        self._odom: list[float] | None = None  # the odometry pose's x, y at the last step
        self.path_m = 0.0  # the odometry's path length since the anchor
        self.diverged: tuple[float, float, float] | None = None  # (D m, L m, s since the anchor) once diverged
        self.events = 0  # divergences found (each lasting until the next anchor)
        self.worst: tuple[float, float, float] | None = None  # the divergence with the largest D - L

    def step(self, epoch: object, t: float, pose: FloatArray, cov: FloatArray,
             odom_pose: FloatArray) -> tuple[float, float, float] | None:
        """The pose at ``t``; ``epoch`` changes when the back-end took a fix or was restarted (the pose at
        ``t`` is then the new anchor).  ``(D, L, s)`` while the fused path has diverged, else None."""
        if epoch != self._epoch or self._anchor is None or self._odom is None:
            self._epoch = epoch
            self._anchor = (float(t), float(pose[0]), float(pose[1]), float(cov[0, 0]), float(cov[0, 1]),
                            float(cov[1, 1]))
            self._odom = [float(odom_pose[0]), float(odom_pose[1])]
            self.path_m = 0.0
            self.diverged = None
            return None
        ox, oy = float(odom_pose[0]), float(odom_pose[1])
        self.path_m += math.hypot(ox - self._odom[0], oy - self._odom[1])
        self._odom[0], self._odom[1] = ox, oy
        if self.diverged is not None:
            return self.diverged
        ta, pax, pay, a00, a01, a11 = self._anchor
        ex, ey = float(pose[0]) - pax, float(pose[1]) - pay
        d = math.hypot(ex, ey)
        e = d - self.path_m
        if not e > 0.0:
            return None
        ux, uy = ex / d, ey / d
        c = np.asarray(cov, dtype=float)
        var = (self.slip * self.path_m) ** 2 + self.s2
        var += ux * ux * a00 + 2.0 * ux * uy * a01 + uy * uy * a11
        var += ux * ux * float(c[0, 0]) + 2.0 * ux * uy * float(c[0, 1]) + uy * uy * float(c[1, 1])
        if not math.isfinite(var) or e * e <= self.chi2 * var:
            return None
        self.diverged = (d, self.path_m, float(t) - ta)
        self.events += 1
        if self.worst is None or e > self.worst[0] - self.worst[1]:
            self.worst = self.diverged
        return self.diverged


__all__ = ["PathDivergence"]
