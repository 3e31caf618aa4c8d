"""Odometry handling: the twist to integrate and the dead-reckoned ``odom`` pose.

:class:`OdometryTracker` checks each wheel-odometry message, decides which body twist the
back-end integrates (the message's own, or robot_localization's differential mode: the
twist of the pose increment when the message's twist disagrees with it) and keeps the
dead-reckoned ``odom`` pose the front-ends use for their ``odom_delta`` (de-skew, motion
model).  Core maths: no I/O.
"""

from __future__ import annotations

import math

import numpy as np

from fgloc.backends.base import FloatArray
from fgloc.geometry import between, compose1, wrap_angle
from fgloc.geometry import exp as se2_exp
from fgloc.geometry import log as se2_log
from fgloc.localization.config import PipelineConfig


class OdometryTracker:
    """The dead-reckoned odom pose and the twist to integrate (see the module docstring)."""

    def __init__(self, cfg: PipelineConfig) -> None:
        self.cfg = cfg
        self.pose = np.zeros(3)            # dead-reckoned odom pose at ``t``
        self.t: float | None = None        # stamp of the last odometry message
        self.first_t: float | None = None
        self.twist = np.zeros(3)           # the last twist integrated (held until the next message)
        self.from_poses = 0                # twists taken from pose increments
        self._prev_pose: tuple[float, FloatArray] | None = None
        self._scale_sig = np.asarray(cfg.pose_delta_sigmas, dtype=float)

    def step(self, t: float, twist: FloatArray, cov: FloatArray | None, pose: FloatArray | None
             ) -> tuple[FloatArray, FloatArray | None]:
        """Take one (checked) odometry message; returns the twist and covariance to integrate."""
        tw, cov = self._twist(t, twist, cov, pose)
        # dead-reckoned odom pose (for the front-end's odom_delta); twist held backwards
        if self.t is not None:
            self.pose = compose1(self.pose, se2_exp(tw * (t - self.t)))
        self.t = t
        self.twist = tw
        if self.first_t is None:
            self.first_t = t
        return tw, cov

    def pose_at(self, t: float) -> FloatArray:
        """The odom pose at ``t``: the last message's pose carried on (or back) with its twist,
        when ``t`` is within ``odom_extrapolate_max_s`` of it (slow or late odometry must not hand
        the front-end a stale motion for its de-skew); else the last pose as it is."""
        if self.t is not None and abs(t - self.t) <= self.cfg.odom_extrapolate_max_s:
            return compose1(self.pose, se2_exp(self.twist * (t - self.t)))
        return self.pose

    def _twist(self, t: float, tw: FloatArray, cov: FloatArray | None, pose: FloatArray | None
               ) -> tuple[FloatArray, FloatArray | None]:
        """The body twist to integrate: the message's, or the dead-reckoned pose's differential.

        robot_localization's differential mode: when the source carries poses and its twist
        disagrees with the pose increment (CARMEN logs that leave tv = rv = 0, or rv = 0 while
        the pose turns) by more than ``pose_delta_tolerance_m/_deg`` (+10 %), or ``pose_deltas:
        always``, the twist is ``log(between(prev_pose, pose)) / dt`` (held over ``(t_prev, t]``
        like an encoder twist, so integrating it reproduces the pose increment exactly).  Its
        covariance then grows with the motion (``pose_delta_sigmas`` + ``pose_delta_rel`` *
        |twist|): the poses' stamps are often where the error is (bursty logger stamps).
        """
        prev = self._prev_pose
        self._prev_pose = None if pose is None else (t, pose)
        mode = self.cfg.pose_deltas
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
            tol_lin = self.cfg.pose_delta_tolerance_m + 0.1 * lin
            tol_rot = math.radians(self.cfg.pose_delta_tolerance_deg) + 0.1 * rot
            if float(np.hypot(d_tw[0] - delta[0], d_tw[1] - delta[1])) <= tol_lin and \
                    abs(float(wrap_angle(d_tw[2] - delta[2]))) <= tol_rot:
                return tw, cov
        u = se2_log(delta) / dt
        self.from_poses += 1
        speed = float(np.hypot(u[0], u[1]))
        sig = self._scale_sig + self.cfg.pose_delta_rel * np.array([speed, speed, abs(float(u[2])) + speed])
        return u, np.diag(sig**2)
