"""The Foxglove layout for the view channels (``docs/foxglove/fgloc-layout.json``).

``fgloc view layout -o FILE`` writes it; the repository's copy is this function's output
(a test checks).  The file is in the format Foxglove's *Layouts -> Import from file*
reads (``configById`` + a mosaic ``layout`` tree); the panel configurations are built
with foxglove-sdk's own layout classes (:mod:`foxglove.layouts`), so their keys are the
app's.  Arrangement:

* left: a top-down 3D panel in the ``map`` frame following ``base_link``: the map
  (its RGBA cells), the scan (red), the fused pose (cyan arrow) and its 2-sigma
  ellipse and yaw wedge (orange), accepted fixes (green) and rejected ones (magenta),
  AMCL's particles (yellow), the trajectory so far (line);
* right, top: plots of the fix-minus-fused offsets and the fused sigmas (m, deg);
* right, middle: a plot of per-source rates, rejected fixes and the compass offset;
* right, bottom: raw ``/fgloc/fix`` (status and reason of each scan) and ``/fgloc/health``.
"""

from __future__ import annotations

import json
from typing import Any

from fgloc.view import channels as ch


def _config(panel: Any) -> dict[str, Any]:
    """The ``config`` of a foxglove.layouts panel as plain JSON."""
    return json.loads(panel.to_json())["config"]


def layout_dict() -> dict[str, Any]:
    from fgloc.view.server import require_foxglove

    require_foxglove()
    import foxglove.layouts as fl

    topics: dict[str, Any] = {
        ch.MAP: fl.BaseRendererGridTopicSettings(visible=True, color_mode="rgba-fields", frame_locked=True,
                                                 draw_behind=True),
        ch.SCAN: fl.BaseRendererLaserScanTopicSettings(visible=True, point_size=4.0, color_mode="flat",
                                                       flat_color="#ff3b30"),
        ch.POSE: fl.BaseRendererPoseTopicSettings(visible=True, type="arrow", color="#00c8ff",
                                                  arrow_scale=(0.8, 0.15, 0.15)),
        ch.POSE_COVARIANCE: fl.BaseRendererSceneUpdateTopicSettings(visible=True),
        ch.FIX_ACCEPTED: fl.BaseRendererPoseTopicSettings(visible=True, type="arrow", color="#34c759",
                                                          arrow_scale=(0.5, 0.1, 0.1)),
        ch.FIX_REJECTED: fl.BaseRendererPoseTopicSettings(visible=True, type="arrow", color="#ff2dff",
                                                          arrow_scale=(0.5, 0.1, 0.1)),
        ch.PARTICLES: fl.BaseRendererPosesTopicSettings(visible=True, type="arrow", arrow_scale=(0.25, 0.04, 0.04)),
        ch.TRAJECTORY: fl.BaseRendererPosesTopicSettings(visible=True, type="line", line_width=0.05),
    }
    three_d = fl.ThreeDeePanel(config=fl.ThreeDeeConfig(
        fixed_frame=ch.MAP_FRAME, follow_tf=ch.BASE_FRAME, follow_mode="follow-position",
        camera_state=fl.ThreeDeeCameraState(perspective=False, distance=30.0, phi=0.0, theta_offset=90.0),
        scene=fl.BaseRendererSceneSettings(transforms=fl.BaseRendererTransforms(show_label=True, axis_size=0.5)),
        topics=topics))

    def plot(title: str, series: list[tuple[str, str]]) -> Any:
        return fl.PlotPanel(title=title, config=fl.PlotConfig(
            paths=[fl.PlotSeries(value=v, label=label, enabled=True, timestamp_method="receiveTime")
                   for v, label in series],
            show_legend=True, x_axis_val="timestamp"))

    errors = plot("fix vs fused, fused sigma", [
        (f"{ch.FIX}.offset_from_fused_m", "fix - fused (m)"),
        (f"{ch.FIX}.offset_from_fused_deg", "fix - fused (deg)"),
        (f"{ch.FUSED}.sigma_x_m", "sigma x (m)"),
        (f"{ch.FUSED}.sigma_y_m", "sigma y (m)"),
        (f"{ch.FUSED}.sigma_yaw_deg", "sigma yaw (deg)"),
    ])
    health = plot("source health", [
        (f"{ch.HEALTH}.sources.scan.rate_hz", "scan Hz"),
        (f"{ch.HEALTH}.sources.odom.rate_hz", "odom Hz"),
        (f"{ch.HEALTH}.sources.imu.rate_hz", "imu Hz"),
        (f"{ch.HEALTH}.sources.scan.rejected", "fixes rejected"),
        (f"{ch.HEALTH}.sources.scan.no_fix", "no fix"),
        (f"{ch.HEALTH}.sources.imu.compass_offset_deg", "compass offset (deg)"),
    ])
    raw_fix = fl.RawMessagesPanel(title="front-end result", config=fl.RawMessagesConfig(topic_path=ch.FIX))
    raw_health = fl.RawMessagesPanel(title="health", config=fl.RawMessagesConfig(topic_path=ch.HEALTH))
    ids = {"3d": "3D!fgloc3d", "errors": "Plot!fglocerrors", "health": "Plot!fglochealth",
           "fix": "RawMessages!fglocfix", "rawhealth": "RawMessages!fglochealth"}
    config_by_id = {ids["3d"]: {**_config(three_d), "title": "fgloc: map, scan, poses"},
                    ids["errors"]: {**_config(errors), "title": "fix vs fused, fused sigma"},
                    ids["health"]: {**_config(health), "title": "source health"},
                    ids["fix"]: {**_config(raw_fix), "title": "front-end result"},
                    ids["rawhealth"]: {**_config(raw_health), "title": "health"}}
    mosaic = {
        "direction": "row", "splitPercentage": 60, "first": ids["3d"],
        "second": {
            "direction": "column", "splitPercentage": 66,
            "first": {"direction": "column", "splitPercentage": 50, "first": ids["errors"], "second": ids["health"]},
            "second": {"direction": "row", "splitPercentage": 50, "first": ids["fix"], "second": ids["rawhealth"]},
        },
    }
    return {"configById": config_by_id, "globalVariables": {}, "userNodes": {}, "linkedGlobalVariables": [],
            "playbackConfig": {"speed": 1.0}, "layout": mosaic}


def layout_json() -> str:
    return json.dumps(layout_dict(), indent=2, sort_keys=True) + "\n"
