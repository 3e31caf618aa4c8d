"""fgloc data -> Foxglove messages (``foxglove.messages``, protobuf-encoded by the SDK).

Pure functions, no I/O; importing this module needs foxglove-sdk (``pip install
"fgloc[view]"``).  Stamps are seconds (float) -> ``foxglove.Timestamp``; planar poses
``[x, y, yaw]`` -> 3-D poses in the z = 0 plane (the laser at its mount height).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from foxglove import messages as fm
from numpy.typing import NDArray

from fgloc.geometry import yaw_to_quaternion
from fgloc.io.ros import stamp_to_sec_nsec
from fgloc.types import LaserScan, PoseFix, StaticTransform, all_finite

FloatArray = NDArray[np.float64]

GRID_FIELDS = ("red", "green", "blue", "alpha", "occupancy")  # byte offsets 0..4 of a cell
GRID_CELL_STRIDE = 5
COVARIANCE_SIGMAS = 2.0          # the ellipse is drawn at this many standard deviations
ELLIPSE_POINTS = 32
WEDGE_LENGTH_M = 0.6


def timestamp(stamp: float) -> Any:
    sec, nsec = stamp_to_sec_nsec(max(float(stamp), 0.0) if math.isfinite(stamp) else 0.0)
    return fm.Timestamp(sec, nsec)


def pose3(pose: FloatArray, z: float = 0.0) -> Any:
    # yaw_to_quaternion in scalar maths (the same bits: numpy's float64 sin / cos are libm's), a numpy
    # call per message was most of this function
    h = 0.5 * float(pose[2])
    return fm.Pose(position=fm.Vector3(x=float(pose[0]), y=float(pose[1]), z=float(z)),
                   orientation=fm.Quaternion(x=0.0, y=0.0, z=math.sin(h), w=math.cos(h)))


def grid_cells(occ_map: Any) -> NDArray[np.uint8]:
    """``(H, W, 5)`` bytes per cell: grey level (free light, occupied black), alpha (unknown
    translucent) and the occupancy value itself as int8 (-1 unknown, 0..100)."""
    v = np.asarray(occ_map.data, dtype=np.int16)
    unknown = v < 0
    occ = np.clip(v, 0, 100).astype(np.float64)
    grey = np.where(unknown, 128, np.round(235.0 * (1.0 - occ / 100.0))).astype(np.uint8)
    out = np.empty(v.shape + (GRID_CELL_STRIDE,), dtype=np.uint8)
    out[..., 0] = grey
    out[..., 1] = grey
    out[..., 2] = grey
    out[..., 3] = np.where(unknown, 80, 255).astype(np.uint8)
    out[..., 4] = np.clip(v, -1, 100).astype(np.int8).view(np.uint8)
    return out


def grid_message(occ_map: Any, stamp: float, frame_id: str = "map") -> Any:
    """The map (an :class:`~fgloc.maps.OccupancyMap`, or anything with its ``data``, ``resolution``
    and ``origin``) as a ``foxglove.Grid``: row 0 is the bottom row (smallest y), as in the map."""
    cells = grid_cells(occ_map)
    width = int(cells.shape[1])
    u8, i8 = fm.PackedElementFieldNumericType.Uint8, fm.PackedElementFieldNumericType.Int8
    fields = [fm.PackedElementField(name=n, offset=i, type=(i8 if n == "occupancy" else u8))
              for i, n in enumerate(GRID_FIELDS)]
    res = float(occ_map.resolution)
    return fm.Grid(timestamp=timestamp(stamp), frame_id=frame_id, pose=pose3(occ_map.origin),
                   column_count=width, cell_size=fm.Vector2(x=res, y=res),
                   row_stride=width * GRID_CELL_STRIDE, cell_stride=GRID_CELL_STRIDE,
                   fields=fields, data=cells.tobytes())


def scan_message(scan: LaserScan) -> Any:
    """The scan in its own frame; beams the localizer does not use (no return, out of
    [range_min, range_max], NaN) are NaN so the view shows what was matched."""
    n = len(scan.ranges)
    r = np.where(scan.valid_mask(), np.asarray(scan.ranges, dtype=np.float64), np.nan)
    end = float(scan.angle_min + scan.angle_increment * max(n - 1, 0))
    kw: dict[str, Any] = {}
    if scan.intensities is not None and len(scan.intensities) == n:
        kw["intensities"] = np.asarray(scan.intensities, dtype=np.float64).tolist()
    return fm.LaserScan(timestamp=timestamp(scan.stamp), frame_id=scan.frame_id or "laser", pose=pose3(np.zeros(3)),
                        start_angle=float(scan.angle_min), end_angle=end, ranges=r.tolist(), **kw)


def transforms_message(transforms: list[StaticTransform], stamp: float) -> Any:
    ts = timestamp(stamp)
    out = []
    for tr in transforms:
        h = 0.5 * float(tr.pose[2])
        out.append(fm.FrameTransform(
            timestamp=ts, parent_frame_id=tr.parent, child_frame_id=tr.child,
            translation=fm.Vector3(x=float(tr.pose[0]), y=float(tr.pose[1]), z=float(tr.z)),
            rotation=fm.Quaternion(x=0.0, y=0.0, z=math.sin(h), w=math.cos(h))))
    return fm.FrameTransforms(transforms=out)


def pose_message(fix: PoseFix, frame_id: str | None = None) -> Any:
    return fm.PoseInFrame(timestamp=timestamp(fix.stamp), frame_id=frame_id or fix.frame_id, pose=pose3(fix.pose))


def _pose_objects(p: FloatArray) -> list[Any]:
    """``foxglove.Pose`` of each planar pose row of ``p`` (z = 0, a yaw-only quaternion)."""
    q = yaw_to_quaternion(p[:, 2]).reshape(-1, 4)
    qz, qw = q[:, 2].tolist(), q[:, 3].tolist()
    xs, ys = p[:, 0].tolist(), p[:, 1].tolist()
    return [fm.Pose(position=fm.Vector3(x=x, y=y, z=0.0), orientation=fm.Quaternion(x=0.0, y=0.0, z=z, w=w))
            for x, y, z, w in zip(xs, ys, qz, qw, strict=True)]


def poses_message(stamp: float, frame_id: str, poses: FloatArray) -> Any:
    p = np.asarray(poses, dtype=float).reshape(-1, 3)
    return fm.PosesInFrame(timestamp=timestamp(stamp), frame_id=frame_id, poses=_pose_objects(p))


class GrowingPoses:
    """:func:`poses_message` of a pose list that grows at its end (the fused trajectory so far, sent
    again and again): the ``foxglove.Pose`` objects of the poses already sent are kept and only the new
    ones are made (a 10-minute run re-sent thousands of poses each time).  The same message: a pose is
    made from its own row whatever else is in the array."""

    def __init__(self) -> None:
        self._rows = np.zeros((0, 3))
        self._objects: list[Any] = []

    def message(self, stamp: float, frame_id: str, poses: FloatArray) -> Any:
        p = np.asarray(poses, dtype=float).reshape(-1, 3)
        k = len(self._objects)
        if k > len(p) or p[:k].tobytes() != self._rows[:k].tobytes():
            k = 0  # not the same beginning: made anew
            self._objects = []
        if k < len(p):
            self._objects = self._objects + _pose_objects(p[k:])
        self._rows = p.copy()
        return fm.PosesInFrame(timestamp=timestamp(stamp), frame_id=frame_id, poses=self._objects)


def covariance_ellipse(cov: FloatArray, sigmas: float = COVARIANCE_SIGMAS, n: int = ELLIPSE_POINTS) -> FloatArray:
    """``(n, 2)`` points of the ``sigmas``-sigma ellipse of the xy block of ``cov`` (centred at 0)."""
    c = np.asarray(cov, dtype=float)[:2, :2]
    c = 0.5 * (c + c.T)
    w, v = np.linalg.eigh(c)
    w = np.sqrt(np.maximum(w, 0.0)) * sigmas
    cos_a, sin_a = _circle(n)
    unit = np.column_stack([cos_a * w[0], sin_a * w[1]])
    return unit @ v.T


_CIRCLES: dict[int, tuple[FloatArray, FloatArray]] = {}


def _circle(n: int) -> tuple[FloatArray, FloatArray]:
    """The cosines and sines of ``n`` angles evenly around the circle from 0 (made once per ``n``)."""
    c = _CIRCLES.get(n)
    if c is None:
        a = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
        c = _CIRCLES[n] = (np.cos(a), np.sin(a))
    return c


def covariance_scene(fused: PoseFix, frame_id: str | None = None) -> Any:
    """The fused pose's uncertainty: the 2-sigma xy ellipse and the +-2-sigma yaw wedge."""
    cov = np.asarray(fused.cov, dtype=float).reshape(3, 3)
    x, y, yaw = (float(v) for v in fused.pose)
    color = fm.Color(r=1.0, g=0.55, b=0.0, a=1.0)
    ell = covariance_ellipse(cov) if all_finite(cov) else np.zeros((0, 2))
    lines = []
    if len(ell):
        pts = [fm.Point3(x=px, y=py, z=0.02) for px, py in (ell + (x, y)).tolist()]
        lines.append(fm.LinePrimitive(type=fm.LinePrimitiveLineType.LineLoop, thickness=2.0, scale_invariant=True,
                                      points=pts, color=color))
    s_yaw = math.sqrt(max(float(cov[2, 2]), 0.0)) * COVARIANCE_SIGMAS if math.isfinite(float(cov[2, 2])) else 0.0
    a = np.linspace(yaw - min(s_yaw, math.pi), yaw + min(s_yaw, math.pi), 7)
    arc = np.column_stack([x + WEDGE_LENGTH_M * np.cos(a), y + WEDGE_LENGTH_M * np.sin(a)]).tolist()
    wedge = [fm.Point3(x=px, y=py, z=0.02) for px, py in [[x, y], *arc, [x, y]]]
    lines.append(fm.LinePrimitive(type=fm.LinePrimitiveLineType.LineStrip, thickness=2.0, scale_invariant=True,
                                  points=wedge, color=color))
    ent = fm.SceneEntity(timestamp=timestamp(fused.stamp), frame_id=frame_id or fused.frame_id,
                         id="fused_covariance", lines=lines)
    return fm.SceneUpdate(entities=[ent])


