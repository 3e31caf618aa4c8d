"""An IMU whose mount the log lacks and whose own readings say it is not level on the robot.

A log without ``/tf_static`` (fuse's TurtleBot3 tutorial bag, a driver's own recording) leaves the
IMU unmounted: its axes are taken as the robot's.  For an IMU mounted upside down or on its side
(robot_localization's Husky test bags: rolled 90 deg) that makes its yaw rate the wrong axis, or the
wrong sign, and the run a wrong answer with every pose ``ok``.  Gravity says where the robot's up is in
the sensor's frame: the IMU's orientation (the world's z axis in the sensor's axes) or, without one,
its accelerometer (at rest and on average, the reaction to gravity points up).  When the median of
those over the log's first messages lies more than :data:`TILT_DEG` from the sensor's z axis (no
ground robot drives on such a slope; :mod:`fgloc.localization.sources` levels the odometry only
below it), the rotation that brings it onto z is used as the IMU's mount, and said.  The mount's
turn about the vertical stays unknown: it does not move the yaw rate, and the IMU's heading offset
is estimated anyway.  The gravity maths (the up direction, the levelling rotation) is
:mod:`fgloc.frames.imu`'s; this module reads the log and says what it did.
"""

from __future__ import annotations

import math
from typing import Any

from fgloc.frames.imu import TILT_DEG, levelling_quaternion, up_direction

#: IMU messages read to find the up direction
N_MESSAGES = 400
#: tf messages read to find the log's own mount (as the laser's lookup does)
N_TF = 2000


def tilted_imu_mounts(reader: Any, imu_topics: list[str], configured: list[dict], base_frame: str,
                      path: Any, odom_topics: list[str] | None = None) -> list[dict[str, Any]]:
    """``sources.static_transforms`` entries for the IMU topics whose frame neither the config nor the
    log's tf mounts and whose readings are tilted more than :data:`TILT_DEG` (see the module), each
    said in a warning; ``[]`` for the others.  ``odom_topics``: the odometry the run reads, whose
    ``child_frame_id`` names the robot's base (REP 105), as the session's mounts take it."""
    import logging

    import numpy as np

    from fgloc.frames.mounts import OWN_FRAMES, MountTable
    from fgloc.frames.static import parse_static_transforms
    from fgloc.frames.tf import frame_name

    log = logging.getLogger("fgloc.app.run")
    firsts: dict[str, list[Any]] = {}
    for t in dict.fromkeys(imu_topics):
        if not reader.has(t):
            continue
        msgs = []
        for _topic, m in reader.messages([t]):
            msgs.append(m)
            if len(msgs) >= N_MESSAGES:
                break
        frame = frame_name(str(getattr(msgs[0], "frame_id", "") or "")) if msgs else ""
        if frame and frame not in OWN_FRAMES and frame != base_frame and frame not in firsts:
            firsts[frame] = msgs
    if not firsts:
        return []
    given = {frame_name(str(e.get("child", ""))) for e in configured if isinstance(e, dict)}
    firsts = {f: m for f, m in firsts.items() if f not in given}
    if not firsts:
        return []
    table = MountTable(parse_static_transforms(configured), base_frame)
    for t in dict.fromkeys(odom_topics or ()):
        if reader.has(t):
            first = next(iter(reader.messages([t])), None)
            if first is not None and hasattr(first[1], "child_frame_id"):
                table.add_odometry_frames(str(getattr(first[1], "frame_id", "odom")), str(first[1].child_frame_id))
    tf_topics = [t for t in (reader.topics.tf_static, reader.topics.tf) if reader.has(t)]
    for t in tf_topics:
        for n, (_topic, m) in enumerate(reader.messages([t])):
            table.add_tf(m)
            if n >= N_TF:
                break
    out = []
    for frame, msgs in firsts.items():
        if table.chain(frame) is not None:
            continue
        up = up_direction(msgs)
        if up is None:
            continue
        tilt = math.degrees(math.acos(max(-1.0, min(1.0, float(up[2])))))
        if tilt <= TILT_DEG:
            continue
        q = levelling_quaternion(up)
        parent = base_frame or "base_link"
        out.append({"parent": parent, "child": frame, "xyz": [0.0, 0.0, 0.0], "xyzw": q})
        roll, pitch = (round(math.degrees(v)) + 0 for v in _roll_pitch(np.asarray(q)))
        log.warning("%s: no mount of the IMU frame %s in the log, and its readings put the robot's up %.0f deg from "
                    "its z axis (not a slope: a sensor mounted %s): used mounted rolled %.0f deg, pitched %.0f deg; "
                    "its turn about the vertical is unknown, so the run's heading may be off by a constant (give "
                    "the mount to override: --static-transform %s %s X Y Z ROLL PITCH YAW)", path, frame, tilt,
                    "upside down" if tilt > 150 else "on its side", roll, pitch, parent, frame)
    return out


def _roll_pitch(q: Any) -> tuple[float, float]:
    x, y, z, w = (float(v) for v in q)
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    return roll, pitch
