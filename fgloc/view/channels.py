"""The view's channels: topic names, Foxglove schemas and what each one carries.

One table shared by the WebSocket publisher, the MCAP recorder and the saved layout
(``docs/foxglove/``), so a live view, a replayed ``run.mcap`` and the layout agree.
Every topic is under ``/fgloc/`` so it never collides with a log's own ROS topics
(``/scan``, ``/tf``) that ``run.mcap`` also holds.
"""

from __future__ import annotations

from dataclasses import dataclass

MAP = "/fgloc/map"
SCAN = "/fgloc/scan"
TF = "/fgloc/tf"
POSE = "/fgloc/pose"
POSE_COVARIANCE = "/fgloc/pose/covariance"
FUSED = "/fgloc/fused"
FIX = "/fgloc/fix"
FIX_ACCEPTED = "/fgloc/fix/accepted"
FIX_REJECTED = "/fgloc/fix/rejected"
PARTICLES = "/fgloc/particles"
TRAJECTORY = "/fgloc/trajectory"
HEALTH = "/fgloc/health"

# frames (REP 105); the laser frame is the scan's own frame_id
MAP_FRAME = "map"
ODOM_FRAME = "odom"
BASE_FRAME = "base_link"


@dataclass(frozen=True)
class ChannelSpec:
    topic: str
    schema: str  # a Foxglove schema name, or "json" (a JSON channel with a JSON schema)
    what: str


CHANNELS: tuple[ChannelSpec, ...] = (
    ChannelSpec(MAP, "foxglove.Grid", "the occupancy map: RGBA colours + the int8 occupancy (-1 unknown, 0..100)"),
    ChannelSpec(SCAN, "foxglove.LaserScan", "the current scan in its laser frame (invalid beams NaN)"),
    ChannelSpec(TF, "foxglove.FrameTransforms", "map -> odom -> base_link -> laser at each scan"),
    ChannelSpec(POSE, "foxglove.PoseInFrame", "the fused pose after each scan"),
    ChannelSpec(POSE_COVARIANCE, "foxglove.SceneUpdate", "the fused pose's 2-sigma xy ellipse and yaw wedge"),
    ChannelSpec(FUSED, "json", "the fused pose with its covariance and sigmas (for plots)"),
    ChannelSpec(FIX, "json", "the front-end result of each scan: accepted / rejected / no_fix / ..., the reason"),
    ChannelSpec(FIX_ACCEPTED, "foxglove.PoseInFrame", "front-end fixes the back-end used"),
    ChannelSpec(FIX_REJECTED, "foxglove.PoseInFrame", "front-end fixes the back-end gated out"),
    ChannelSpec(PARTICLES, "foxglove.PosesInFrame", "AMCL's particle cloud (subsampled), when AMCL runs"),
    ChannelSpec(TRAJECTORY, "foxglove.PosesInFrame", "the fused trajectory so far (decimated)"),
    ChannelSpec(HEALTH, "json", "per-source rates, counts, gated fixes, back-end estimates (compass offset ...)"),
)

# what a viewer may lose when it is slow (dropped from a full queue); the map is never
# queued (kept and re-sent to every new subscriber)
TOPICS = tuple(c.topic for c in CHANNELS)
