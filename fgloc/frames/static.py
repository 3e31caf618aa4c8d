"""Static transforms given by the user, not found in the log (an IMU mount, a laser mount).

robot_localization users publish a sensor's mount from a launch file
(``static_transform_publisher``), so many recorded logs lack it: r_l's own ``test1.bag`` has an
IMU mounted rotated about two axes and no ``/tf_static``.  fgloc takes such transforms from the
config (``sources.static_transforms``) or the command line (``fgloc run --static-transform``)::

    sources:
      static_transforms:
        - {parent: base_link, child: imu_link, xyz: [0, -0.3, 0.52], rpy_deg: [90, 0, -90]}
        - {parent: base_link, child: laser, xyz: [0.2, 0, 0.3], xyzw: [0, 0, 0, 1]}

``rpy_deg`` is roll, pitch, yaw in degrees about the parent's fixed x, y, z axes (REP 103, as
``static_transform_publisher``'s ``yaw pitch roll``); ``xyzw`` a quaternion instead.  A
configured transform wins over one of the same child frame in the log.  A transform may hang on any
frame: the robot's base (``sources.base_frame``, else ``base_link`` / ``base_footprint``) or an
intermediate one (``base_link -> plate``, ``plate -> imu_link``); the chain to the base is composed
(:class:`fgloc.frames.mounts.MountTable`).  Checks only: no I/O.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from fgloc.config.schema import suggest
from fgloc.errors import ConfigError
from fgloc.frames.tf import BASE_FRAMES, is_world_frame
from fgloc.geometry import quaternion_matrix, rpy_quaternion
from fgloc.types import Transform3D

ROBOT_FRAMES = BASE_FRAMES  # the robot's own frames (fgloc.frames.tf)
KEYS = ("parent", "child", "xyz", "rpy_deg", "xyzw")


def _numbers(v: Any, n: int, where: str) -> list[float]:
    if not isinstance(v, (list, tuple)) or len(v) != n:
        raise ConfigError(f"{where}: needs {n} numbers, got {v!r}")
    try:
        out = [float(x) for x in v]
    except (TypeError, ValueError):
        raise ConfigError(f"{where}: needs {n} numbers, got {v!r}") from None
    if not all(math.isfinite(x) for x in out):
        raise ConfigError(f"{where}: needs {n} finite numbers, got {v!r}")
    return out


def transform_of(parent: str, child: str, xyz: Sequence[float], xyzw: Sequence[float]) -> Transform3D:
    """A :class:`Transform3D` from a translation and a (unit) quaternion."""
    q = np.asarray(xyzw, dtype=float) / float(np.linalg.norm(xyzw))
    R = quaternion_matrix(*q.tolist())
    return Transform3D(parent.lstrip("/"), child.lstrip("/"),
                       np.array([float(xyz[0]), float(xyz[1]), math.atan2(R[3], R[0])]),
                       float(xyz[2]), q)


def parse_static_transforms(entries: Iterable[Any] | None, source: str = "config") -> list[Transform3D]:
    """The transforms of a ``sources.static_transforms`` list; one-line :class:`ConfigError`
    naming the entry for anything wrong."""
    out: list[Transform3D] = []
    seen: set[str] = set()
    for i, e in enumerate(entries or ()):
        where = f"{source}: sources.static_transforms[{i}]"
        if not isinstance(e, dict):
            raise ConfigError(f"{where}: must be a mapping {{parent, child, xyz, rpy_deg | xyzw}}")
        unknown = sorted(set(e) - set(KEYS))
        if unknown:
            hint = suggest(str(unknown[0]), KEYS) or f" (known: {', '.join(KEYS)})"
            raise ConfigError(f"{where}: unknown key {unknown[0]!r}{hint}")
        parent, child = str(e.get("parent") or "").lstrip("/"), str(e.get("child") or "").lstrip("/")
        if not parent or not child:
            raise ConfigError(f"{where}: needs parent and child frame names")
        if parent == child:
            raise ConfigError(f"{where}: parent and child are both {parent!r}")
        if is_world_frame(parent):
            raise ConfigError(f"{where}: parent {parent!r}: fgloc uses mounts on the robot (its base "
                              f"{' or '.join(ROBOT_FRAMES)}, sources.base_frame, or a frame on it), not a world frame")
        if child in seen:
            raise ConfigError(f"{where}: child frame {child!r} given twice")
        seen.add(child)
        xyz = _numbers(e.get("xyz", [0.0, 0.0, 0.0]), 3, f"{where}.xyz")
        if "rpy_deg" in e and "xyzw" in e:
            raise ConfigError(f"{where}: give rpy_deg or xyzw, not both")
        if "xyzw" in e:
            q = _numbers(e["xyzw"], 4, f"{where}.xyzw")
            n = math.sqrt(sum(x * x for x in q))
            if abs(n - 1.0) > 0.01:
                raise ConfigError(f"{where}.xyzw: not a unit quaternion (norm {n:.4f})")
        else:
            rpy = _numbers(e.get("rpy_deg", [0.0, 0.0, 0.0]), 3, f"{where}.rpy_deg")
            q = rpy_quaternion(*np.radians(rpy).tolist()).tolist()
        out.append(transform_of(parent, child, xyz, q))
    return out


def static_transform_entry(parent: str, child: str, x: float, y: float, z: float, roll_deg: float,
                           pitch_deg: float, yaw_deg: float) -> dict[str, Any]:
    """A ``sources.static_transforms`` entry (``fgloc run --static-transform``'s eight values)."""
    return {"parent": parent, "child": child, "xyz": [x, y, z], "rpy_deg": [roll_deg, pitch_deg, yaw_deg]}


def entry_of_publisher_args(args: Sequence[float | str]) -> dict[str, Any] | None:
    """A ``sources.static_transforms`` entry from ``static_transform_publisher`` arguments
    (``x y z yaw pitch roll parent child [period]`` in radians, or ``x y z qx qy qz qw parent
    child [period]``); None when they are neither."""
    nums: list[float] = []
    for a in args:
        try:
            nums.append(float(a))
        except (TypeError, ValueError):
            break
    names = [str(a) for a in args[len(nums):]]
    if len(names) < 2 or len(nums) not in (6, 7) or not all(math.isfinite(v) for v in nums):
        return None
    parent, child = names[0].lstrip("/"), names[1].lstrip("/")
    xyz = [round(v, 9) for v in nums[:3]]
    if len(nums) == 7:
        n = math.sqrt(sum(v * v for v in nums[3:]))
        if not n > 0:
            return None
        return {"parent": parent, "child": child, "xyz": xyz, "xyzw": [round(v / n, 12) for v in nums[3:]]}
    yaw, pitch, roll = nums[3:6]
    return {"parent": parent, "child": child, "xyz": xyz,
            "rpy_deg": [round(math.degrees(v), 6) for v in (roll, pitch, yaw)]}
