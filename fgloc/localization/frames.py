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
configured transform wins over one of the same child frame in the log.  Only mounts on the robot
(parent ``base_link`` or ``base_footprint``) are used.  :class:`MountTable` is the sensors'
mounts a session looks up: the configured ones, then the log's tf (chains composed).  Core
maths and checks: no I/O (a missing mount is one logged warning).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from fgloc.backends.imu import mount_rotation
from fgloc.config.schema import suggest
from fgloc.errors import ConfigError
from fgloc.geometry import matrix_quaternion, quaternion_matrix, rpy_quaternion
from fgloc.io.tf import BASE_FRAMES
from fgloc.types import StaticTransform, Transform3D

log = logging.getLogger(__name__)

ROBOT_FRAMES = BASE_FRAMES  # the robot's own frames (one home: fgloc.io.tf)
#: a sensor frame that needs no mount: none given, or the robot's own
OWN_FRAMES = ("", *ROBOT_FRAMES)
KEYS = ("parent", "child", "xyz", "rpy_deg", "xyzw")
#: s (of an IMU's stamps): an IMU frame without a mount is warned about only after this long without
#: one, or at the end of the log: a ROS 2 recorder logs /tf_static up to tens of ms after the first
#: IMU messages (TurtleBot3 bags: 0-53 ms), and a mount that arrives is applied from then on
MOUNT_WAIT_S = 1.0
_IDENTITY = np.eye(3)
_IDENTITY.flags.writeable = False
_IDENTITY_ENTRY = (None, _IDENTITY, _IDENTITY.ravel().tolist())


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
        if parent not in ROBOT_FRAMES:
            raise ConfigError(f"{where}: parent {parent!r}: fgloc uses mounts on the robot "
                              f"({' or '.join(ROBOT_FRAMES)})")
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


def _same_rotation(a: StaticTransform, b: StaticTransform) -> bool:
    qa, qb = getattr(a, "rotation_xyzw", None), getattr(b, "rotation_xyzw", None)
    if qa is None or qb is None:
        return qa is None and qb is None and float(a.pose[2]) == float(b.pose[2])
    return bool(np.array_equal(np.asarray(qa), np.asarray(qb)))


class MountTable:
    """The sensors' mounts on the robot: the configured ones (``sources.static_transforms``) win
    over the log's tf (:meth:`add_tf`); a sensor mounted through a chain (``base_link -> plate ->
    imu``) gets the chain's rotation composed.  Rotations are computed once per transform."""

    def __init__(self, configured: Sequence[StaticTransform] | None = None) -> None:
        self.configured = {t.child.lstrip("/"): t for t in configured or ()}
        self.mounts: dict[str, StaticTransform] = dict(self.configured)
        # every tf link by child frame: a sensor mounted through a chain (base_link -> plate -> imu)
        self._links: dict[str, StaticTransform] = {}
        self._chains: dict[str, StaticTransform | None] = {}
        # the mounts' rotations by frame (and their entries as floats)
        self._rotations: dict[str, tuple[StaticTransform | None, np.ndarray, list[float]]] = {}
        self._warned: set[str] = set()

    def add_tf(self, msg: object) -> None:
        """A ``/tf_static`` or ``/tf`` message (a list of transforms): the mounts on the robot and
        every link (configured frames and the robot's own are not overridden)."""
        if isinstance(msg, (list, tuple)):
            for tr in msg:
                if not isinstance(tr, StaticTransform):
                    continue
                child = tr.child.lstrip("/")
                if child in self.configured or child in ROBOT_FRAMES:
                    continue
                if tr.parent.lstrip("/") in ROBOT_FRAMES:
                    self.mounts[child] = tr
                old = self._links.get(child)
                if old is None or not _same_rotation(old, tr) or old.parent != tr.parent:
                    self._chains.clear()
                self._links[child] = tr

    def chain(self, frame: str) -> StaticTransform | None:
        """``base_link -> frame`` through the tf links (rotation composed; None: no chain)."""
        if frame in self._chains:
            return self._chains[frame]
        R, cur, out = np.eye(3), frame, None
        for _ in range(32):
            tr = self._links.get(cur)
            if tr is None:
                break
            R = mount_rotation(tr) @ R
            cur = tr.parent.lstrip("/")
            if cur in ROBOT_FRAMES:
                out = transform_of(cur, frame, [0.0, 0.0, 0.0], matrix_quaternion(R).tolist())
                break
        self._chains[frame] = out
        return out

    def mount(self, frame: str) -> StaticTransform | None:
        """The robot -> ``frame`` mount (None: the robot's own frame, or none known yet)."""
        f = frame.lstrip("/")
        if f in OWN_FRAMES:
            return None
        tr = self.mounts.get(f)
        if tr is None:
            tr = self.chain(f)
        return tr

    def rotation(self, tr: StaticTransform | None) -> np.ndarray:
        """``mount_rotation(tr)``, computed once per transform (every IMU message asks; a new
        transform of the same frame replaces it)."""
        return self._rotation_entry(tr)[1]

    def rotation_values(self, tr: StaticTransform | None) -> list[float]:
        """:meth:`rotation`'s 9 entries row by row as floats (what ``imu_in_base`` reads), kept with it."""
        return self._rotation_entry(tr)[2]

    def _rotation_entry(self, tr: StaticTransform | None) -> tuple[StaticTransform | None, np.ndarray, list[float]]:
        if tr is None:
            return _IDENTITY_ENTRY
        got = self._rotations.get(tr.child)
        if got is None or got[0] is not tr:
            R = mount_rotation(tr)
            got = self._rotations[tr.child] = (tr, R, R.ravel().tolist())
        return got

    def warn_missing(self, frame: str) -> None:
        """One warning per frame: no mount, taken as mounted like base_link."""
        if frame not in self._warned:
            self._warned.add(frame)
            log.warning("no transform base_link -> %s: the IMU is taken as mounted like base_link", frame)
