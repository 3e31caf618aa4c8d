"""Write ROS 2 MCAP logs (profile ``ros2``, ``cdr`` messages, ``ros2msg`` schemas as rosbag2
stores them), through :class:`fgloc.io.mcap_format.StreamWriter` (chunked, indexed, CRCs).

:meth:`LogWriter.write` encodes fgloc objects with the fixed-layout encoders of
:mod:`fgloc.io.fastcdr` (byte-identical to mcap_ros2's generic encoder); the MCAP log time
is the message stamp unless given.  A transform list written without ``stamp`` gets the
stamp of the next message written (the start of the log), so it is read first.

:meth:`LogWriter.write_raw` / :meth:`LogWriter.copy` write a message as the bytes it already
has (an input log's record, :class:`fgloc.io.source.Record`) with its own schema: no decode /
encode round trip.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from functools import partial
from pathlib import Path
from typing import IO, Any

from fgloc.errors import LogError
from fgloc.io import fastcdr
from fgloc.io.mcap_format import StreamWriter
from fgloc.io.msgdefs import MSG_TEXT, full_text, short_name
from fgloc.io.ros import stamp_to_ns
from fgloc.io.source import Record
from fgloc.io.topics import IMU, LASER_SCAN, ODOMETRY, POSE_COV_STAMPED, TF_MESSAGE, TWIST_COV_STAMPED
from fgloc.types import CompassHeading, Imu, LaserScan, Odometry, PoseFix, StaticTransform, Twist

LIBRARY = "fgloc"


def message_encoder(msg: object) -> tuple[str, Callable[[Any, float], bytes]] | None:
    """``(ROS 2 type, encode(msg, stamp) -> CDR bytes)`` of an fgloc message (None: not one of these)."""
    if isinstance(msg, LaserScan):
        return LASER_SCAN, fastcdr.encode_laser_scan
    if isinstance(msg, Odometry):
        return ODOMETRY, fastcdr.encode_odometry
    if isinstance(msg, Imu):
        return IMU, fastcdr.encode_imu
    if isinstance(msg, CompassHeading):
        return IMU, fastcdr.encode_compass
    if isinstance(msg, PoseFix):
        return POSE_COV_STAMPED, fastcdr.encode_pose_fix
    if isinstance(msg, Twist):
        return TWIST_COV_STAMPED, fastcdr.encode_twist
    return None


def _is_tf(msg: object) -> bool:
    return isinstance(msg, list | tuple) and all(isinstance(x, StaticTransform) for x in msg)


class LogWriter:
    """Write fgloc messages into a ROS 2 MCAP (profile ros2, cdr, ros2msg schemas).

    ``profile``/``library``: the MCAP header's (``profile=""`` for a plain MCAP of
    :meth:`write_raw` messages, as :class:`fgloc.view.record.McapFile`).  ``file``: an open
    binary file to write to instead of opening ``path`` (e.g. a
    :class:`fgloc.io.outputs.GuardedFile`; ``path`` then only names it).

    A context manager; ``write(topic, msg, stamp=None, log_time_ns=None)`` takes a
    :class:`LaserScan`, :class:`Odometry`, :class:`Imu` (the whole message),
    :class:`CompassHeading` (yaw and yaw rate only), :class:`PoseFix` or
    ``list[StaticTransform]`` (a :class:`~fgloc.types.Transform3D` with its whole rotation).
    Header stamps come from ``msg.stamp`` (or ``stamp``), the log time is the same unless
    ``log_time_ns`` is given (e.g. an input's record time).
    """

    def __init__(self, path: str | Path, chunk_size: int = 1024 * 1024, compression: str = "zstd",
                 profile: str = "ros2", library: str = LIBRARY, file: Any = None) -> None:
        self.path = Path(path)
        try:
            if file is None and self.path.parent != Path(""):
                self.path.parent.mkdir(parents=True, exist_ok=True)
            self._file: IO[bytes] = self.path.open("wb") if file is None else file
        except OSError as e:
            raise LogError(f"{self.path}: cannot write log ({e.strerror or e})") from None
        comp = {"zstd": "zstd", "lz4": "lz4", "none": ""}[compression]
        self._writer = StreamWriter(self._file, profile=profile, library=library, chunk_size=chunk_size,
                                    compression=comp)
        self._schemas: dict[tuple[str, str, bytes], int] = {}
        self._channels: dict[tuple[str, int, str], int] = {}
        self._std: dict[tuple[str, str], int] = {}  # (topic, type) -> channel of fgloc's own schemas
        self._copied: dict[tuple[str, int], tuple[Any, int]] = {}  # (topic, id(input channel)) -> it, channel
        self._pending_tf: list[tuple[str, list[StaticTransform]]] = []
        self._last_stamp: float | None = None
        self.count = 0

    # -- registration ------------------------------------------------------------------------
    def _schema_id(self, name: str, encoding: str, data: bytes) -> int:
        key = (name, encoding, data)
        sid = self._schemas.get(key)
        if sid is None:
            sid = self._schemas[key] = self._writer.add_schema(name, encoding, data)
        return sid

    def _channel_id(self, topic: str, schema_id: int, message_encoding: str = "cdr") -> int:
        key = (topic, schema_id, message_encoding)
        cid = self._channels.get(key)
        if cid is None:
            cid = self._channels[key] = self._writer.add_channel(topic, message_encoding, schema_id)
        return cid

    def _std_channel(self, topic: str, type_name: str) -> int:
        cid = self._std.get((topic, type_name))
        if cid is None:
            sid = self._schema_id(type_name, "ros2msg", full_text(type_name).encode())
            cid = self._std[(topic, type_name)] = self._channel_id(topic, sid)
        return cid

    # -- writing -----------------------------------------------------------------------------
    def write(self, topic: str, msg: object, stamp: float | None = None, log_time_ns: int | None = None) -> None:
        """Write one message; ``stamp`` overrides ``msg.stamp`` (header and log time)."""
        enc = message_encoder(msg)
        if enc is None:
            if not _is_tf(msg):
                raise TypeError(f"cannot write {type(msg).__name__} to a log")
            tfs = list(msg)  # type: ignore[call-overload]
            if stamp is None:  # stamped with the next message's time (the start of the log)
                if self._last_stamp is None:
                    self._pending_tf.append((topic, tfs))
                    return
                stamp = self._last_stamp
            self._flush_tf(float(stamp))
            self._emit(topic, TF_MESSAGE, fastcdr.encode_tf(tfs, float(stamp)), float(stamp), log_time_ns)
            return
        type_name, encode = enc
        st = float(msg.stamp if stamp is None else stamp)  # type: ignore[attr-defined]
        self._flush_tf(st)
        self._emit(topic, type_name, encode(msg, st), st, log_time_ns)

    def _flush_tf(self, stamp: float) -> None:
        if self._pending_tf:
            pending, self._pending_tf = self._pending_tf, []
            for ptopic, pmsg in pending:
                self._emit(ptopic, TF_MESSAGE, fastcdr.encode_tf(pmsg, stamp), stamp, None)

    def _emit(self, topic: str, type_name: str, data: bytes, stamp: float, log_time_ns: int | None) -> None:
        lt = max(stamp_to_ns(stamp), 0) if log_time_ns is None else int(log_time_ns)
        self._writer.add_message(self._std_channel(topic, type_name), lt, data, lt, self.count)
        self._last_stamp = stamp
        self.count += 1

    def write_raw(self, topic: str, schema_name: str, schema_data: bytes, data: bytes, log_time_ns: int,
                  schema_encoding: str = "ros2msg", message_encoding: str = "cdr",
                  publish_time_ns: int | None = None) -> None:
        """Write a message as the bytes it already has (``data``, e.g. an input log's CDR) on
        ``topic`` with its schema: no decode / encode.  Pending transform lists get this
        message's log time as their stamp."""
        self._write_raw(self._raw_channel(topic, schema_name, schema_data, schema_encoding, message_encoding),
                        data, log_time_ns, publish_time_ns)

    def raw_writer(self, topic: str, schema_name: str, schema_data: bytes, schema_encoding: str = "ros2msg",
                   message_encoding: str = "cdr") -> Callable[[bytes, int], None]:
        """``write(data, log_time_ns)``: :meth:`write_raw` on ``topic`` with this schema, its channel
        looked up once (registered now, as the first :meth:`write_raw` would)."""
        return partial(self._write_raw, self._raw_channel(topic, schema_name, schema_data, schema_encoding,
                                                          message_encoding))

    def _raw_channel(self, topic: str, schema_name: str, schema_data: bytes, schema_encoding: str,
                     message_encoding: str) -> int:
        sid = 0 if not (schema_name or schema_encoding or schema_data) else \
            self._schema_id(schema_name, schema_encoding, bytes(schema_data))
        return self._channel_id(topic, sid, message_encoding)

    def _write_raw(self, cid: int, data: bytes, log_time_ns: int, publish_time_ns: int | None = None) -> None:
        if self._pending_tf:
            self._flush_tf(log_time_ns * 1e-9)
        lt = int(log_time_ns)
        self._writer.add_message(cid, lt, data, lt if publish_time_ns is None else int(publish_time_ns), self.count)
        self.count += 1

    def copy(self, rec: Record, topic: str | None = None) -> None:
        """Write an input :class:`Record`: its original bytes when it has them (ROS 2 CDR
        inputs), else its message re-encoded at its log time."""
        ch = rec.channel
        if rec.data is not None and ch is not None:
            to = topic or rec.topic
            # the channel of an input channel object, looked up once (the object is kept: its id stays its own)
            hit = self._copied.get((to, id(ch)))
            if hit is None or hit[0] is not ch:
                name, enc, sdata = ch.schema_name or ch.type, ch.schema_encoding, ch.schema_data
                if not sdata.strip() and short_name(ch.type) in MSG_TEXT:  # no definition: the standard one
                    name, enc, sdata = ch.type, "ros2msg", full_text(ch.type).encode()
                hit = self._copied[(to, id(ch))] = (ch, self._raw_channel(to, name, sdata, enc, ch.message_encoding))
            self._write_raw(hit[1], rec.data, rec.log_time_ns)
        else:
            self.write(topic or rec.topic, rec.msg, log_time_ns=rec.log_time_ns)

    def close(self) -> None:
        if not self._file.closed:
            try:
                for ptopic, pmsg in self._pending_tf:
                    self._emit(ptopic, TF_MESSAGE, fastcdr.encode_tf(pmsg, 0.0), 0.0, None)
                self._pending_tf = []
                self._writer.finish()
            finally:  # a full disk: the file is closed all the same (its space freed once it is removed)
                try:
                    self._file.close()
                except OSError:
                    pass

    def __enter__(self) -> LogWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def tee(records: Iterable[Record], writer: LogWriter) -> Iterator[tuple[str, object]]:
    """``(topic, message)`` of ``records`` while copying each into ``writer`` (raw bytes where
    the input has them): the run's recording of its inputs without a decode/encode trip."""
    for rec in records:
        writer.copy(rec)
        yield rec.topic, rec.msg
