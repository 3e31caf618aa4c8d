"""Twist sources (``geometry_msgs/TwistWithCovarianceStamped``): a body twist, robot_localization's ``twistN``.

A twist source is fused as an odometry source's twist is (:class:`TwistHandler` is an
:class:`~fgloc.localization.sources.odometry.OdometryHandler` of messages without a pose): the
first twist or odometry source is the one the localizer integrates, a later one is velocity
measurements for a back-end that takes them.  ``use``: a subset of ``vx, vy, vyaw``; a twist has
no poses, so no ``differential``.  A twist reported in a sensor frame on the robot (``header.
frame_id`` with a mount in ``sources.static_transforms`` or the log's tf) is turned into
``base_link``: ``v_base = R v_sensor + w x (-r)`` for the mount's planar rotation ``R`` and
position ``r``; a frame without a mount is taken as ``base_link`` (counted on the source's
report).
"""

from __future__ import annotations

import math

import numpy as np

from fgloc.frames.mounts import OWN_FRAMES
from fgloc.io.topics import TWIST_COV_STAMPED
from fgloc.localization.sources.odometry import OdometryHandler
from fgloc.localization.sources.spec import SourceType
from fgloc.types import Odometry, Twist


class TwistHandler(OdometryHandler):
    """A twist source's messages, as an odometry's twists (see the module docstring)."""

    accepts = (Twist,)

    def handle(self, msg: Twist) -> None:
        tw = np.asarray(msg.twist, dtype=float).reshape(-1)
        cov = None if msg.twist_cov is None else np.asarray(msg.twist_cov, dtype=float).reshape(3, 3)
        frame = msg.frame_id.lstrip("/")
        if frame not in OWN_FRAMES and not self.ctx.mounts.is_base(frame):
            mount = self.ctx.mounts.mount(frame)
            if mount is None:
                self.state.extra["no_transform"] = self.state.extra.get("no_transform", 0) + 1
                self.state.extra["no_transform_frame"] = frame
            else:
                tw, cov = in_base(tw, cov, float(mount.pose[0]), float(mount.pose[1]), float(mount.pose[2]))
        self.fuse(Odometry(float(msg.stamp), tw, cov, None, None, "", "base_link"))


def in_base(tw: np.ndarray, cov: np.ndarray | None, x_m: float, y_m: float, yaw_rad: float
            ) -> tuple[np.ndarray, np.ndarray | None]:
    """A planar twist ``[vx, vy, w]`` of a sensor at ``(x_m, y_m, yaw_rad)`` on the robot as the
    robot's (``base_link``) twist, and its covariance through the same linear map."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    # v_base = R v_s - w x r = R v_s + w (y, -x)
    J = np.array([[c, -s, y_m], [s, c, -x_m], [0.0, 0.0, 1.0]])
    return J @ tw, None if cov is None else J @ cov @ J.T


SOURCE = SourceType("twist", TWIST_COV_STAMPED, "/twist", ("vx", "vy", "vyaw"), ("vx", "vy", "vyaw"), TwistHandler,
                    differential=False)
