"""The sensors' mounts a session looks up (:class:`MountTable`): the transform from the robot's base
frame to a sensor's frame through any chain of transforms.

REP 105: the robot's base frame is the one its odometry moves (``child_frame_id``), whatever its
name (``base_link``, ``base_footprint``, ``mustang_base``); robot_localization names it
``base_link_frame``, fgloc ``sources.base_frame``.  When it is not given, it is the
``child_frame_id`` of the odometry the session reads, else ``base_link`` / ``base_footprint``
(also under a tf prefix: :func:`~fgloc.frames.tf.is_base_frame`).

A sensor's mount is the composition of the links between the base and its frame: the log's
``/tf_static`` and ``/tf``, the config's ``sources.static_transforms`` and ``--static-transform``
(a configured link wins over the log's of the same child frame), through intermediate frames
(``base_link -> plate -> imu``), each link given parent -> child or child -> parent.  Links that
move the base in the world (``odom -> base_link``: a world frame's, or one that changed) are not
mounts and are never on a chain.  When both ``base_footprint`` and ``base_link`` exist, the chain
between them is honoured; with no link between them, either stands for the robot.

A sensor frame that no chain connects to the base is the caller's to report
(:meth:`MountTable.unconnected` says what the frame's chain does reach); the sources use it
unmounted (identity), counted and reported once per source, never silently.
"""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Sequence

import numpy as np

from fgloc.frames.imu import mount_rotation
from fgloc.frames.static import ROBOT_FRAMES, transform_of
from fgloc.frames.tf import WORLD_FRAMES, frame_name, is_base_frame, is_world_frame
from fgloc.geometry import matrix_quaternion
from fgloc.types import StaticTransform

log = logging.getLogger(__name__)

#: a sensor frame that needs no mount: none given, or the robot's own (REP 105's names; a configured
#: or odometry-given base frame is the robot's too: :meth:`MountTable.is_base`)
OWN_FRAMES = ("", *ROBOT_FRAMES)
#: s (of an IMU's stamps): an IMU frame without a mount is warned about only after this long without
#: one, or at the end of the log: a ROS 2 recorder logs /tf_static up to tens of ms after the first
#: IMU messages (TurtleBot3 bags: 0-53 ms), and a mount that arrives is applied from then on
MOUNT_WAIT_S = 1.0
MAX_CHAIN = 32
_IDENTITY = np.eye(3)
_IDENTITY.flags.writeable = False
_IDENTITY_ENTRY = (None, _IDENTITY, _IDENTITY.ravel().tolist())


def _same(a: StaticTransform, b: StaticTransform) -> bool:
    """The same link: parent, translation and rotation."""
    if a.parent != b.parent or float(a.z) != float(b.z) or not np.array_equal(a.pose, b.pose):
        return False
    qa, qb = getattr(a, "rotation_xyzw", None), getattr(b, "rotation_xyzw", None)
    if qa is None or qb is None:
        return qa is None and qb is None
    return bool(np.array_equal(np.asarray(qa), np.asarray(qb)))


def _rt(tr: StaticTransform) -> tuple[np.ndarray, np.ndarray]:
    """A link's rotation and translation (parent <- child)."""
    return mount_rotation(tr), np.array([float(tr.pose[0]), float(tr.pose[1]), float(tr.z)])


