"""Odometry sources (``nav_msgs/Odometry``): the body twist the localizer integrates.

The first odometry source is the one the localizer integrates (its tracker and the back-end's
odometry factor / prediction); a second one is fused as velocity measurements by a back-end
that takes them (the EKF's ``add_velocity``) and skipped by one that does not.  A
``differential`` source (or one that uses no velocity) gives the twist of its pose increments,
as robot_localization's ``odomN_differential`` does (:func:`differential_cov`); an axis used as
a velocity beside the increments of the others keeps the message's velocity.  With a levelling
IMU (``use: [..., roll, pitch]``) the twist is projected onto the ground plane.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from fgloc.backends.contract import Capability
from fgloc.geometry import between, rotate_covariance
from fgloc.geometry import log as se2_log
from fgloc.io.topics import ODOMETRY
from fgloc.localization.sources.handler import SourceContext, SourceHandler, cov_bad, flat_floats, values_bad
from fgloc.localization.sources.spec import COMPONENTS, OUT_OF_ORDER, SourceSpec, SourceType
from fgloc.types import Odometry

if TYPE_CHECKING:
    from fgloc.localization.sources.report import SourceReport

#: an attitude older than this (s) does not level an odometry message
MAX_TILT_AGE_S = 0.5
#: a base tilted more than this (rad) is no ground robot on a slope (the steepest ramps and loading
#: docks are under 20 deg) but a wrong mount or a bad reading: not levelled, counted
MAX_TILT_RAD = math.radians(30.0)
#: a twist variance this large ((m/s)^2 or (rad/s)^2) is a driver's "not estimated" placeholder
#: (1e6, 99999), no noise a wheel, visual or flow odometry has: that component gets the default
NOT_ESTIMATED_VAR = 1e3


def usable_diagonal(d0: float, d1: float, d2: float) -> bool:
    """Whether a twist covariance's three variances are all usable as the message gives them (none
    0, negative, NaN or at least :data:`NOT_ESTIMATED_VAR`)."""
    return 0.0 < d0 < NOT_ESTIMATED_VAR and 0.0 < d1 < NOT_ESTIMATED_VAR and 0.0 < d2 < NOT_ESTIMATED_VAR


def usable_twist_cov(cov: np.ndarray | None, default_sigmas: tuple[float, float, float] | list[float],
                     diag: tuple[float, float, float] | None = None) -> np.ndarray:
    """A twist covariance (3x3) with each unusable diagonal entry (0, negative, NaN, at least
    :data:`NOT_ESTIMATED_VAR`) replaced by its own default ``sigma^2`` and that row / column's
    correlations dropped; the usable entries are kept as the message gives them (``cov`` itself
    when all three are usable; the defaults' diagonal without a covariance).  ``diag``: ``cov``'s
    diagonal as floats when the caller has it."""
    if cov is None:
        return np.diag(np.square(default_sigmas))
    d0, d1, d2 = diag if diag is not None else (float(cov[0, 0]), float(cov[1, 1]), float(cov[2, 2]))
    if usable_diagonal(d0, d1, d2):
        return cov
    bad = [i for i, v in enumerate((d0, d1, d2)) if not 0.0 < v < NOT_ESTIMATED_VAR]  # NaN too
    out = np.array(cov, dtype=float).reshape(3, 3)
    for i in bad:
        out[i, :] = 0.0
        out[:, i] = 0.0
        out[i, i] = float(default_sigmas[i]) ** 2
    return out


def differential_cov(cov: np.ndarray, prev_cov: np.ndarray, prev_yaw: float, dt: float) -> np.ndarray:
    """The covariance of a differential source's twist, as robot_localization computes it (its
    ``*_differential`` mode, which the ported configs were tuned with): the two poses' covariances
    (``[x, y, yaw]``, the xy block turned from the source's frame into the earlier pose's body
    frame) summed and multiplied by ``dt``.  (Not ``(C1 + C2) / dt^2``: an odometry's poses are
    integrated, consecutive ones almost perfectly correlated: that would make the increments far
    less certain than robot_localization takes them.)"""
    return np.asarray(rotate_covariance(np.asarray(cov) + np.asarray(prev_cov), -prev_yaw) * dt, dtype=float)



class OdometryHandler(SourceHandler):
    """An odometry source's messages into the localizer (see the module docstring)."""

    accepts: ClassVar[tuple[type, ...]] = (Odometry,)
    group = "twist"  # the first twist source is integrated; a second one is velocity measurements
    second_fused = False

    def __init__(self, spec: SourceSpec, ctx: SourceContext, fused: bool = True, second: bool = False) -> None:
        super().__init__(spec, ctx, fused, second)
        #: whether the source fuses any of vx, vy, vyaw, and whether it takes the message's whole
        #: twist and covariance as they are (all three, ``covariance: message``, not differential)
        self.velocities = any(spec.uses(c) for c in ("vx", "vy", "vyaw"))
        self.whole_twist = (spec.covariance == "message" and set(spec.use) >= {"vx", "vy", "vyaw"}
                            and not spec.differential)

    def handle(self, msg: Any) -> None:
        child = msg.child_frame_id
        if child != self.state.extra.get("child_frame"):  # REP 105: the odometry moves the robot's base
            self.state.extra["child_frame"] = child
            self.ctx.mounts.add_odometry_frames(msg.frame_id, child)
        self.fuse(msg)

    def fuse(self, msg: Odometry) -> None:
        """One odometry message's twist (or its pose increment) into the localizer or the back-end."""
        spec, st = self.spec, self.state
        h = st.health
        # a second odometry source: its velocities are measurements in a back-end that takes them
        # (the EKF's add_velocity; the smoothers' integrate them into a factor of their own); a
        # back-end without add_velocity integrates one twist source and skips it
        be = self.loc.backend
        velocity = False
        if not st.fused:
            velocity = Capability.VELOCITY in be.capabilities
            if not velocity:
                self.skip("a second odometry source (this back-end integrates one twist source; the EKF fuses "
                          "its velocities)")
                return
        # the twist's covariance copied once; its entries as floats serve every check below
        tc = msg.twist_cov
        cov_copy = None if tc is None else np.array(tc, dtype=float)
        cl = None if cov_copy is None else cov_copy.ravel().tolist()
        if (cl is not None and values_bad(cl)) or (spec.differential and cov_bad(msg.pose_cov)):
            self.skip("covariance with a NaN or negative diagonal")
            return
        tw = flat_floats(msg.twist)
        cov = None if cov_copy is None else cov_copy if cov_copy.shape == (3, 3) else cov_copy.reshape(3, 3)
        tw_msg, cov_msg = tw, cov  # (read, never written)
        if tw.shape == (3,):
            vy = abs(tw.item(1))
            if vy > st.vy_max:  # (a NaN never is)
                st.vy_max = vy
        pose = None if msg.pose is None else flat_floats(msg.pose)
        velocities, whole_twist = self.velocities, self.whole_twist
        if spec.differential or not velocities:
            # robot_localization's differential mode: the twist of the pose increments
            pc = None if msg.pose_cov is None else np.asarray(msg.pose_cov, dtype=float).reshape(3, 3)
            if pose is not None and st.prev_pose is not None and not msg.stamp > st.prev_pose[0]:
                # out of order: the increments go on from the newest pose (none is lost)
                self.skip(OUT_OF_ORDER)
                return
            prev, st.prev_pose = st.prev_pose, (None if pose is None else (float(msg.stamp), pose))
            prev_pc, st.extra["prev_pose_cov"] = st.extra.get("prev_pose_cov"), pc
            if pose is None:
                self.skip("differential source without poses")
                return
            if prev is None or not msg.stamp > prev[0]:
                return
            dt = float(msg.stamp) - prev[0]
            tw = se2_log(between(prev[1], pose)) / dt
            cov = None if pc is None else \
                differential_cov(pc, pc if prev_pc is None else prev_pc, float(prev[1][2]), dt)
            comps: tuple[str, ...] = ("x", "y", "yaw")
            mixed = [i for i, (pc_, vc) in enumerate((("x", "vx"), ("y", "vy"), ("yaw", "vyaw")))
                     if not spec.uses(pc_) and spec.uses(vc)]
            if mixed:
                # an axis fused as a velocity beside the increments of the others (r_l: x, y, vyaw)
                dflt = np.square(list(be.encoder_sigmas))
                tw = tw.copy()
                cov = np.diag(dflt) if cov is None else cov.copy()
                comps = tuple(("vx", "vy", "vyaw")[i] if i in mixed else c for i, c in enumerate(comps))
                for i in mixed:
                    tw[i] = tw_msg[i]
                    cov[i, :] = 0.0
                    cov[:, i] = 0.0
                    ok = cov_msg is not None and float(cov_msg[i, i]) > 0
                    cov[i, i] = float(cov_msg[i, i]) if ok and cov_msg is not None else float(dflt[i])
        else:
            comps = ("vx", "vy", "vyaw")
        # each component on its own: a usable variance kept, an unusable one (an AR.Drone's yaw rate
        # 0 with variance 0 beside vx / vy 0.09) its own default
        message_cov = cov is not None and cov is cov_msg
        if whole_twist and cov is not None and message_cov and cl is not None and usable_diagonal(cl[0], cl[4], cl[8]):
            out = cov  # all three velocities as the message says: its whole covariance, correlations kept
        elif whole_twist:
            out = cov = usable_twist_cov(cov, be.encoder_sigmas,
                                         (cl[0], cl[4], cl[8]) if message_cov and cl is not None else None)
        else:
            default = be.encoder_sigmas
            cov = usable_twist_cov(cov, default, (cl[0], cl[4], cl[8]) if message_cov and cl is not None else None)
            out = np.zeros((3, 3))
            for i, c in enumerate(comps):
                v = spec.variance(c, float(cov[i, i]))
                out[i, i] = v if math.isfinite(v) else default[i] ** 2
            # a diff drive that does not report vy: 0 with the message's (small) variance
            if comps[1] == "vy" and not spec.uses("vy"):
                out[1, 1] = float(cov[1, 1])
        t = float(msg.stamp)
        tw, out = self.levelled(t, tw, out)
        if velocity:
            used = tuple(spec.uses(p) or spec.uses(v) for p, v in (("x", "vx"), ("y", "vy"), ("yaw", "vyaw")))
            be.add_velocity(t, tw, out, used, spec.name)
            h.accepted += 1
            return
        h.accepted += 1
        # the localizer's checks on the values at hand: the covariance's finiteness from its entries when
        # it is the message's as copied above
        out_ok = math.isfinite(sum(cl)) if message_cov and out is cov and cl is not None else None
        self.loc.odometry_values(t, tw, out, None if spec.differential else pose, out_ok)

    def levelled(self, t: float, tw: np.ndarray, cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The body twist projected onto the ground plane through the levelling IMU's latest
        roll / pitch: ``[vx cos p + vy sin r sin p, vy cos r, w]`` (unchanged without one)."""
        tilt, st = self.ctx.tilt, self.state
        if tilt is None or abs(t - tilt[0]) > MAX_TILT_AGE_S:
            return tw, cov
        _, r, p = tilt
        ar, ap, ex = abs(r), abs(p), st.extra
        if not (ar <= MAX_TILT_RAD and ap <= MAX_TILT_RAD):  # NaN too
            ex["tilt_implausible"] = ex.get("tilt_implausible", 0) + 1
            return tw, cov
        ex["levelled"] = ex.get("levelled", 0) + 1
        ex["tilt_max_rad"] = max(ex.get("tilt_max_rad", 0.0), ar, ap)
        if r == 0.0 and p == 0.0:  # level (a flat IMU's exact zeros): the projection is the identity
            return tw, cov
        cr, sr, cp, sp = math.cos(r), math.sin(r), math.cos(p), math.sin(p)
        J = np.array([[cp, sr * sp, 0.0], [0.0, cr, 0.0], [0.0, 0.0, 1.0]])
        return J @ np.asarray(tw, dtype=float), J @ np.asarray(cov, dtype=float) @ J.T


    # ------------------------------------------------------------------ report
    def backend_streams(self) -> list[str]:
        return ["odom"] if self.state.fused else [self.spec.name]

    def reports_noise(self) -> bool:
        # the noise an odometry's yaw rate showed: only when the source fuses its yaw
        return self.spec.uses("vyaw") or self.spec.uses("yaw")

    def report_estimates(self, r: SourceReport) -> None:
        s, st, loc = self.spec, self.state, self.loc
        be = loc.backend
        if st.fused and not s.differential:
            # twists the localizer's tracker replaced by pose increments (pipeline.pose_deltas)
            n_poses = int(loc.stats.get("odometry_from_poses", 0) or 0)
            if n_poses:
                r.from_poses = n_poses
                mode = getattr(getattr(loc, "pcfg", None), "pose_deltas", "auto")
                tracker = getattr(loc, "odom", None)
                shift = tracker.offset.shift if tracker is not None and hasattr(tracker, "offset") else 0
                r.from_poses_why = "pipeline.pose_deltas: always" if mode == "always" else \
                    f"the twist {'leads' if shift < 0 else 'lags'} its poses by one message " \
                    "(pipeline.pose_deltas: auto)" if shift else \
                    "the twist disagreed with the poses (pipeline.pose_deltas: auto)"
            if st.messages:
                r.vy_max_mps = round(st.vy_max, 4)
        if st.fused and Capability.ODOM_SCALES in be.capabilities:
            sc = be.odom_scales()
            r.speed_scale = round(float(sc[0]), 4)
            r.yaw_rate_scale = round(float(sc[1]), 4)


SOURCE = SourceType("odometry", ODOMETRY, "/odom", ("vx", "vy", "vyaw"), COMPONENTS, OdometryHandler)
