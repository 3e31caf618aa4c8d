"""The ``smoother:`` and ``batch:`` config sections (their defaults are here and only here)."""

from __future__ import annotations

from dataclasses import dataclass

from fgloc.config.schema import optional_radians, radians, setting

KERNELS = ("huber", "cauchy", "none")


@dataclass
class SmootherConfig:
    """``smoother:`` section (the defaults are here and only here; angles in degrees, see the properties)."""

    lag_s: float = setting(2.0, "smoothing window of the fixed-lag smoother", gt=0)
    encoder_sigmas: tuple[float, float, float] = setting(
        (0.01, 0.01, 0.02), "[vx m/s, vy m/s, w rad/s] twist noise when /odom carries no covariance", gt=0)
    q_slip: tuple[float, float, float] = setting(
        (1e-5, 1e-5, 1e-5), "extra spectral density on integrated twist (slip, model error)", min=0)
    odom_kernel: str = setting("huber", "robust kernel on twist factors (wheel slip)", choices=KERNELS)
    odom_kernel_k: float = setting(1.345, "its scale", gt=0)
    compass_sigma_deg: float = setting(0.5, "per reading; readings between keyframes are averaged", gt=0)
    compass_kernel: str = setting("cauchy", "robust kernel on compass factors (cauchy ignores magnetic disturbances)",
                                  choices=KERNELS)
    compass_kernel_k: float = setting(1.345, "its scale", gt=0)
    offset_interval_s: float = setting(1.0, "one compass-offset variable per interval", gt=0)
    offset_rw_sigma_deg: float = setting(0.05, "deg/sqrt(s), random walk of the compass-to-map offset", gt=0)
    offset_prior_sigma_deg: float = setting(30.0, "prior on the compass offset when it is unknown", gt=0)
    calibrated_offset_sigma_deg: float = setting(1.0, "prior on the compass offset when it is known", gt=0)
    fix_kernel: str = setting("huber", "robust kernel on scan-to-map fixes", choices=KERNELS)
    fix_kernel_k: float = setting(1.345, "its scale", gt=0)
    fix_min_sigma_xy: float = setting(0.003, "m, floor on the front-end's position sigma", min=0)
    fix_min_sigma_theta_deg: float = setting(0.1, "floor on the front-end's heading sigma", min=0)
    fix_gate: float | None = setting(None, "optional Mahalanobis (squared) gate of a fix against the prediction",
                                     gt=0)
    fix_gate_m: float | None = setting(1.0, "reject a fix this far from the prediction (null: no gate)", gt=0)
    fix_gate_theta_deg: float | None = setting(30.0, "... or this far in heading; the robust kernel does the rest",
                                               gt=0)
    max_rejections: int = setting(1000000, "fixes gated in a row before the back-end is reset to one (the "
                                  "localizer relocalizes first: pipeline.relocalize_after)", min=1)
    relinearize_threshold: float = setting(0.01, "iSAM2 relinearization threshold", gt=0)
    relinearize_skip: int = setting(1, "iSAM2 relinearize every n-th update", min=1)
    marginalize_every_s: float = setting(0.5, "keyframes leave the window in groups this far apart (s; each "
                                         "group costs one re-elimination of the window, every update did with "
                                         "0): each stays lag_s to lag_s + this", min=0)
    online_covariance: bool = setting(False, "marginal covariance at every keyframe; false: only when asked "
                                      "(each /fused_pose)")
    update_every: int = setting(1, "keyframes per iSAM2 update (2 halves solver time; the keyframe in between "
                                "is reported as its odometry prediction)", min=1)
    min_keyframe_dt_s: float = setting(0.005, "a scan closer than this to the previous keyframe gets none", min=0)
    max_wait_s: float = setting(0.1, "wait this long for odometry to reach a keyframe stamp", min=0)
    calibration_fixes: int = setting(3, "map fixes used to calibrate the compass offset", min=1)
    gyro: bool = setting(True, "yaw rates (IMU gyro, compass rate) as between-keyframe yaw-increment factors "
                         "with an estimated bias")
    gyro_sigma_radps: float = setting(0.02, "gyro noise per reading when the message carries none (unknown: "
                                      "a cautious 1 deg/s, as the EKF's compass_rate_sigma_deg)", gt=0)
    gyro_bias_prior_radps: float = setting(0.02, "prior sigma of a gyro's bias", gt=0)
    gyro_bias_rw_radps: float = setting(2e-5, "random walk of the gyro bias (rad/s per sqrt(s))", gt=0)
    # false by default (docs/results/fusion.md, "Design evidence")
    gyro_bias_in_graph: bool = setting(False, "the gyro bias as a graph variable, observed by every yaw source (the "
                                       "wheels too); false: estimated beside the graph from absolute headings "
                                       "and standstill only (health.GyroBias, as the EKF)")
    odom_gains: bool = setting(True, "estimate the odometry's speed and yaw-rate scales (reported / true) as "
                               "calibration variables")
    gyro_chord: bool = setting(True, "where a gyro covers a keyframe interval, the odometry's translation is "
                               "integrated along the gyro's heading (a skid steer's wheel yaw, which lies, does "
                               "not bend the odometry factor's chord); its yaw stays the wheels'")
    odom_speed_scale_prior: float = setting(0.2, "prior sigma of the speed scale around 1", gt=0)
    odom_yaw_scale_prior: float = setting(1.0, "prior sigma of the yaw-rate scale around 1 (a skid steer "
                                          "reports 1.4-7 times the turn)", gt=0)
    odom_scale_rw: float = setting(0.003, "random walk of the scales (per sqrt(s))", gt=0)
    odom_drift: bool = setting(False, "with odom_gains: estimate the odometry's sideways creep and turn per metre "
                               "driven forward (a mecanum base's or a differential drive's unequal wheel radii) as "
                               "a calibration variable, observed by the fixes (the sideways part only for an "
                               "odometry that reports sideways speed)")
    odom_drift_prior: tuple[float, float] = setting(
        (0.01, 0.01), "prior sigmas around 0 of the drift [m sideways per m, rad of turn per m] (a 1 % wheel "
        "radius difference on a 0.5 m track turns 0.02 rad per m)", gt=0)
    odom_drift_rw: tuple[float, float] = setting((1e-4, 1e-4), "random walk of the drift (per sqrt(s))", gt=0)
    unmeasured_accel_q: float = setting(
        0.5, "where the odometry's stamps do not reach (it stopped or dropped a stretch): how fast the speed "
        "may change ((m/s)^2/s; the EKF's q_v); the graph's own recent motion is carried on there", gt=0)
    unmeasured_turn_q: float = setting(1.0, "... and the turn rate ((rad/s)^2/s; the EKF's q_w)", gt=0)
    scans_only_twist_sigma: tuple[float, float, float] = setting(
        (1.0, 1.0, 1.0), "a log without odometry (scans on a map): how fast the robot may move [vx m/s, vy m/s, "
        "w rad/s] before the graph's keyframes show its velocity (then carried on from keyframe to keyframe)", gt=0)
    slow_odom_timing: bool = setting(
        False, "an odometry slower than ~17 Hz carries its timing in the keyframe factor's yaw, (period * w)^2 "
        "at each end: better heading in turns on a fully mapped route (CARMEN fr079 / intel), but off by "
        "default: through unmapped space it let the dead-reckoned heading drift further (mit-csail)")
    odom_timing_jitter: bool = setting(
        True, "the output covariance (its bound by the last fix, carried along the odometry) covers a slow "
        "odometry's timing: its pose at each end known to within its period, (period^2 / 12) * w^2 yaw variance "
        "at each end (the estimate is unchanged)")
    odom_clock: bool = setting(True, "a slow odometry's clock offset against the scans (a driver's latency) "
                               "estimated from the fixes' yaw increments and applied to its stamps once confident "
                               "(fgloc/localization/clock.py; the localizer applies it for the smoothers, not the "
                               "EKF: its odometry run ahead of the scans made CARMEN logs worse)")
    adapt_noise: bool = setting(True, "weight the yaw sources by the noise they show against each other "
                                "(wheel, gyro, heading, fixes)")
    latency: bool = setting(True, "estimate the scan stamps' latency (a fix is the pose that long before its "
                            "stamp) from how the fixes' increments lag the gyro / odometry; corrected once "
                            "significant")
    latency_s: float | None = setting(None, "a known scan latency (s): overrides the estimate")
    relative_yaw_rw_sigma_deg: float = setting(0.057, "deg/sqrt(s), random walk of a differential orientation "
                                               "source's own offset (how fast its heading may drift from the "
                                               "graph's; the EKF's relative_yaw_q 1e-6 rad^2/s)", gt=0)

    # the angle settings in radians
    compass_sigma = radians()
    offset_rw_sigma = radians()
    offset_prior_sigma = radians()
    calibrated_offset_sigma = radians()
    fix_min_sigma_theta = radians()
    fix_gate_theta = optional_radians()
    relative_yaw_rw_sigma = radians()


@dataclass
class BatchConfig:
    """``batch:`` section: the batch smoother uses the ``smoother:`` factors, then this."""

    max_iterations: int = setting(50, "Levenberg-Marquardt iterations over the whole run", min=1)
