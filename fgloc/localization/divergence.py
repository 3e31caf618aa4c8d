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

The map's placements against the odometry: a map that does not fit.  Every pose the map put the
back-end at (a fix it took, a relocalization) is a placement; between two, the odometry says how the
robot moved.  :class:`MapJumps` compares the placements' change with it: the position change against the
odometry's displacement turned onto the earlier placement's heading (a wheel odometry's distance is
good to a few % ...), the heading change against the odometry's turn (... its turn less so: a skid
steer's wheels report 1.4-2.5 times the true one).  A change beyond what a slipping, scrubbing
odometry explains is a jump the wheels did not drive.  A kidnapping makes one; a map that is not this
building's geometry (mirrored, at the wrong scale, another building) makes them again and again:
each relocalization lands somewhere else, or turns the robot where its wheels went straight.  Two
within :attr:`MapJumps.WINDOW_S` of each other is no kidnapping (nobody carries a robot twice in a minute),
and no rare bad relocalization of a long run either.  Each jump remembers whether it ended a global
search (the localizer did not know where the robot was: the search settled on a place): a right map
with places alike (a symmetric room) makes such jumps too, out of global searches that settle on a
look-alike place (status.py tells the two apart by how well the map's ranges fit the laser's).

The fixes' course against the odometry's: a laser mounted otherwise than its tf says.  A laser turned by
``a`` on its bracket (the tf says it looks straight ahead) gives fixes whose heading is the robot's turned by
``a``, and whose positions follow the laser: driving straight ahead, they move at ``-a`` to their own heading,
while the odometry (base_link's, by definition) drove along its heading.  The position stays within the
mount's lever arm times ``a`` (centimetres), the heading is ``a`` off at every pose, and nothing else
contradicts it: a compass offset is estimated against the map.  :class:`FixCourse` measures the angle
between the fixes' displacement (in the first fix's frame) and the odometry's (in its body frame) over
stretches of at least :attr:`FixCourse.MIN_M` driven with little turning (each chord against the heading halfway
along it: the fixes and the odometry may disagree on a slow turn), and its median over the run.

