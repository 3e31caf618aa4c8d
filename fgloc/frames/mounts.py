"""The sensors' mounts a session looks up (:class:`MountTable`): the configured ones
(``sources.static_transforms``, :mod:`fgloc.frames.static`) win over the log's tf, and a
sensor mounted through a chain (``base_link -> plate -> imu``) gets the chain's rotation
composed.  A sensor frame without a mount is taken as the robot's, with one logged warning.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np

from fgloc.frames.imu import mount_rotation
from fgloc.frames.static import ROBOT_FRAMES, transform_of
from fgloc.geometry import matrix_quaternion
from fgloc.types import StaticTransform

log = logging.getLogger(__name__)

#: a sensor frame that needs no mount: none given, or the robot's own
OWN_FRAMES = ("", *ROBOT_FRAMES)
#: s (of an IMU's stamps): an IMU frame without a mount is warned about only after this long without
#: one, or at the end of the log: a ROS 2 recorder logs /tf_static up to tens of ms after the first
#: IMU messages (TurtleBot3 bags: 0-53 ms), and a mount that arrives is applied from then on
MOUNT_WAIT_S = 1.0
_IDENTITY = np.eye(3)
_IDENTITY.flags.writeable = False
_IDENTITY_ENTRY = (None, _IDENTITY, _IDENTITY.ravel().tolist())


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
