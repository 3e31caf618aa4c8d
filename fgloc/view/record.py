"""The view's channels recorded into an MCAP with the same Foxglove schemas as the live view.

:class:`McapViewRecorder` is a :class:`fgloc.view.feed.ViewSink` that encodes
synchronously (a recording must be complete, so nothing is dropped) and writes through
any object with ``write_raw(topic, schema_name, schema_data, data, log_time_ns,
schema_encoding=..., message_encoding=...)``: the run's :class:`fgloc.io.LogWriter` (so
the channels land in ``run.mcap`` beside the ROS topics) or :class:`McapFile` (a file of
its own).  Opened in Foxglove with the layout in
``docs/foxglove/``, a recording shows the same picture as the live view.

Particles are recorded at most every ``particles_period_s`` of log time (the live view
gets every scan's): a particle cloud per scan would dominate the file.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from fgloc.errors import LogError
from fgloc.io.log import stamp_to_ns
from fgloc.view import channels as ch
from fgloc.view.feed import ACCEPTED, REJECTED, ScanView, json_ready


class RawMcapWriter(Protocol):
    def write_raw(self, topic: str, schema_name: str, schema_data: bytes, data: bytes, log_time_ns: int,
                  schema_encoding: str = ..., message_encoding: str = ...) -> None: ...


class McapFile:
    """A plain MCAP file (profile none) taking :meth:`write_raw` messages; a context manager."""

    def __init__(self, path: str | Path) -> None:
        from mcap.writer import CompressionType, Writer

        self.path = Path(path)
        try:
            self._file = self.path.open("wb")
        except OSError as e:
            raise LogError(f"{self.path}: cannot write ({e.strerror or e})") from None
        self._writer = Writer(self._file, compression=CompressionType.ZSTD)
        self._writer.start(profile="", library="fgloc.view")
        self._schemas: dict[tuple[str, str], int] = {}
        self._channels: dict[tuple[str, str], int] = {}
        self._seq = 0
        self.count = 0

    def write_raw(self, topic: str, schema_name: str, schema_data: bytes, data: bytes, log_time_ns: int,
                  schema_encoding: str = "protobuf", message_encoding: str = "protobuf") -> None:
        key = (schema_name, schema_encoding)
        sid = self._schemas.get(key)
        if sid is None:
            sid = self._writer.register_schema(schema_name, schema_encoding, schema_data)
            self._schemas[key] = sid
        ckey = (topic, schema_name)
        cid = self._channels.get(ckey)
        if cid is None:
            cid = self._writer.register_channel(topic, message_encoding, sid)
            self._channels[ckey] = cid
        self._writer.add_message(cid, log_time=int(log_time_ns), data=data, publish_time=int(log_time_ns),
                                 sequence=self._seq)
        self._seq += 1
        self.count += 1

    def close(self) -> None:
        if not self._file.closed:
            self._writer.finish()
            self._file.close()

    def __enter__(self) -> McapFile:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class McapViewRecorder:
    """Writes the view channels through ``writer.write_raw`` (see the module docstring).

    ``close()`` does not close ``writer`` (its owner does).
    """

    def __init__(self, writer: RawMcapWriter, particles_period_s: float = 0.5, max_particles: int = 500) -> None:
        from fgloc.view import encode, server

        server.require_foxglove()
        self._enc = encode
        self.writer = writer
        self.particles_period_s = float(particles_period_s)
        self.max_particles = int(max_particles)
        self._last_particles = -math.inf
        self._json_schemas = {t: (str(sch["title"]), json.dumps(sch).encode()) for t, sch in
                              ((ch.FUSED, encode.FUSED_SCHEMA), (ch.FIX, encode.FIX_SCHEMA),
                               (ch.HEALTH, encode.HEALTH_SCHEMA))}
        self._schemas: dict[Any, tuple[str, str, bytes]] = {}
        self._last_ns = 0
        # the log time (ns) to write at now, or None (then the stamp): fgloc run puts the channels at
        # the log time of the input being processed, beside the inputs on the input's recording clock
        self.clock: Callable[[], int | None] | None = None
        self.count = 0
        self.errors = 0

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

    def _write(self, topic: str, msg: Any, stamp: float) -> None:
        try:
            name, encoding, data = self._schema(type(msg))
            self.writer.write_raw(topic, name, data, msg.encode(), self._ns(stamp),
                                  schema_encoding=encoding, message_encoding="protobuf")
            self.count += 1
        except (TypeError, ValueError, OverflowError):
            self.errors += 1

    def _write_json(self, topic: str, obj: dict[str, Any], stamp: float) -> None:
        name, schema = self._json_schemas[topic]
        try:
            data = json.dumps(obj, separators=(",", ":"), allow_nan=False).encode()
        except (TypeError, ValueError):  # numpy values, NaN: the slow, careful way
            data = json.dumps(json_ready(obj), separators=(",", ":")).encode()
        self.writer.write_raw(topic, name, schema, data, self._ns(stamp), schema_encoding="jsonschema",
                              message_encoding="json")
        self.count += 1

    # ------------------------------------------------------------------ ViewSink
    def on_map(self, occ_map: Any, stamp: float) -> None:
        self._write(ch.MAP, self._enc.grid_message(occ_map, stamp), stamp)

    def on_scan(self, view: ScanView) -> None:
        enc = self._enc
        self._write(ch.SCAN, enc.scan_message(view.scan), view.stamp)
        if view.transforms:
            st = view.fused.stamp if view.fused is not None else view.stamp
            self._write(ch.TF, enc.transforms_message(view.transforms, st), view.stamp)
        if view.fused is not None:
            self._write(ch.POSE, enc.pose_message(view.fused), view.stamp)
            self._write(ch.POSE_COVARIANCE, enc.covariance_scene(view.fused), view.stamp)
            self._write_json(ch.FUSED, enc.fused_json(view.fused), view.stamp)
        self._write_json(ch.FIX, enc.fix_json(view.stamp, view.status, view.reason, view.fix, view.fused), view.stamp)
        if view.fix is not None and view.status in (ACCEPTED, REJECTED):
            topic = ch.FIX_ACCEPTED if view.status == ACCEPTED else ch.FIX_REJECTED
            self._write(topic, enc.pose_message(view.fix), view.stamp)

    def on_particles(self, stamp: float, frame_id: str, poses: np.ndarray) -> None:
        if stamp - self._last_particles < self.particles_period_s:
            return
        self._last_particles = stamp
        step = max(1, -(-len(poses) // self.max_particles))
        self._write(ch.PARTICLES, self._enc.poses_message(stamp, frame_id, poses[::step]), stamp)

    def on_trajectory(self, stamp: float, frame_id: str, poses: np.ndarray) -> None:
        self._write(ch.TRAJECTORY, self._enc.poses_message(stamp, frame_id, poses), stamp)

    def on_health(self, stamp: float, health: dict[str, Any]) -> None:
        self._write_json(ch.HEALTH, health, stamp)

    def close(self) -> None:
        pass
