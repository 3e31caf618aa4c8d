"""Pose sources (``geometry_msgs/PoseWithCovarianceStamped``): absolute poses as keyframes.

A pose in the configured ``frame_id`` (default: ``map``, or ``odom`` without a map) goes to the
back-end as a keyframe (``add_keyframe``), after the localizer started; ``gate``: a
Mahalanobis (squared) gate against the back-end's prediction.  A pose in another frame, not
finite, or with a bad covariance is a counted skip.
"""

from __future__ import annotations

import math

import numpy as np

from fgloc.geometry import wrap_angle
from fgloc.io.topics import POSE_COV_STAMPED
from fgloc.localization.sources.handler import SourceHandler, cov_bad
from fgloc.localization.sources.spec import COMPONENTS, UNUSED_VAR, SourceType
from fgloc.types import PoseFix


class PoseHandler(SourceHandler):
    """A pose source's messages into the back-end (see the module docstring)."""

    accepts = (PoseFix,)

    def handle(self, msg: PoseFix) -> None:
        spec, st = self.spec, self.state
        h = st.health
        want = spec.frame_id or ("odom" if self.loc.odom_mode else "map")
        if msg.frame_id.lstrip("/") != want:
            self.skip(f"pose in frame {msg.frame_id!r}, not {want!r}")
            return
        pose = np.asarray(msg.pose, dtype=float).reshape(-1)
        cov = np.asarray(msg.cov, dtype=float).reshape(3, 3)
        if pose.shape != (3,) or not np.all(np.isfinite(pose)):
            self.skip("pose not finite")
            return
        if cov_bad(cov):
            self.skip("covariance with a NaN or negative diagonal")
            return
        c = np.diag([spec.variance(comp, float(cov[i, i])) for i, comp in enumerate(("x", "y", "yaw"))])
        if spec.covariance == "message":
            c = cov.copy()
            for i, comp in enumerate(("x", "y", "yaw")):
                if not spec.uses(comp):
                    c[i, :] = 0.0
                    c[:, i] = 0.0
                    c[i, i] = UNUSED_VAR
        if not np.all(np.diag(c) > 0):
            self.skip("covariance zero (unknown): set covariance fixed with sigmas")
            return
        be = self.loc.backend
        if not be.initialized:
            self.skip("before the localizer started")
            return
        t = float(msg.stamp)
        if spec.gate is not None:
            be.current(covariance=True)  # a fresh marginal to gate against (not the one an output last asked for)
            pred, pcov = be.predict(t)
            e = pose - pred
            e[2] = wrap_angle(e[2])
            try:
                d2 = float(e @ np.linalg.solve(pcov + c, e))
            except np.linalg.LinAlgError:
                d2 = math.inf
            if not d2 <= spec.gate:
                h.gated += 1
                return
        if spec.differential:
            self.skip("differential pose sources are not fused (use an odometry source)")
            return
        used = be.add_keyframe(t, PoseFix(t, pose, c, source=spec.name, frame_id=want))
        if used:
            h.accepted += 1
        else:
            h.gated += 1


SOURCE = SourceType("pose", POSE_COV_STAMPED, "/pose", ("x", "y", "yaw"), COMPONENTS, PoseHandler)
