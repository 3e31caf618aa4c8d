"""The paper's EKF as a :class:`~fgloc.backends.base.Backend`.

Odometry twists are encoder updates, compass readings compass updates (heading
converted to the map frame with the calibrated offset, rate only until then; when
the joint ``[theta, w]`` update is gated the rate is applied alone), and keyframe
fixes map updates (a late fix, older than the filter time, is first carried forward by the
filter's velocities).  The online and the final trajectory are the same: the pose
right after each scan's fix (a filter does not smooth).
"""

from __future__ import annotations

import numpy as np

from fgloc.backends.base import Backend, FloatArray, twist_covariance
from fgloc.backends.compass import CompassCalibrator
from fgloc.backends.ekf import EKF, EKFConfig, motion_model
from fgloc.types import PoseFix, Trajectory


class EKFBackend(Backend):
    name = "ekf"

    def __init__(self, config: EKFConfig | None = None) -> None:
        super().__init__()
        c = config or EKFConfig()
        self.ekf = EKF(c)
        self.ekf.x = np.zeros(self.ekf.n)
        self.ekf.P = np.eye(self.ekf.n)
        self.encoder_sigmas = c.encoder_sigmas
        self.compass_sigma = c.compass_sigma
        self.compass_rate_sigma = c.compass_rate_sigma
        self.use_compass_yaw = c.use_compass_yaw
        self.calib = CompassCalibrator(c.calibration_fixes)
        self.max_rejections = c.max_rejections
        self._consecutive_rejects = 0

    @property
    def initialized(self) -> bool:
        return self.ekf.initialized

    def initialize(self, t: float, pose: FloatArray, cov: FloatArray | None = None) -> None:
        self.ekf.initialize(t, pose, cov)
        self._consecutive_rejects = 0
        self._record_online(t, self.ekf.pose(), self.ekf.pose_cov())

    def set_compass_offset(self, offset: float) -> None:
        self.calib.offset = float(offset)

    def compass_offset(self) -> float | None:
        return self.calib.offset

    def add_odometry(self, t: float, twist: FloatArray, twist_cov: FloatArray | None) -> None:
        if not self.initialized:
            return
        if t < (self.ekf.t or -np.inf):
            self.stats["late"] += 1
        self.ekf.update_encoder(t, twist, twist_covariance(twist_cov, self.encoder_sigmas))

    def add_compass(self, t: float, yaw: float | None, yaw_var: float,
                    rate: float | None, rate_var: float) -> None:
        if yaw is not None:
            self.calib.add_compass(t, yaw, rate)
        if not self.initialized:
            return
        th = self.calib.to_map(yaw) if (yaw is not None and self.use_compass_yaw) else None
        vy = yaw_var if np.isfinite(yaw_var) and yaw_var > 0 else self.compass_sigma**2
        vr = rate_var if np.isfinite(rate_var) and rate_var > 0 else self.compass_rate_sigma**2
        if not self.ekf.update_compass(t, th, vy, rate, vr) and th is not None and rate is not None:
            self.ekf.update_compass(t, None, vy, rate, vr)

    def add_keyframe(self, t: float, fix: PoseFix | None) -> bool:
        if not self.initialized:
            return False
        used = False
        if fix is not None:
            force = self._consecutive_rejects >= self.max_rejections
            pose, cov = np.asarray(fix.pose, dtype=float), np.asarray(fix.cov, dtype=float)
            if self.ekf.t is not None and t < self.ekf.t:
                # a late fix (the scan arrived after newer odometry): carried forward to the filter
                # time by the filter's own velocities, with their motion noise, not applied as if new
                dt = self.ekf.t - t
                s = self.ekf.x.copy()
                s[:3] = pose
                pose = motion_model(s, dt, self.ekf.config.omni)[:3]
                cov = cov + self.ekf.process_noise(dt)[:3, :3]
                t = self.ekf.t
            used = self.ekf.update_map(t, pose, cov, gate=not force)
            if used:
                self._consecutive_rejects = 0
                self.stats["fixes_used"] += 1
                self.calib.add_fix(t, float(pose[2]))
            else:
                self._consecutive_rejects += 1
                self.stats["fixes_rejected"] += 1
        else:
            self.ekf.predict(t)
        self.stats["keyframes"] += 1
        self._record_online(self.ekf.t or t, self.ekf.pose(), self.ekf.pose_cov())
        return used

    def predict(self, t: float) -> tuple[FloatArray, FloatArray]:
        return self.ekf.predict_pose(t)

    def current(self) -> tuple[float, FloatArray, FloatArray] | None:
        if not self.initialized:
            return None
        return float(self.ekf.t or 0.0), self.ekf.pose(), self.ekf.pose_cov()

    def finish(self) -> Trajectory:
        self.stats["gated"] = dict(self.ekf.stats["gated"])
        return self.online_trajectory()