def _sigma_of(v: float) -> float | None:
    return math.sqrt(v) if math.isfinite(v) and v >= 0 else None


def _sigmas_flat(c: FloatArray) -> tuple[float | None, float | None, float | None]:
    sx, sy, syaw = _sigma_of(c.item(0)), _sigma_of(c.item(4)), _sigma_of(c.item(8))
    return sx, sy, (None if syaw is None else math.degrees(syaw))


def sigmas(cov: FloatArray) -> tuple[float | None, float | None, float | None]:
    """The standard deviations of x (m), y (m) and yaw (deg) of a 3x3 covariance (None: not a variance)."""
    return _sigmas_flat(np.asarray(cov, dtype=float).reshape(9))


def fused_json(fused: PoseFix) -> dict[str, Any]:
    c = np.asarray(fused.cov, dtype=float).reshape(9)
    sx, sy, syaw = _sigmas_flat(c)
    p = fused.pose
    return {"stamp": float(fused.stamp), "frame_id": fused.frame_id, "source": fused.source,
            "x_m": float(p[0]), "y_m": float(p[1]), "yaw_deg": math.degrees(float(p[2])),
            "sigma_x_m": sx, "sigma_y_m": sy, "sigma_yaw_deg": syaw, "cov": c.tolist()}


def fix_json(stamp: float, status: str, reason: str, fix: PoseFix | None, fused: PoseFix | None) -> dict[str, Any]:
    """The front-end result of one scan; ``offset_from_fused_*``: the fix minus the fused pose."""
    out: dict[str, Any] = {"stamp": float(stamp), "status": status, "reason": reason}
    if fix is not None:
        sx, sy, syaw = sigmas(fix.cov)
        out.update({"source": fix.source, "quality": float(fix.quality), "x_m": float(fix.pose[0]),
                    "y_m": float(fix.pose[1]), "yaw_deg": math.degrees(float(fix.pose[2])),
                    "sigma_x_m": sx, "sigma_y_m": sy, "sigma_yaw_deg": syaw})
        if fused is not None:
            dx, dy = float(fix.pose[0] - fused.pose[0]), float(fix.pose[1] - fused.pose[1])
            dyaw = math.remainder(float(fix.pose[2] - fused.pose[2]), 2.0 * math.pi)
            out.update({"offset_from_fused_m": math.hypot(dx, dy), "offset_from_fused_deg": math.degrees(dyaw)})
    return out