class MountTable:
    """The sensors' mounts on the robot (see the module docstring).  ``configured``: the config's
    links (``sources.static_transforms``); ``base_frame``: the robot's base frame ("" : the
    odometry's ``child_frame_id``, else ``base_link`` / ``base_footprint``).  Chains are composed
    once per frame (until a link changes) and rotations once per transform."""

    def __init__(self, configured: Sequence[StaticTransform] | None = None, base_frame: str = "") -> None:
        self.configured = {frame_name(t.child): t for t in configured or ()}
        self.base_frame = frame_name(base_frame or "")
        #: the odometry's child frames seen (the base, when none is configured), in order
        self.odometry_frames: list[str] = []
        #: the odometry's parent frames seen (world frames)
        self.world_frames: set[str] = set(WORLD_FRAMES)
        # every link by child frame: the configured ones, then the log's
        self._links: dict[str, StaticTransform] = dict(self.configured)
        self._moving: set[str] = set()  # child frames whose link changed (not mounts of a base)
        self._chains: dict[str, StaticTransform | None] = {}
        self._mounts: dict[str, StaticTransform | None] = {}  # mount() by the frame as the message names it
        self._own: dict[str, bool] = {}  # is_base() by the frame as the message names it
        # the mounts' rotations by frame (and their entries as floats)
        self._rotations: dict[str, tuple[StaticTransform | None, np.ndarray, list[float]]] = {}
        self._warned: set[str] = set()

    # ------------------------------------------------------------------ the base
    def bases(self) -> list[str]:
        """The frames that stand for the robot, preferred first: the configured base (with the other
        REP 105 name when it is ``base_link`` / ``base_footprint``), else the odometry's child
        frames, then ``base_link``, ``base_footprint``."""
        if self.base_frame:
            if is_base_frame(self.base_frame):
                prefix = self.base_frame[: -len(self.base_frame.rsplit("/", 1)[-1])]
                return [self.base_frame, *(prefix + b for b in ROBOT_FRAMES if prefix + b != self.base_frame)]
            return [self.base_frame]
        return [*self.odometry_frames, *(b for b in ROBOT_FRAMES if b not in self.odometry_frames)]

    def is_base(self, frame: str) -> bool:
        """``frame`` stands for the robot (its own frame: no mount)."""
        got = self._own.get(frame)
        if got is None:
            f = frame_name(frame)
            got = self._own[frame] = f in self.bases() if self.base_frame else \
                f in self.odometry_frames or is_base_frame(f)
        return got

    def base_name(self) -> str:
        """The base frame mounts are from (for messages)."""
        return self.bases()[0]

    def add_odometry_frames(self, frame_id: str, child_frame_id: str) -> None:
        """An odometry message's frames: its child is the robot's base (when none is configured),
        its parent a world frame."""
        parent, child = frame_name(frame_id), frame_name(child_frame_id)
        changed = False
        if parent and parent not in self.world_frames:
            self.world_frames.add(parent)
            changed = True
        if child and child not in self.odometry_frames and child != parent:
            self.odometry_frames.append(child)
            changed = changed or not self.base_frame
        if changed:
            self._forget()

    # ------------------------------------------------------------------ links
    def add_tf(self, msg: object) -> None:
        """A ``/tf_static`` or ``/tf`` message (a list of transforms): every link (a configured
        child frame is not overridden)."""
        if isinstance(msg, (list, tuple)):
            for tr in msg:
                if not isinstance(tr, StaticTransform):
                    continue
                child = frame_name(tr.child)
                if child in self.configured or child == frame_name(tr.parent):
                    continue
                old = self._links.get(child)
                if old is not None and _same(old, tr):
                    continue
                self._links[child] = tr
                if old is not None:
                    if child in self._moving and self.is_base(child):
                        continue  # the base moving in the world (/tf odom -> base_link): never a mount
                    self._moving.add(child)
                self._forget()

    def _forget(self) -> None:
        self._chains.clear()
        self._mounts.clear()
        self._own.clear()

    def _mount_link(self, tr: StaticTransform) -> bool:
        """A link that can be on a mount's chain: not the base's motion in the world."""
        child, parent = frame_name(tr.child), frame_name(tr.parent)
        if not self.is_base(child) or self.is_base(parent):
            return True
        world = parent in self.world_frames or is_world_frame(parent)
        return not world and child not in self._moving

    def _neighbours(self) -> dict[str, list[tuple[str, StaticTransform, bool]]]:
        """frame -> [(other frame, link, other is the link's child)]."""
        out: dict[str, list[tuple[str, StaticTransform, bool]]] = {}
        for tr in self._links.values():
            if not self._mount_link(tr):
                continue
            p, c = frame_name(tr.parent), frame_name(tr.child)
            out.setdefault(p, []).append((c, tr, True))
            out.setdefault(c, []).append((p, tr, False))
        return out

    def _paths(self, frame: str) -> dict[str, list[tuple[StaticTransform, bool]]]:
        """Breadth first from ``frame``: each reachable frame's shortest chain of links from it."""
        nb = self._neighbours()
        paths: dict[str, list[tuple[StaticTransform, bool]]] = {frame: []}
        todo = deque([frame])
        while todo:
            cur = todo.popleft()
            if len(paths[cur]) >= MAX_CHAIN:
                continue
            for other, tr, down in nb.get(cur, ()):
                if other not in paths:
                    paths[other] = [*paths[cur], (tr, down)]
                    todo.append(other)
        return paths

    def chain(self, frame: str) -> StaticTransform | None:
        """``base -> frame`` through the links (None: no chain reaches a base frame)."""
        f = frame_name(frame)
        if f in self._chains:
            return self._chains[f]
        paths = self._paths(f)
        out = None
        for base in self.bases():
            path = paths.get(base)
            if path is None and not self.base_frame:
                # a prefixed REP 105 frame (tb3_0/base_link) reached
                base = next((b for b in paths if b != f and is_base_frame(b)), "")
                path = paths.get(base)
            if path is None:
                continue
            if len(path) == 1 and not path[0][1] and frame_name(path[0][0].parent) == base:
                out = path[0][0]  # a mount on the base itself: the link as it is
                break
            # walk from the sensor to the base: T_base_sensor = T_base_k ... T_1_sensor
            R, t = np.eye(3), np.zeros(3)
            for tr, down in path:  # down: the link goes from the current frame to its child
                Rl, tl = _rt(tr)
                if down:  # parent = current frame: T_cur_next = T_link; we need T_next_cur = inverse
                    R, t = Rl.T @ R, Rl.T @ (t - tl)
                else:  # the current frame is the link's child: T_parent_cur = T_link
                    R, t = Rl @ R, Rl @ t + tl
            out = transform_of(base, f, t.tolist(), matrix_quaternion(R).tolist())
            break
        self._chains[f] = out
        return out

    def mount(self, frame: str) -> StaticTransform | None:
        """The base -> ``frame`` mount (None: the robot's own frame, or none known yet)."""
        try:
            return self._mounts[frame]
        except KeyError:
            pass
        f = frame_name(frame)
        out = None if not f or self.is_base(f) else self.chain(f)
        self._mounts[frame] = out
        return out

    def unconnected(self, frame: str) -> str:
        """Why ``frame`` has no mount, for the one line that reports it: the base it was looked up
        from and what the frame's links reach instead."""
        f = frame_name(frame)
        reached = sorted(k for k in self._paths(f) if k != f)
        where = f"the frames its links reach: {', '.join(reached)}" if reached else "no transform names it"
        return f"no transform chain {self.base_name()} -> {f} ({where})"

    # ------------------------------------------------------------------ rotations
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

    def warn_missing(self, frame: str, what: str = "IMU") -> None:
        """One warning per frame: no chain to the base, used unmounted (identity)."""
        f = frame_name(frame)
        if f not in self._warned:
            self._warned.add(f)
            log.warning("%s; the %s is used unmounted (as if its axes were the base's): set sources.base_frame "
                        "or give the mount (sources.static_transforms, --static-transform)", self.unconnected(f), what)
