"""tf chains: the 2-D ``base_link -> laser`` mount composed from a log's transforms.

Transforms arrive as 2-D :class:`StaticTransform` (x, y, yaw of the quaternion, z kept) with
a flag per transform telling whether it turns the child's z axis down (a scanner mounted
upside down; :func:`fgloc.io.ros.tf_flips`).  Such a rotation is ``Rz(yaw) Rx(pi)``; a chain
through an odd number of them is an upside-down scanner, whose scans an upright one in the
same place sees mirrored (``angle_min`` and ``angle_increment`` negated), as nav2 does.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from fgloc.errors import ConfigError
from fgloc.geometry import compose, quaternion_matrix
from fgloc.types import StaticTransform

BASE_FRAMES = ("base_link", "base_footprint")  #: the robot's own frames (REP 105)
#: frames that hold the robot's pose in the world (REP 105): a link from one of them to the base is
#: the robot's motion, and nothing is mounted on them
WORLD_FRAMES = ("odom", "map", "world", "earth", "utm")
LEVEL_COS = 0.99  # a laser's z axis within ~8 deg of vertical (up, or down: upside down)
MAX_CHAIN = 32


def frame_name(frame: str) -> str:
    """A tf frame as tf2 names it: without ROS 1's leading ``/`` (``/laser`` is ``laser``)."""
    return frame.lstrip("/")


def is_world_frame(frame: str) -> bool:
    """One of :data:`WORLD_FRAMES`, also under a tf prefix (``tb3_0/odom``)."""
    return frame_name(frame).rsplit("/", 1)[-1] in WORLD_FRAMES


def tf_edge(t: StaticTransform) -> tuple[str, str]:
    """A transform's ``(parent, child)`` as tf2 names the frames (:func:`frame_name`)."""
    return frame_name(t.parent), frame_name(t.child)


def is_base_frame(frame: str) -> bool:
    """One of the robot's own frames (:data:`BASE_FRAMES`), also under a tf prefix or namespace
    (``tb3_0/base_link``, ``/robot1/base_footprint``: a multi-robot log's frames)."""
    return frame_name(frame).rsplit("/", 1)[-1] in BASE_FRAMES


class TfTree:
    """Transforms by child frame (the first one seen wins) and their upside-down flags; frames
    are compared as tf2 names them (:func:`frame_name`)."""

    def __init__(self) -> None:
        self.parents: dict[str, StaticTransform] = {}
        self.flipped: dict[tuple[str, str], bool] = {}

    def add(self, transforms: list[StaticTransform], flips: list[bool] | None = None) -> None:
        for k, tr in enumerate(transforms):
            self.parents.setdefault(frame_name(tr.child), tr)
            if flips is not None and flips[k]:
                self.flipped[tf_edge(tr)] = True

    def chain(self, frame: str) -> tuple[StaticTransform, bool] | None:
        """``(base -> frame, mirrored)`` or None when no chain reaches a base frame (a prefixed
        one too: :func:`is_base_frame`): the 2-D mount and whether an odd number of the
        transforms on the way turn the z axis down."""
        pose, z, cur, mirrored = np.zeros(3), 0.0, frame_name(frame), False
        for _ in range(MAX_CHAIN):
            if is_base_frame(cur):
                return StaticTransform(cur, frame, pose, z), mirrored
            tr = self.parents.get(cur)
            if tr is None:
                return None
            if self.flipped.get(tf_edge(tr), False):
                # R = Rz(yaw) Rx(pi): a child pose (x, y, th) is (x, -y, -th) before the yaw
                pose = np.array([pose[0], -pose[1], -pose[2]])
                z = -z
                mirrored = not mirrored
            pose = compose(tr.pose, pose)
            z += tr.z
            cur = frame_name(tr.parent)
        return None


def mount_of(frame: str, transforms: Iterable[StaticTransform], base_frame: str = "") -> StaticTransform | None:
    """The robot -> ``frame`` transform among ``transforms`` (a user's mounts), if any: through their
    chain to the base (``base_frame``, else :data:`BASE_FRAMES`; :class:`fgloc.frames.mounts.MountTable`)."""
    from fgloc.frames.mounts import MountTable

    return MountTable(list(transforms), base_frame).mount(frame)


#: who gives the mounts planar_mount checks, by default (its ConfigError names it)
MOUNT_OPTIONS = "--static-transform / --static-transform-xyzw"


def planar_mount(t: StaticTransform, given_by: str = MOUNT_OPTIONS) -> tuple[StaticTransform, bool]:
    """A robot -> laser transform (a :class:`~fgloc.types.Transform3D` with its whole rotation, or a
    planar one) as the 2-D mount the scans are used with, and whether they are to be read mirrored.

    A level laser is its (x, y, yaw); one mounted upside down (its z axis down: rolled or pitched
    by pi, ``R = Rz(yaw) Rx(pi)``) is the upright laser at the same place and yaw whose scans are
    the log's mirrored (angles negated), as :mod:`fgloc.io` reads a log's upside-down tf and nav2
    does.  A tilted laser (z axis more than ~8 deg off vertical) is a :class:`ConfigError` naming
    ``given_by`` (the option or config key the mount came from): its beams do not sweep the plane
    the map is of."""
    q = getattr(t, "rotation_xyzw", None)
    if q is None:
        return t, False
    r = quaternion_matrix(*(float(v) for v in np.asarray(q, dtype=float) / float(np.linalg.norm(q))))
    mount = StaticTransform(t.parent, t.child, np.array([t.pose[0], t.pose[1], np.arctan2(r[3], r[0])]), t.z)
    if r[8] >= LEVEL_COS:
        return mount, False
    if r[8] <= -LEVEL_COS:
        return mount, True
    tilt = float(np.degrees(np.arccos(min(1.0, abs(r[8])))))
    raise ConfigError(f"{given_by} {t.parent} {t.child}: the laser is tilted {tilt:.1f} deg from level (roll / "
                      "pitch); fgloc maps and localizes with a level laser or one upside down (ROLL 180 or "
                      "PITCH 180): check the ROLL and PITCH given")
