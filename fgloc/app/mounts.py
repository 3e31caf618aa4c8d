"""``--static-transform`` / ``--static-transform-xyzw``: a sensor mount the log lacks, given on the
command line.  ``fgloc run``, ``fgloc map`` and ``fgloc map-check`` take the same two options (their help texts are
here) and read them with :func:`static_transform_entries`, into ``sources.static_transforms``
entries (REP 103 frames; angles in degrees about the parent's fixed x, y, z axes, as
``static_transform_publisher``'s yaw pitch roll; a laser mounted upside down is ROLL 180).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from fgloc.errors import ConfigError

if TYPE_CHECKING:  # the CLI imports this module: numpy only when a command runs
    from fgloc.types import Transform3D

RPY_OPTION = "--static-transform"
XYZW_OPTION = "--static-transform-xyzw"
RPY_HELP = ("PARENT CHILD X Y Z ROLL PITCH YAW (m, deg; REP 103): a mount the log lacks, e.g. base_link "
            "imu_link 0 -0.3 0.52 90 0 -90, or an upside-down laser base_link laser 0.2 0 0 180 0 0 "
            "(wins over the log's tf)")
XYZW_HELP = ("PARENT CHILD X Y Z QX QY QZ QW (m, unit quaternion): the same mount given as a quaternion, "
             "e.g. base_link laser 0.2 0 0 1 0 0 0 (upside down)")
#: usage errors of the options (a value that is not a number): one line naming what they take
HINTS = {
    XYZW_OPTION: f"{XYZW_OPTION} needs nine values PARENT CHILD X Y Z QX QY QZ QW (m, unit quaternion), "
                 f"e.g. {XYZW_OPTION} base_link laser 0.2 0 0 1 0 0 0",
    RPY_OPTION: f"{RPY_OPTION} needs eight values PARENT CHILD X Y Z ROLL PITCH YAW (m, deg), "
                f"e.g. {RPY_OPTION} base_link laser 0.2 0 0 180 0 0",
}


def static_transform_entries(rpy: tuple[Any, ...] | None = None,
                             xyzw: tuple[Any, ...] | None = None) -> list[dict[str, Any]]:
    """``sources.static_transforms`` entries of the two options' values (None: not given), checked:
    one-line :class:`ConfigError` naming the option for anything wrong (a non-finite number, a
    quaternion that is not of unit length, no parent, a child that is the robot or the parent, one child twice)."""
    from fgloc.frames.static import ROBOT_FRAMES, static_transform_entry
    from fgloc.frames.tf import frame_name, is_world_frame

    entries: list[tuple[str, dict[str, Any]]] = []
    if rpy is not None:
        parent, child, *nums = rpy
        entries.append((RPY_OPTION, static_transform_entry(parent, child, *(float(v) for v in nums[:6]))))
    if xyzw is not None:
        parent, child, *nums = xyzw
        entries.append((XYZW_OPTION, {"parent": parent, "child": child, "xyz": [float(v) for v in nums[:3]],
                                      "xyzw": [float(v) for v in nums[3:7]]}))
    seen: set[str] = set()
    for option, e in entries:
        parent, child = frame_name(str(e["parent"])), frame_name(str(e["child"]))
        e["parent"], e["child"] = parent, child
        values = e["xyz"] + e.get("rpy_deg", e.get("xyzw", []))
        if not all(math.isfinite(v) for v in values):
            raise ConfigError(f"{option} {parent} {child}: every value must be a finite number, got "
                              f"{' '.join(f'{v:g}' for v in values)}")
        if not parent or is_world_frame(parent):
            raise ConfigError(f"{option}: parent frame {parent!r}: fgloc takes mounts on the robot "
                              f"({' or '.join(ROBOT_FRAMES)}, the config's sources.base_frame, or a frame on it)")
        if not child or child in ROBOT_FRAMES or child == parent:
            raise ConfigError(f"{option}: child frame {child!r}: name the sensor's frame (the scans' frame_id)")
        if child in seen:
            raise ConfigError(f"{option}: child frame {child!r} given by both options")
        seen.add(child)
        if "xyzw" in e:
            n = math.sqrt(sum(v * v for v in e["xyzw"]))
            if abs(n - 1.0) > 0.01:
                raise ConfigError(f"{option} {parent} {child}: QX QY QZ QW is not a unit quaternion (norm {n:.4f})")
    return [e for _, e in entries]


def static_transforms(rpy: tuple[Any, ...] | None = None, xyzw: tuple[Any, ...] | None = None) -> list[Transform3D]:
    """The two options' mounts as :class:`~fgloc.types.Transform3D` (what ``fgloc map`` and
    ``fgloc map-check`` hand the mapper): :func:`static_transform_entries`, then
    :func:`~fgloc.frames.static.parse_static_transforms` naming the option in its errors."""
    from fgloc.frames.static import parse_static_transforms

    return parse_static_transforms(static_transform_entries(rpy, xyzw), source=RPY_OPTION)


def check_frames(entries: list[dict[str, Any]], sensor_frames: dict[str, str], path: Any = "log",
                 what: str = "sensor") -> None:
    """One-line :class:`ConfigError` for a command-line mount whose child frame is none of the log's
    ``sensor_frames`` (``{frame: what carries it}``, e.g. ``{"rplidar_link": "its scans"}``): such a
    mount would be silently unused.  ``what``: the kind of frame the command uses a mount for."""
    from fgloc.frames.tf import frame_name

    for e in entries:
        child = frame_name(str(e.get("child", "")))
        if child in sensor_frames:
            continue
        option = XYZW_OPTION if "xyzw" in e else RPY_OPTION
        have = "; ".join(f"{where} are in '{f}'" for f, where in sensor_frames.items()) or "it has no sensor frames"
        best = next(iter(sensor_frames), "FRAME")
        raise ConfigError(f"{path}: {option} {e.get('parent')} {child}: the log has no {what} frame '{child}' "
                          f"({have}): give the {what}'s frame as CHILD, e.g. {option} {e.get('parent')} {best} ...")
