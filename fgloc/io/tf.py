"""tf chains: the 2-D ``base_link -> laser`` mount composed from a log's transforms.

Transforms arrive as 2-D :class:`StaticTransform` (x, y, yaw of the quaternion, z kept) with
a flag per transform telling whether it turns the child's z axis down (a scanner mounted
upside down; :func:`fgloc.io.ros.tf_flips`).  Such a rotation is ``Rz(yaw) Rx(pi)``; a chain
through an odd number of them is an upside-down scanner, whose scans an upright one in the
same place sees mirrored (``angle_min`` and ``angle_increment`` negated), as nav2 does.
"""

from __future__ import annotations

import numpy as np

from fgloc.geometry import compose
from fgloc.types import StaticTransform

BASE_FRAMES = ("base_link", "base_footprint")
MAX_CHAIN = 32


class TfTree:
    """Transforms by child frame (the first one seen wins) and their upside-down flags."""

    def __init__(self) -> None:
        self.parents: dict[str, StaticTransform] = {}
        self.flipped: dict[tuple[str, str], bool] = {}

    def add(self, transforms: list[StaticTransform], flips: list[bool] | None = None) -> None:
        for k, tr in enumerate(transforms):
            self.parents.setdefault(tr.child, tr)
            if flips is not None and flips[k]:
                self.flipped[(tr.parent, tr.child)] = True

    def chain(self, frame: str) -> tuple[StaticTransform, bool] | None:
        """``(base -> frame, mirrored)`` or None when no chain reaches a base frame: the 2-D
        mount and whether an odd number of the transforms on the way turn the z axis down."""
        pose, z, cur, mirrored = np.zeros(3), 0.0, frame, False
        for _ in range(MAX_CHAIN):
            if cur in BASE_FRAMES:
                return StaticTransform(cur, frame, pose, z), mirrored
            tr = self.parents.get(cur)
            if tr is None:
                return None
            if self.flipped.get((tr.parent, tr.child), False):
                # R = Rz(yaw) Rx(pi): a child pose (x, y, th) is (x, -y, -th) before the yaw
                pose = np.array([pose[0], -pose[1], -pose[2]])
                z = -z
                mirrored = not mirrored
            pose = compose(tr.pose, pose)
            z += tr.z
            cur = tr.parent
        return None