# JSON schemas of the JSON channels (what Foxglove's plot / raw-message panels list)
_NUM = {"type": ["number", "null"]}
FUSED_SCHEMA: dict[str, Any] = {
    "type": "object", "title": "fgloc.Fused",
    "properties": {"stamp": {"type": "number"}, "frame_id": {"type": "string"}, "source": {"type": "string"},
                   "x_m": _NUM, "y_m": _NUM, "yaw_deg": _NUM, "sigma_x_m": _NUM, "sigma_y_m": _NUM,
                   "sigma_yaw_deg": _NUM, "cov": {"type": "array", "items": {"type": "number"}}},
}
FIX_SCHEMA: dict[str, Any] = {
    "type": "object", "title": "fgloc.Fix",
    "properties": {"stamp": {"type": "number"}, "status": {"type": "string"}, "reason": {"type": "string"},
                   "source": {"type": "string"}, "quality": _NUM, "x_m": _NUM, "y_m": _NUM, "yaw_deg": _NUM,
                   "sigma_x_m": _NUM, "sigma_y_m": _NUM, "sigma_yaw_deg": _NUM,
                   "offset_from_fused_m": _NUM, "offset_from_fused_deg": _NUM},
}
_SOURCE = {"type": "object", "properties": {"count": {"type": "integer"}, "rate_hz": _NUM,
                                            "skipped": {"type": "integer"}}}
HEALTH_SCHEMA: dict[str, Any] = {
    "type": "object", "title": "fgloc.Health",
    "properties": {"stamp": {"type": "number"}, "frame_id": {"type": "string"},
                   "sources": {"type": "object", "properties": {"scan": _SOURCE, "odom": _SOURCE, "imu": _SOURCE}},
                   "localizer": {"type": "object"}, "backend": {"type": "object"}, "frontend": {"type": "string"},
                   "view": {"type": "object"}},
}
