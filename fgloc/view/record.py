"""The view's channels recorded into an MCAP with the same Foxglove schemas as the live view.

:class:`McapViewRecorder` is a :class:`fgloc.view.feed.ViewSink` that encodes
synchronously (a recording must be complete, so nothing is dropped) and writes through
any object with ``write_raw(topic, schema_name, schema_data, data, log_time_ns,
schema_encoding=..., message_encoding=...)``: the run's :class:`fgloc.io.LogWriter` (so
the channels land in ``run.mcap`` beside the ROS topics) or :class:`McapFile` (a file of
its own).  Opened in Foxglove with the layout in
``docs/foxglove/``, a recording shows the same picture as the live view.

The scan is written as bytes by :mod:`fgloc.view.wire` (the same bytes the SDK's
``foxglove.LaserScan`` encodes to, its ranges packed from the array, not one float at a time).

Particles are recorded at most every ``particles_period_s`` of log time (the live view
gets every scan's): a particle cloud per scan would dominate the file.  The other heavy
channels can be bounded the same way (``fgloc run`` does; the defaults here record all):

* ``scan_period_s``: the scan (``/fgloc/scan``) at most that often (the log's own scans are in
  ``run.mcap`` at their full rate anyway);
* ``covariance_period_s``: the fused pose's uncertainty (``/fgloc/pose/covariance``) drawn in
  the robot's frame (``base_link``, frame-locked: Foxglove carries it along with the robot
  through ``/fgloc/tf``) and re-drawn at most that often, or sooner when a sigma changes by
  more than ``covariance_change`` (a relocalization); 0: per scan in the fused pose's frame,
  as the live view draws it.  Both drawings show the same ellipse and wedge;
* ``predicted_period_s``: a scan the front-end did not match (``frontend_every``: the pose is
  the odometry prediction) is recorded (transforms, pose, fused, fix) only this long after the
  last one recorded; every matched scan is.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from fgloc.geometry import rotate_covariance
from fgloc.io.mcap_writer import LogWriter
from fgloc.io.ros import stamp_to_ns
from fgloc.types import all_finite
from fgloc.view import channels as ch
from fgloc.view.channels import BASE_FRAME
from fgloc.view.feed import ACCEPTED, PREDICTED, REJECTED, ScanView, json_ready

#: ``json.dumps(obj, separators=(",", ":"), allow_nan=False)`` with its encoder made once
_JSON = json.JSONEncoder(separators=(",", ":"), allow_nan=False).encode


class RawMcapWriter(Protocol):
    def write_raw(self, topic: str, schema_name: str, schema_data: bytes, data: bytes, log_time_ns: int,
                  schema_encoding: str = ..., message_encoding: str = ...) -> None: ...


class McapFile(LogWriter):
    """A plain MCAP file (profile none) taking :meth:`write_raw` messages; a context manager:
    the ROS 2 log writer with the view's header."""

    def __init__(self, path: str | Path) -> None:
        super().__init__(path, profile="", library="fgloc.view")


