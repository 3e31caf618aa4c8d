"""``pipeline:`` section: how the localizer tracks, relocalizes and handles odometry.

The defaults are here and only here (see :mod:`fgloc.config.schema` for the convention).
"""

from __future__ import annotations

from dataclasses import dataclass

from fgloc.backends.global_search import GlobalSearchConfig
from fgloc.config.schema import section, setting


@dataclass(frozen=True)
class PipelineConfig:
    """``pipeline:`` the localizer around the front-end and the back-end."""

    frontend_every: int = setting(2, "match every n-th scan (a keyframe each); the scans between get the "
                                  "odometry prediction as their online pose", min=1)
    # relocalization (tracking goes on meanwhile; a jump needs all of the following)
    relocalize_after: int = setting(10, "matched scans in a row without an accepted fix -> look for a better "
                                    "place globally", min=1)
    relocalize_search_every: int = setting(4, "... a global search on every n-th such scan", min=1)
    relocalize_min_quality: float = setting(0.8, "... a candidate with at least this quality (inlier fraction) "
                                            "on every scan", min=0, max=1)
    relocalize_margin: float = setting(0.15, "... that beats the tracked match's quality by this", min=0)
    relocalize_ambiguity: float = setting(0.1, "... no other candidate > 1 m / 20 deg away within this of its "
                                          "quality", min=0)
    relocalize_confirm: int = setting(2, "... and that matches again on this many further scans "
                                      "(odometry-carried)", min=0)
    relocalize_confirm_s: float = setting(1.0, "... spanning at least this long (a burst of scans is one piece "
                                          "of evidence)", min=0)
    # lost detection
    lost_after_s: float = setting(3.0, "no accepted fix for this long (at least relocalize_after informative scans; "
                                  "fixes the back-end rejects count as none) -> lost: global search as at start-up",
                                  gt=0)
    max_lost_share: float = setting(0.2, "fgloc run exits 3 when lost longer than this share of the run, or at its "
                                    "end (--allow-lost: exit 0)", min=0, max=1)
    # start-up and global localization
    initial_sigma_xy_m: float = setting(0.1, "prior on --initial-pose (or a global-search result)", gt=0)
    initial_sigma_yaw_deg: float = setting(5.0, "heading prior on --initial-pose", gt=0)
    global_min_quality: float = setting(0.5, "front-end quality a global candidate must reach", min=0, max=1)
    global_max_sigma_xy_m: float = setting(0.15, "front-ends with their own global mode (AMCL): first fix "
                                           "accepted when tighter than this", gt=0)
    global_max_sigma_yaw_deg: float = setting(5.0, "... and than this in heading", gt=0)
    global_compass_tolerance_deg: float = setting(30.0, "global candidates further from the compass heading are "
                                                  "dropped", gt=0)
    global_retry_move_m: float = setting(0.25, "front-ends without a global mode: after a global search found "
                                         "nothing, the next one waits until the odometry moved this far ...", min=0)
    global_retry_turn_deg: float = setting(10.0, "... or turned this much ...", min=0)
    global_retry_s: float = setting(1.0, "... or this long passed (the same scan from the same place finds the same: "
                                    "nothing)", min=0)
    global_search: GlobalSearchConfig = section(GlobalSearchConfig, "coarse correlative global search (front-ends "
                                                "without a global mode of their own)")
    # odometry
    odom_keyframe_interval_s: float = setting(0.1, "keyframe spacing in odom-only mode without scans", gt=0)
    odom_extrapolate_max_s: float = setting(0.5, "carry the odometry to the scan stamp over at most this gap",
                                            min=0)
    pose_deltas: str = setting("auto", "odometry twist from the pose increments (robot_localization's "
                               "differential mode): auto = when the twist disagrees with them (CARMEN: tv = rv = 0)",
                               choices=("auto", "always", "never"))
    pose_delta_sigmas: tuple[float, float, float] = setting(
        (0.01, 0.01, 0.02), "m/s, m/s, rad/s: base noise of a pose-derived twist ...", gt=0)
    pose_delta_rel: float = setting(0.1, "... plus this fraction of the speed", min=0)
    pose_delta_tolerance_m: float = setting(0.002, "auto: twist and pose increment agree within this (+10 %)",
                                            min=0)
    pose_delta_tolerance_deg: float = setting(0.1, "... and this in heading (+10 %)", min=0)