Core maths only: no I/O.
"""

from __future__ import annotations

import math
from collections import deque

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


class MapJumps:
    """The map's placements against the odometry's motion between them (module docstring): :meth:`place` at
    every pose the map put the back-end at, :meth:`odometry` at every pose (the odometry's pose then, for its
    path length and turn); :attr:`events` the jumps the odometry does not explain."""

    #: a jump: the position off the odometry's displacement by more than ``slip`` of its path (the jump gate's
    #: ``integrity.odometry_slip``: a wheel odometry's distance is good to a few %) plus this (m) ...
    MIN_M = 2.0
    #: ... or the heading off the odometry's turn by more than TURN_SLIP of its turns plus MIN_RAD
    TURN_SLIP = 1.5  # a skid steer's wheels report up to 2.5 times the turn
    MIN_RAD = math.radians(45.0)
    WINDOW_S = 60.0  # two jumps this close (log s): the map does not fit (:attr:`repeated`)

    def __init__(self, slip: float) -> None:
        self.slip = float(slip)
        self._last: tuple[float, FloatArray, FloatArray] | None = None  # (t, placed pose, odometry pose) then
        self._odom: FloatArray | None = None  # the odometry's pose at the last step
        self.path_m = 0.0  # the odometry's path length and its turns' sum, either way (rad), since the last placement
        self.turned_rad = 0.0
        self.events = 0
        #: the largest jump: (t, m off the odometry's displacement, rad off its turn, m driven)
        self.worst: tuple[float, float, float, float] | None = None
        self._jump_t: float | None = None  # the last jump's stamp
        #: the last jumps: (t, whether a global search placed it)
        self.jumps: deque[tuple[float, bool]] = deque(maxlen=64)
        #: the shortest time between two jumps (s; None before the second)
        self.closest_s: float | None = None

    @property
    def repeated(self) -> bool:
        """Two jumps within :data:`WINDOW_S`: the map keeps putting the robot where its odometry did not go."""
        return self.closest_s is not None and self.closest_s <= self.WINDOW_S

    def odometry(self, odom_pose: FloatArray) -> None:
        o = np.asarray(odom_pose, dtype=float)
        if self._odom is not None:
            self.path_m += math.hypot(float(o[0] - self._odom[0]), float(o[1] - self._odom[1]))
            self.turned_rad += abs(math.remainder(float(o[2] - self._odom[2]), math.tau))
        self._odom = o.copy()

    def place(self, t: float, pose: FloatArray, odom_pose: FloatArray, searched: bool = False) -> bool:
        """The map put the back-end at ``pose`` at ``t`` (the odometry's pose then: ``odom_pose``); whether
        that was a jump from the last placement the odometry does not explain.  ``searched``: a global search
        placed it (the pose before was lost; kept in :attr:`jumps`)."""
        self.odometry(odom_pose)
        p = np.asarray(pose, dtype=float).copy()
        o = np.asarray(odom_pose, dtype=float).copy()
        last, self._last = self._last, (float(t), p, o)
        path, turned = self.path_m, self.turned_rad
        self.path_m = self.turned_rad = 0.0
        if last is None:
            return False
        _, p0, o0 = last
        dx, dy = float(o[0] - o0[0]), float(o[1] - o0[1])
        c, s = math.cos(float(o0[2])), math.sin(float(o0[2]))
        bx, by = c * dx + s * dy, -s * dx + c * dy  # the odometry's displacement in its own body frame then
        c, s = math.cos(float(p0[2])), math.sin(float(p0[2]))
        ex = float(p[0] - p0[0]) - (c * bx - s * by)
        ey = float(p[1] - p0[1]) - (s * bx + c * by)
        e_m = math.hypot(ex, ey)
        e_rad = abs(math.remainder(float(p[2] - p0[2]) - float(o[2] - o0[2]), math.tau))
        if e_m <= self.slip * path + self.MIN_M and e_rad <= self.TURN_SLIP * turned + self.MIN_RAD:
            return False
        self.events += 1
        if self._jump_t is not None:
            gap = float(t) - self._jump_t
            self.closest_s = gap if self.closest_s is None else min(self.closest_s, gap)
        self._jump_t = float(t)
        self.jumps.append((float(t), bool(searched)))
        if self.worst is None or e_m > self.worst[1]:
            self.worst = (float(t), e_m, e_rad, path)
        return True


class FixCourse:
    """The fixes' course against the odometry's (module docstring): :meth:`fix` at every fix the back-end took
    (with the odometry's pose then), :meth:`restart` where the pose was restarted; :meth:`offset` the median
    angle (rad, the fixes' course minus the odometry's: a laser turned by ``a`` gives ``-a``)."""

    MIN_M = 1.0  # a stretch: at least this far driven (the odometry's displacement) ...
    MAX_TURN_RAD = math.radians(3.0)  # ... turning at most this much, by the odometry and by the fixes
    LENGTH_SLIP = 0.5  # the fixes' displacement within this share of the odometry's (else a jump: no stretch)
    MIN_STRETCHES = 20  # judged after this many stretches

    def __init__(self) -> None:
        self._anchor: tuple[FloatArray, FloatArray] | None = None  # (fix pose, odometry pose) at the stretch's start
        self.angles: deque[float] = deque(maxlen=512)  # each stretch's angle (rad), the newest last
        self._added = 0
        self._offset: tuple[int, tuple[float, int] | None] = (0, None)  # (stretches added then, offset())

    def restart(self) -> None:
        """The pose was restarted (or jumped): the next fix starts a stretch."""
        self._anchor = None

    def fix(self, pose: FloatArray, odom_pose: FloatArray) -> None:
        """A fix the back-end took at ``pose`` (map) while the odometry was at ``odom_pose`` (odom)."""
        p = np.asarray(pose, dtype=float)
        o = np.asarray(odom_pose, dtype=float)
        if self._anchor is None:
            self._anchor = (p.copy(), o.copy())
            return
        p0, o0 = self._anchor
        turn = math.remainder(float(o[2] - o0[2]), math.tau)
        fturn = math.remainder(float(p[2] - p0[2]), math.tau)
        if abs(turn) > self.MAX_TURN_RAD or abs(fturn) > self.MAX_TURN_RAD:
            self._anchor = (p.copy(), o.copy())
            return
        c, s = math.cos(float(o0[2])), math.sin(float(o0[2]))
        dx, dy = float(o[0] - o0[0]), float(o[1] - o0[1])
        bx, by = c * dx + s * dy, -s * dx + c * dy
        d = math.hypot(bx, by)
        if d < self.MIN_M:
            return
        c, s = math.cos(float(p0[2])), math.sin(float(p0[2]))
        dx, dy = float(p[0] - p0[0]), float(p[1] - p0[1])
        fx, fy = c * dx + s * dy, -s * dx + c * dy
        self._anchor = (p.copy(), o.copy())
        if abs(math.hypot(fx, fy) - d) > self.LENGTH_SLIP * d:
            return
        # each chord against the heading halfway along it (an arc's chord turns by half the arc's turn)
        self.angles.append(math.remainder((math.atan2(fy, fx) - 0.5 * fturn) - (math.atan2(by, bx) - 0.5 * turn),
                                          math.tau))
        self._added += 1

    def offset(self) -> tuple[float, int] | None:
        """``(median angle rad, stretches)`` once :attr:`MIN_STRETCHES` were measured, else None."""
        if self._offset[0] != self._added:
            n = len(self.angles)
            med = (float(np.median(np.fromiter(self.angles, float, n))), n) if n >= self.MIN_STRETCHES else None
            self._offset = (self._added, med)
        return self._offset[1]


__all__ = ["FixCourse", "MapJumps", "PathDivergence"]