class McapViewRecorder:
    """Writes the view channels through ``writer.write_raw`` (see the module docstring).

    ``close()`` does not close ``writer`` (its owner does).
    """

    def __init__(self, writer: RawMcapWriter, particles_period_s: float = 0.5, max_particles: int = 500,
                 scan_period_s: float = 0.0, covariance_period_s: float = 0.0,
                 covariance_change: float = 1.0, predicted_period_s: float = 0.0) -> None:
        from foxglove import messages

        from fgloc.view import encode, server, wire

        server.require_foxglove()
        self._enc = encode
        self._wire = wire
        self._fm = messages
        self.writer = writer
        self.particles_period_s = float(particles_period_s)
        self.max_particles = int(max_particles)
        self.scan_period_s = float(scan_period_s)
        self.covariance_period_s = float(covariance_period_s)
        self.covariance_change = float(covariance_change)
        self.predicted_period_s = float(predicted_period_s)
        self._last_pose = -math.inf
        self._last_particles = -math.inf
        self._last_scan = -math.inf
        self._last_cov: tuple[float, tuple[float, float, float]] | None = None  # stamp, sigmas drawn
        self._json_schemas = {t: (str(sch["title"]), json.dumps(sch).encode()) for t, sch in
                              ((ch.FUSED, encode.FUSED_SCHEMA), (ch.FIX, encode.FIX_SCHEMA),
                               (ch.HEALTH, encode.HEALTH_SCHEMA))}
        self._schemas: dict[Any, tuple[str, str, bytes]] = {}
        self._trajectory = encode.GrowingPoses()  # the trajectory's poses sent so far, kept
        # per (topic, schema name): the writer's write(data, log_time_ns) with the channel looked up
        # once (a writer with raw_writer, as fgloc's LogWriter), else None (write_raw each time)
        self._raw: dict[tuple[str, str], Callable[[bytes, int], None]] = {}
        self._proto: dict[str, tuple[type, Callable[[bytes, int], None]]] = {}  # per topic: its class, _sink
        self._json_sinks: dict[str, Callable[[bytes, int], None]] = {}
        self._last_ns = 0
        # the log time (ns) to write at now, or None (then the stamp): fgloc run puts the channels at
        # the log time of the input being processed, beside the inputs on the input's recording clock
        self.clock: Callable[[], int | None] | None = None
        self.count = 0
        self.errors = 0
        # the map, given before the first input (stamp 0): written with the first message after it, at
        # that message's log time, so that a recording starts at the log's start and not in 1970
        self._pending_map: Any = None

    def _ns(self, stamp: float) -> int:
        if self.clock is not None and (now := self.clock()) is not None:
            return now
        ns = stamp_to_ns(stamp) if math.isfinite(stamp) and stamp >= 0 else self._last_ns
        self._last_ns = max(self._last_ns, ns)
        return ns

    def _schema(self, cls: Any) -> tuple[str, str, bytes]:
        # one bytes object per schema: the writer keys its schemas by their bytes (hash cached)
        s = self._schemas.get(cls)
        if s is None:
            sch = cls.get_schema()
            s = self._schemas[cls] = (sch.name, sch.encoding, bytes(sch.data))
        return s

    def _sink(self, topic: str, name: str, schema: bytes, schema_encoding: str,
              message_encoding: str) -> Callable[[bytes, int], None]:
        """``write(data, log_time_ns)`` on ``topic`` with this schema: the writer's ``raw_writer`` (its
        channel looked up once; made at the topic's first message, as the first ``write_raw`` would
        register it), else ``write_raw`` each time."""
        key = (topic, name)
        raw = self._raw.get(key)
        if raw is None:
            make = getattr(self.writer, "raw_writer", None)
            if make is not None:
                raw = make(topic, name, schema, schema_encoding, message_encoding)
            else:
                write_raw = self.writer.write_raw

                def raw(data: bytes, log_time_ns: int) -> None:
                    write_raw(topic, name, schema, data, log_time_ns, schema_encoding=schema_encoding,
                              message_encoding=message_encoding)
            self._raw[key] = raw
        return raw

    def _write(self, topic: str, msg: Any, stamp: float) -> None:
        self._write_ns(topic, msg, self._ns(stamp))

    def _flush_map(self, log_time_ns: int) -> None:
        occ, self._pending_map = self._pending_map, None
        self._write_ns(ch.MAP, self._enc.grid_message(occ, log_time_ns * 1e-9), log_time_ns)

    def _write_ns(self, topic: str, msg: Any, log_time_ns: int) -> None:
        if self._pending_map is not None:
            self._flush_map(log_time_ns)
        try:
            self._put(topic, type(msg), msg.encode(), log_time_ns)
        except (TypeError, ValueError, OverflowError):
            self.errors += 1

    def _write_wire_ns(self, topic: str, cls: type, data: bytes, log_time_ns: int) -> None:
        """A message of Foxglove class ``cls`` already encoded (:mod:`fgloc.view.wire`)."""
        if self._pending_map is not None:
            self._flush_map(log_time_ns)
        try:
            self._put(topic, cls, data, log_time_ns)
        except (TypeError, ValueError, OverflowError):
            self.errors += 1

    def _put(self, topic: str, cls: type, data: bytes, log_time_ns: int) -> None:
        hit = self._proto.get(topic)  # (message class, write) of the topic's last message
        if hit is None or hit[0] is not cls:
            name, encoding, schema = self._schema(cls)
            hit = self._proto[topic] = (cls, self._sink(topic, name, schema, encoding, "protobuf"))
        hit[1](data, log_time_ns)
        self.count += 1

    def _write_json(self, topic: str, obj: dict[str, Any], stamp: float) -> None:
        self._write_json_ns(topic, obj, self._ns(stamp))

    def _write_json_ns(self, topic: str, obj: dict[str, Any], log_time_ns: int) -> None:
        if self._pending_map is not None:
            self._flush_map(log_time_ns)
        try:
            data = _JSON(obj).encode()
        except (TypeError, ValueError):  # numpy values, NaN: the slow, careful way
            data = json.dumps(json_ready(obj), separators=(",", ":")).encode()
        write = self._json_sinks.get(topic)
        if write is None:
            name, schema = self._json_schemas[topic]
            write = self._json_sinks[topic] = self._sink(topic, name, schema, "jsonschema", "json")
        write(data, log_time_ns)
        self.count += 1

    # ------------------------------------------------------------------ ViewSink
    def on_map(self, occ_map: Any, stamp: float) -> None:
        if not (math.isfinite(stamp) and stamp > 0):  # before any input: at the next message's log time
            self._pending_map = occ_map
            return
        self._write(ch.MAP, self._enc.grid_message(occ_map, stamp), stamp)

    @staticmethod
    def _due(last: float, stamp: float, period: float) -> bool:
        return period <= 0 or not math.isfinite(stamp) or stamp < last or stamp - last >= period

    def on_scan(self, view: ScanView) -> None:
        enc = self._enc
        stamp = view.stamp
        ns = self._ns(stamp)  # every message of the scan at the same log time
        if self._due(self._last_scan, stamp, self.scan_period_s):
            self._last_scan = stamp
            self._write_wire_ns(ch.SCAN, self._fm.LaserScan, self._wire.laser_scan(view.scan), ns)
        if view.status == PREDICTED and not self._due(self._last_pose, stamp, self.predicted_period_s):
            return
        self._last_pose = stamp
        fused = view.fused
        if view.transforms:
            self._write_ns(ch.TF, enc.transforms_message(view.transforms, fused.stamp if fused is not None else stamp),
                           ns)
        if fused is not None:
            self._write_ns(ch.POSE, enc.pose_message(fused), ns)
            if self.covariance_period_s <= 0:
                self._write_ns(ch.POSE_COVARIANCE, enc.covariance_scene(fused), ns)
            else:
                self._covariance(view, ns)
            self._write_json_ns(ch.FUSED, enc.fused_json(fused), ns)
        self._write_json_ns(ch.FIX, enc.fix_json(stamp, view.status, view.reason, view.fix, fused), ns)
        if view.fix is not None and view.status in (ACCEPTED, REJECTED):
            topic = ch.FIX_ACCEPTED if view.status == ACCEPTED else ch.FIX_REJECTED
            self._write_ns(topic, enc.pose_message(view.fix), ns)

    def _covariance(self, view: ScanView, log_time_ns: int) -> None:
        """The uncertainty in the robot's frame, re-drawn every ``covariance_period_s`` or on change."""
        fused = view.fused
        assert fused is not None
        c = fused.cov
        s0, s1, s2 = _sigma(float(c[0, 0])), _sigma(float(c[1, 1])), _sigma(float(c[2, 2]))
        last = self._last_cov
        if last is not None and not self._due(last[0], view.stamp, self.covariance_period_s):
            k = 1.0 + self.covariance_change
            b0, b1, b2 = last[1]
            if b0 / k <= s0 <= b0 * k and b1 / k <= s1 <= b1 * k and b2 / k <= s2 <= b2 * k:
                return
        self._last_cov = (view.stamp, (s0, s1, s2))
        base = view.transforms[-1].parent if view.transforms else BASE_FRAME
        self._write_ns(ch.POSE_COVARIANCE, body_covariance_scene(fused, base), log_time_ns)

    def on_particles(self, stamp: float, frame_id: str, poses: np.ndarray) -> None:
        if stamp - self._last_particles < self.particles_period_s:
            return
        self._last_particles = stamp
        step = max(1, -(-len(poses) // self.max_particles))
        self._write(ch.PARTICLES, self._enc.poses_message(stamp, frame_id, poses[::step]), stamp)

    def on_trajectory(self, stamp: float, frame_id: str, poses: np.ndarray) -> None:
        self._write(ch.TRAJECTORY, self._trajectory.message(stamp, frame_id, poses), stamp)

    def on_health(self, stamp: float, health: dict[str, Any]) -> None:
        self._write_json(ch.HEALTH, health, stamp)

    def close(self) -> None:
        if self._pending_map is not None:  # nothing came after it: at the last time known
            self._flush_map(self._last_ns)


def _sigma(v: float) -> float:
    return math.sqrt(v) if math.isfinite(v) and v > 0 else 0.0


def body_covariance_scene(fused: Any, base_frame: str = BASE_FRAME) -> Any:
    """The fused pose's 2-sigma xy ellipse and yaw wedge (as
    :func:`fgloc.view.encode.covariance_scene`) drawn in the robot's frame ``base_frame``,
    frame-locked: the covariance rotated into that frame, the wedge around its x axis."""
    from foxglove import messages as fm

    from fgloc.view import encode

    cov = np.asarray(fused.cov, dtype=float).reshape(3, 3)
    body = rotate_covariance(cov, -float(fused.pose[2]))  # map axes -> the robot's
    color = fm.Color(r=1.0, g=0.55, b=0.0, a=1.0)
    lines = []
    if all_finite(cov):
        ell = encode.covariance_ellipse(body)
        pts = [fm.Point3(x=px, y=py, z=0.02) for px, py in ell.tolist()]
        lines.append(fm.LinePrimitive(type=fm.LinePrimitiveLineType.LineLoop, thickness=2.0, scale_invariant=True,
                                      points=pts, color=color))
    v_yaw = float(cov[2, 2])
    s_yaw = math.sqrt(max(v_yaw, 0.0)) * encode.COVARIANCE_SIGMAS if math.isfinite(v_yaw) else 0.0
    a = np.linspace(-min(s_yaw, math.pi), min(s_yaw, math.pi), 7)
    arc = np.column_stack([encode.WEDGE_LENGTH_M * np.cos(a), encode.WEDGE_LENGTH_M * np.sin(a)]).tolist()
    wedge = [fm.Point3(x=px, y=py, z=0.02) for px, py in [[0.0, 0.0], *arc, [0.0, 0.0]]]
    lines.append(fm.LinePrimitive(type=fm.LinePrimitiveLineType.LineStrip, thickness=2.0, scale_invariant=True,
                                  points=wedge, color=color))
    ent = fm.SceneEntity(timestamp=encode.timestamp(fused.stamp), frame_id=base_frame, id="fused_covariance",
                         frame_locked=True, lines=lines)
    return fm.SceneUpdate(entities=[ent])
