"""ROS 2 MCAP logs: read lazily in time order, write with ros2 profile / cdr / ros2msg schemas.

Topics and types (every name can be renamed through :class:`Topics`):

==================  ============================================  ==========================
topic               ROS 2 type                                    fgloc type
==================  ============================================  ==========================
``/scan``           ``sensor_msgs/msg/LaserScan``                 :class:`LaserScan`
``/odom``           ``nav_msgs/msg/Odometry``                     :class:`Odometry`
``/imu``            ``sensor_msgs/msg/Imu``                       :class:`CompassHeading`
``/tf_static``      ``tf2_msgs/msg/TFMessage``                    ``list[StaticTransform]``
``/tf``             ``tf2_msgs/msg/TFMessage``                    ``list[StaticTransform]``
``/ground_truth``   ``nav_msgs/msg/Odometry`` (map frame)         :class:`Odometry`
``/fused_pose``     ``geometry_msgs/msg/PoseWithCovarianceStamped``  :class:`PoseFix`
==================  ============================================  ==========================

:meth:`LogReader.messages` yields ``(topic, message)`` with ``topic`` the name in the file
(compare it with ``reader.topics.scan`` etc.); messages on other topics are ignored.
The order is MCAP log time (fgloc writes log time = header stamp; a ROS recorder writes
its receive time, so stamps there can be slightly out of order across topics).  Indexed
files are read chunk by chunk through the index (memory bounded by the chunks that
overlap in time), never whole.

Conventions of the conversion (both directions):

* stamps: ``header.stamp`` <-> ``stamp`` seconds (nanosecond exact); the MCAP log time of a
  written message is its stamp.  A transform list written without ``stamp`` gets the stamp
  of the next message written (the start of the log), so it is read first.
* 3x3 covariances over ``[x, y, yaw]`` / ``[vx, vy, wz]`` are the ``(0, 1, 5)`` rows and
  columns of the ROS 6x6 ones; an all-zero 6x6 means "unknown" (-> None).  An Odometry
  whose ``pose`` is None is written with ``pose.covariance[0] = -1`` and read back as None.
* Imu (REP 145): ``orientation_covariance[0] == -1`` -> ``yaw_rad`` None, likewise angular
  velocity -> ``yaw_rate_radps`` None; an all-zero covariance -> variance NaN ("unknown");
  otherwise yaw variance is element ``[8]`` (zz) of each covariance.
* TFMessage: each transform -> 2-D ``StaticTransform`` (x, y, yaw of the quaternion; z kept).
* PoseWithCovarianceStamped: only stamp, frame, pose and covariance survive (``quality`` /
  ``source`` of a :class:`PoseFix` have no field; read back as 1.0 / the topic name).

Truncated files (a recorder killed before it wrote the summary): the indexed reader needs
the summary, so the records are streamed instead; every message up to the break is read
(also those in the complete part of a cut chunk), ``reader.truncated`` says where it broke
and a warning is logged.  Without an index, time order across chunks assumes (as every
recorder does) that chunks are written in order of their first message time.
"""

from __future__ import annotations

import heapq
import io
import logging
import math
import os
import struct
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, fields
from pathlib import Path
from typing import IO, Any

import numpy as np

from fgloc.errors import LogError
from fgloc.geometry import compose, quaternion_to_yaw, yaw_to_quaternion
from fgloc.io.fastcdr import decode_scan, encode_scan
from fgloc.io.msgdefs import full_text
from fgloc.types import CompassHeading, LaserScan, Odometry, PoseFix, StaticTransform, Trajectory

log = logging.getLogger(__name__)

MCAP_MAGIC = b"\x89MCAP0\r\n"

LASER_SCAN = "sensor_msgs/msg/LaserScan"
ODOMETRY = "nav_msgs/msg/Odometry"
IMU = "sensor_msgs/msg/Imu"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
POSE_COV_STAMPED = "geometry_msgs/msg/PoseWithCovarianceStamped"
COV_IDX = (0, 1, 5)  # x, y, yaw (or vx, vy, wz) inside a ROS 6x6 covariance


@dataclass
class Topics:
    """Topic names of each role; every one can be renamed on the command line."""

    scan: str = "/scan"
    odom: str = "/odom"
    imu: str = "/imu"
    tf_static: str = "/tf_static"
    tf: str = "/tf"
    ground_truth: str = "/ground_truth"
    fused: str = "/fused_pose"

    def roles(self) -> dict[str, str]:
        """``{topic name: role}``."""
        return {getattr(self, f.name): f.name for f in fields(self)}


ROLE_TYPES = {
    "scan": LASER_SCAN,
    "odom": ODOMETRY,
    "imu": IMU,
    "tf_static": TF_MESSAGE,
    "tf": TF_MESSAGE,
    "ground_truth": ODOMETRY,
    "fused": POSE_COV_STAMPED,
}


# --------------------------------------------------------------------------------------------
# stamps
def stamp_to_sec_nsec(stamp: float) -> tuple[int, int]:
    """Seconds -> ``(sec, nanosec)`` rounded to the nearest nanosecond."""
    sec = math.floor(stamp)
    nsec = round((stamp - sec) * 1e9)
    if nsec >= 1_000_000_000:
        sec, nsec = sec + 1, nsec - 1_000_000_000
    return int(sec), int(nsec)


def sec_nsec_to_stamp(sec: int, nsec: int) -> float:
    return float(sec) + float(nsec) * 1e-9


def stamp_to_ns(stamp: float) -> int:
    sec, nsec = stamp_to_sec_nsec(stamp)
    return sec * 1_000_000_000 + nsec


def _header(stamp: float, frame_id: str) -> dict:
    sec, nsec = stamp_to_sec_nsec(stamp)
    return {"stamp": {"sec": sec, "nanosec": nsec}, "frame_id": frame_id}


def _stamp(header: Any) -> float:
    return sec_nsec_to_stamp(header.stamp.sec, header.stamp.nanosec)


# --------------------------------------------------------------------------------------------
# fgloc -> ROS 2 dicts
def _quat(yaw: float) -> dict:
    q = yaw_to_quaternion(yaw)
    return {"x": float(q[0]), "y": float(q[1]), "z": float(q[2]), "w": float(q[3])}


def _cov6(cov3: np.ndarray | None) -> list[float]:
    c6 = np.zeros((6, 6))
    if cov3 is not None:
        c6[np.ix_(COV_IDX, COV_IDX)] = np.asarray(cov3, dtype=float).reshape(3, 3)
    return [float(v) for v in c6.ravel()]


def _cov3(cov36: Any) -> np.ndarray | None:
    c6 = np.asarray(cov36, dtype=float).reshape(6, 6)
    if not np.any(c6):
        return None
    return c6[np.ix_(COV_IDX, COV_IDX)].copy()


def _var(cov9: Any) -> float:
    c = np.asarray(cov9, dtype=float)
    return float("nan") if not np.any(c) else float(c[8])


def _scan_to_ros(m: LaserScan, stamp: float) -> dict:
    n = len(m.ranges)
    return {
        "header": _header(stamp, m.frame_id),
        "angle_min": m.angle_min,
        "angle_max": m.angle_min + m.angle_increment * max(n - 1, 0),
        "angle_increment": m.angle_increment,
        "time_increment": m.time_increment,
        "scan_time": m.scan_time,
        "range_min": m.range_min,
        "range_max": m.range_max,
        "ranges": np.asarray(m.ranges, dtype=np.float32).tolist(),
        "intensities": [] if m.intensities is None else np.asarray(m.intensities, dtype=np.float32).tolist(),
    }


def _scan_to_cdr(m: LaserScan, stamp: float) -> bytes:
    n = len(m.ranges)
    sec, nsec = stamp_to_sec_nsec(stamp)
    floats = (m.angle_min, m.angle_min + m.angle_increment * max(n - 1, 0), m.angle_increment,
              m.time_increment, m.scan_time, m.range_min, m.range_max)
    return encode_scan(sec, nsec, m.frame_id, floats, m.ranges, m.intensities)


def _already_encoded(payload: bytes) -> bytes:
    return payload


def _scan_from_cdr(data: bytes, topic: str) -> LaserScan | None:
    d = decode_scan(data)
    if d is None:
        return None
    amin, _amax, inc, tinc, stime, rmin, rmax = d["floats"]
    inten = d["intensities"]
    return LaserScan(
        stamp=sec_nsec_to_stamp(d["sec"], d["nanosec"]), angle_min=amin, angle_increment=inc,
        range_min=rmin, range_max=rmax, ranges=d["ranges"], time_increment=tinc, scan_time=stime,
        intensities=inten if len(inten) else None, frame_id=d["frame_id"],
    )


def _odom_to_ros(m: Odometry, stamp: float) -> dict:
    pose = np.zeros(3) if m.pose is None else np.asarray(m.pose, dtype=float)
    pcov = _cov6(m.pose_cov)
    if m.pose is None:
        pcov[0] = -1.0
    tw = np.asarray(m.twist, dtype=float)
    return {
        "header": _header(stamp, m.frame_id),
        "child_frame_id": m.child_frame_id,
        "pose": {
            "pose": {"position": {"x": float(pose[0]), "y": float(pose[1]), "z": 0.0},
                     "orientation": _quat(float(pose[2]))},
            "covariance": pcov,
        },
        "twist": {
            "twist": {"linear": {"x": float(tw[0]), "y": float(tw[1]), "z": 0.0},
                      "angular": {"x": 0.0, "y": 0.0, "z": float(tw[2])}},
            "covariance": _cov6(m.twist_cov),
        },
    }


def _cov9(var: float, absent: bool) -> list[float]:
    c = [0.0] * 9
    if absent:
        c[0] = -1.0
    elif not math.isnan(var):
        c[8] = float(var)
    return c


def _compass_to_ros(m: CompassHeading, stamp: float) -> dict:
    return {
        "header": _header(stamp, m.frame_id),
        "orientation": _quat(0.0 if m.yaw_rad is None else float(m.yaw_rad)),
        "orientation_covariance": _cov9(m.yaw_var, m.yaw_rad is None),
        "angular_velocity": {"x": 0.0, "y": 0.0,
                             "z": 0.0 if m.yaw_rate_radps is None else float(m.yaw_rate_radps)},
        "angular_velocity_covariance": _cov9(m.yaw_rate_var, m.yaw_rate_radps is None),
        "linear_acceleration": {"x": 0.0, "y": 0.0, "z": 0.0},
        "linear_acceleration_covariance": _cov9(float("nan"), True),
    }


def _fix_to_ros(m: PoseFix, stamp: float) -> dict:
    p = np.asarray(m.pose, dtype=float)
    return {
        "header": _header(stamp, m.frame_id),
        "pose": {
            "pose": {"position": {"x": float(p[0]), "y": float(p[1]), "z": 0.0},
                     "orientation": _quat(float(p[2]))},
            "covariance": _cov6(m.cov),
        },
    }


def _tf_to_ros(m: list[StaticTransform], stamp: float) -> dict:
    return {
        "transforms": [
            {
                "header": _header(stamp, t.parent),
                "child_frame_id": t.child,
                "transform": {
                    "translation": {"x": float(t.pose[0]), "y": float(t.pose[1]), "z": float(t.z)},
                    "rotation": _quat(float(t.pose[2])),
                },
            }
            for t in m
        ]
    }


# --------------------------------------------------------------------------------------------
# ROS 2 decoded messages -> fgloc
def _yaw(q: Any) -> float:
    return float(quaternion_to_yaw(q.x, q.y, q.z, q.w))


def _scan_from_ros(m: Any, topic: str) -> LaserScan:
    inten = np.asarray(m.intensities, dtype=np.float32)
    return LaserScan(
        stamp=_stamp(m.header),
        angle_min=float(m.angle_min),
        angle_increment=float(m.angle_increment),
        range_min=float(m.range_min),
        range_max=float(m.range_max),
        ranges=np.asarray(m.ranges, dtype=np.float32),
        time_increment=float(m.time_increment),
        scan_time=float(m.scan_time),
        intensities=inten if len(inten) else None,
        frame_id=m.header.frame_id,
    )


def _odom_from_ros(m: Any, topic: str) -> Odometry:
    pcov = m.pose.covariance
    p = m.pose.pose
    pose = None if pcov[0] == -1 else np.array([p.position.x, p.position.y, _yaw(p.orientation)])
    tw = m.twist.twist
    return Odometry(
        stamp=_stamp(m.header),
        twist=np.array([tw.linear.x, tw.linear.y, tw.angular.z], dtype=float),
        twist_cov=_cov3(m.twist.covariance),
        pose=pose,
        pose_cov=None if pose is None else _cov3(pcov),
        frame_id=m.header.frame_id,
        child_frame_id=m.child_frame_id,
    )


def _compass_from_ros(m: Any, topic: str) -> CompassHeading:
    ocov, wcov = m.orientation_covariance, m.angular_velocity_covariance
    q = m.orientation
    no_yaw = ocov[0] == -1 or (q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w) < 1e-12  # REP 145 / zero quaternion
    no_rate = wcov[0] == -1
    return CompassHeading(
        stamp=_stamp(m.header),
        yaw_rad=None if no_yaw else _yaw(m.orientation),
        yaw_rate_radps=None if no_rate else float(m.angular_velocity.z),
        yaw_var=float("nan") if no_yaw else _var(ocov),
        yaw_rate_var=float("nan") if no_rate else _var(wcov),
        frame_id=m.header.frame_id,
    )


def _fix_from_ros(m: Any, topic: str) -> PoseFix:
    p = m.pose.pose
    cov = _cov3(m.pose.covariance)
    return PoseFix(
        stamp=_stamp(m.header),
        pose=np.array([p.position.x, p.position.y, _yaw(p.orientation)]),
        cov=np.zeros((3, 3)) if cov is None else cov,
        source=topic,
        frame_id=m.header.frame_id,
    )


def _tf_from_ros(m: Any, topic: str) -> list[StaticTransform]:
    out = []
    for t in m.transforms:
        tr = t.transform
        out.append(
            StaticTransform(
                parent=t.header.frame_id.lstrip("/"),
                child=t.child_frame_id.lstrip("/"),
                pose=np.array([tr.translation.x, tr.translation.y, _yaw(tr.rotation)]),
                z=float(tr.translation.z),
            )
        )
    return out


def _tf_flips(m: Any) -> list[bool]:
    """Per transform of a decoded TFMessage: is the child's z axis pointing down (a scanner
    mounted upside down, rolled or pitched by pi)?  Its rotation is then ``Rz(yaw) Rx(pi)``
    with ``yaw`` as :func:`_yaw` gives it."""
    out = []
    for t in m.transforms:
        q = t.transform.rotation
        n = q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w
        out.append(n > 0 and 1.0 - 2.0 * (q.x * q.x + q.y * q.y) / n < 0.0)
    return out


def _mirror_scan(scan: LaserScan) -> LaserScan:
    """The scan of an upside-down scanner as an upright one sees it: angles negated (timing kept)."""
    scan.angle_min = -scan.angle_min
    scan.angle_increment = -scan.angle_increment
    return scan


FROM_ROS: dict[str, Callable[[Any, str], object]] = {
    LASER_SCAN: _scan_from_ros,
    ODOMETRY: _odom_from_ros,
    IMU: _compass_from_ros,
    TF_MESSAGE: _tf_from_ros,
    POSE_COV_STAMPED: _fix_from_ros,
}


def _normalize_type(name: str) -> str:
    """``sensor_msgs/LaserScan`` (ROS 1 style) -> ``sensor_msgs/msg/LaserScan``."""
    parts = name.split("/")
    return f"{parts[0]}/msg/{parts[1]}" if len(parts) == 2 else name


# --------------------------------------------------------------------------------------------
# writer
class LogWriter:
    """Write fgloc messages into a ROS 2 MCAP (profile ros2, cdr, ros2msg schemas).

    A context manager; ``write(topic, msg, stamp=None)`` takes a :class:`LaserScan`,
    :class:`Odometry`, :class:`CompassHeading`, :class:`PoseFix` or ``list[StaticTransform]``.
    Header stamps come from ``msg.stamp`` (or ``stamp``), the log time is the same.
    """

    def __init__(self, path: str | Path, chunk_size: int = 1024 * 1024) -> None:
        from mcap_ros2.writer import Writer

        self.path = Path(path)
        try:
            if self.path.parent != Path(""):
                self.path.parent.mkdir(parents=True, exist_ok=True)
            self._file: IO[bytes] = self.path.open("wb")
        except OSError as e:
            raise LogError(f"{self.path}: cannot write log ({e.strerror or e})") from None
        self._writer = Writer(self._file, chunk_size=chunk_size)
        self._schemas: dict[str, Any] = {}
        # scans go through the vectorized codec (byte-identical, see fastcdr) when the
        # mcap_ros2 writer exposes its per-schema encoder table
        self._fast_scans = isinstance(getattr(self._writer, "_encoders", None), dict)
        self._pending_tf: list[tuple[str, object]] = []
        self._last_stamp: float | None = None
        self.count = 0

    def _schema(self, type_name: str) -> Any:
        s = self._schemas.get(type_name)
        if s is None:
            s = self._writer.register_msgdef(type_name, full_text(type_name))
            self._schemas[type_name] = s
            if type_name == LASER_SCAN and self._fast_scans:
                self._writer._encoders[s.id] = _already_encoded
        return s

    def write(self, topic: str, msg: object, stamp: float | None = None) -> None:
        """Write one message; ``stamp`` overrides ``msg.stamp`` (header and log time)."""
        data: Callable[[Any, float], dict | bytes]
        if isinstance(msg, LaserScan):
            t, st, data = LASER_SCAN, msg.stamp, (_scan_to_cdr if self._fast_scans else _scan_to_ros)
        elif isinstance(msg, Odometry):
            t, st, data = ODOMETRY, msg.stamp, _odom_to_ros
        elif isinstance(msg, CompassHeading):
            t, st, data = IMU, msg.stamp, _compass_to_ros
        elif isinstance(msg, PoseFix):
            t, st, data = POSE_COV_STAMPED, msg.stamp, _fix_to_ros
        elif isinstance(msg, list | tuple) and all(isinstance(x, StaticTransform) for x in msg):
            if stamp is None:  # stamped with the next message's time (the start of the log)
                if self._last_stamp is None:
                    self._pending_tf.append((topic, list(msg)))
                    return
                stamp = self._last_stamp
            t, st, data = TF_MESSAGE, float(stamp), _tf_to_ros
        else:
            raise TypeError(f"cannot write {type(msg).__name__} to a log")
        if stamp is not None:
            st = float(stamp)
        if self._pending_tf:
            pending, self._pending_tf = self._pending_tf, []
            for ptopic, pmsg in pending:
                self._emit(ptopic, TF_MESSAGE, _tf_to_ros(pmsg, st), st)  # type: ignore[arg-type]
        payload: Any = msg
        self._emit(topic, t, data(payload, st), st)

    def _emit(self, topic: str, type_name: str, ros: dict | bytes, stamp: float) -> None:
        self._writer.write_message(topic, self._schema(type_name), ros, log_time=max(stamp_to_ns(stamp), 0),
                                   sequence=self.count)
        self._last_stamp = stamp
        self.count += 1

    def close(self) -> None:
        if not self._file.closed:
            for ptopic, pmsg in self._pending_tf:
                self._emit(ptopic, TF_MESSAGE, _tf_to_ros(pmsg, 0.0), 0.0)  # type: ignore[arg-type]
            self._pending_tf = []
            self._writer.finish()
            self._file.close()

    def __enter__(self) -> LogWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


# --------------------------------------------------------------------------------------------
# streaming record walker (files without summary, truncated files)
@dataclass
class _Break:
    offset: int
    size: int
    messages: int
    last_time_ns: int | None
    reason: str

    def describe(self) -> str:
        t = "" if self.last_time_ns is None else f", the last at t={self.last_time_ns * 1e-9:.3f} s"
        where = f"file ends at byte {self.size}" if self.offset < self.size else f"at byte {self.offset}"
        return f"{where}: {self.reason} starting at byte {self.offset}; {self.messages} complete messages read{t}"


def _decompress(compression: str, data: bytes, partial: bool) -> bytes:
    if compression == "":
        return data
    if compression == "zstd":
        import zstandard

        if partial:
            return zstandard.ZstdDecompressor().decompressobj().decompress(data)
        return zstandard.ZstdDecompressor().decompress(data, max_output_size=1 << 31)
    if compression == "lz4":
        import lz4.frame

        if partial:
            return lz4.frame.LZ4FrameDecompressor().decompress(data)
        return lz4.frame.decompress(data)
    raise ValueError(f"unsupported chunk compression '{compression}'")


class _Walker:
    """Walk MCAP records in file order; yields Schema / Channel / Message records.

    Stops at DataEnd / Footer, or at the first incomplete or corrupt record (then
    ``self.broke`` describes where).  Chunk start times come as ``("chunk", start_ns)``.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self.broke: _Break | None = None
        self.n_messages = 0
        self.last_time: int | None = None

    def _records_in(self, buf: bytes, complete: bool) -> Iterator[Any]:
        from mcap.data_stream import ReadDataStream
        from mcap.records import Channel, Message, Schema

        pos, n = 0, len(buf)
        while pos + 9 <= n:
            opcode, length = struct.unpack_from("<BQ", buf, pos)
            if pos + 9 + length > n:
                if complete:
                    raise ValueError("record overruns its chunk")
                return
            body = ReadDataStream(io.BytesIO(buf[pos + 9 : pos + 9 + length]))
            if opcode == 0x03:
                yield Schema.read(body)
            elif opcode == 0x04:
                yield Channel.read(body)
            elif opcode == 0x05:
                yield Message.read(body, length)
            pos += 9 + length

    def records(self) -> Iterator[Any]:
        from mcap.data_stream import ReadDataStream
        from mcap.records import Channel, Message, Schema

        size = os.path.getsize(self.path)
        with self.path.open("rb") as f:
            f.seek(len(MCAP_MAGIC))
            while True:
                pos = f.tell()
                hdr = f.read(9)
                if len(hdr) < 9:
                    self._break(pos, size, "cut inside a record header" if hdr else "no end-of-data record")
                    return
                opcode, length = struct.unpack("<BQ", hdr)
                if opcode == 0 or (0x10 < opcode < 0x80):
                    self._break(pos, size, f"corrupt record (opcode {opcode:#x})")
                    return
                if opcode in (0x02, 0x0F):  # Footer, DataEnd: the data section is complete
                    return
                complete = pos + 9 + length <= size
                if opcode != 0x06 and not complete:
                    self._break(pos, size, "cut inside a record")
                    return
                if opcode == 0x06:  # Chunk
                    body = f.read(length) if complete else f.read()
                    try:
                        start_ns, _end, _usize, _crc, clen = struct.unpack_from("<QQQII", body, 0)
                        comp = body[32 : 32 + clen].decode()
                        (dlen,) = struct.unpack_from("<Q", body, 32 + clen)
                        data = body[40 + clen : 40 + clen + dlen]
                        yield ("chunk", start_ns)
                        buf = _decompress(comp, data, partial=not complete)
                        for rec in self._records_in(buf, complete):
                            yield self._count(rec)
                    except Exception as e:  # noqa: BLE001 - any decode failure is a break
                        self._break(pos, size, "cut inside a chunk" if not complete
                                    else f"corrupt chunk ({type(e).__name__})")
                        return
                    if not complete:
                        self._break(pos, size, "cut inside a chunk")
                        return
                    continue
                body_bytes = f.read(length)
                rs = ReadDataStream(io.BytesIO(body_bytes))
                try:
                    if opcode == 0x03:
                        yield Schema.read(rs)
                    elif opcode == 0x04:
                        yield Channel.read(rs)
                    elif opcode == 0x05:
                        msg = Message.read(rs, length)
                        yield ("chunk", msg.log_time)
                        yield self._count(msg)
                except Exception as e:  # noqa: BLE001
                    self._break(pos, size, f"corrupt record ({type(e).__name__})")
                    return

    def _count(self, rec: Any) -> Any:
        from mcap.records import Message

        if isinstance(rec, Message):
            self.n_messages += 1
            self.last_time = rec.log_time if self.last_time is None else max(self.last_time, rec.log_time)
        return rec

    def _break(self, pos: int, size: int, reason: str) -> None:
        self.broke = _Break(pos, size, self.n_messages, self.last_time, reason)


# --------------------------------------------------------------------------------------------
# reader
def _bag_file(folder: Path) -> Path:
    """The MCAP file of a rosbag2 folder (``ros2 bag record -s mcap``: metadata.yaml + one .mcap)."""
    files: list[Path] = []
    meta = folder / "metadata.yaml"
    if meta.is_file():
        try:
            import yaml

            info = (yaml.safe_load(meta.read_text()) or {}).get("rosbag2_bagfile_information") or {}
            files = [folder / str(f) for f in info.get("relative_file_paths") or []]
        except Exception:  # noqa: BLE001 - a broken metadata.yaml: look at the files themselves
            files = []
        files = [f for f in files if f.is_file()]
    if not files:
        files = sorted(folder.glob("*.mcap"))
    if len(files) == 1 and files[0].suffix == ".mcap":
        return files[0]
    if len(files) > 1:
        raise LogError(f"{folder}: a split rosbag2 recording ({len(files)} files); convert it into one "
                       f"MCAP with 'fgloc import {folder} -o LOG.mcap'")
    if any(folder.glob("*.db3")) or (files and files[0].suffix == ".db3"):
        raise LogError(f"{folder}: a rosbag2 SQLite (.db3) bag, not MCAP; convert it with "
                       f"'fgloc import {folder} -o LOG.mcap'")
    raise LogError(f"{folder}: is a directory without an MCAP log (no .mcap file in it)")


@dataclass
class _TopicInfo:
    type: str
    count: int = 0


class LogReader:
    """A ROS 2 MCAP log, read lazily and in time order across topics.

    Opening checks the file (missing, not an MCAP, empty) and raises :class:`LogError`
    with one line naming the file and the problem.  ``truncated`` is None, or a one-line
    description of where a cut file broke.
    """

    def __init__(self, path: str | Path, topics: Topics | None = None) -> None:
        self.path = Path(path)
        self.topics = topics or Topics()
        self.truncated: str | None = None
        self._indexed = False
        self._topic_info: dict[str, _TopicInfo] = {}
        self._start_ns: int | None = None
        self._end_ns: int | None = None
        self._n = 0
        self._tf_flip: dict[tuple[str, str], bool] = {}   # (parent, child) -> child upside down
        self._mirror_frames: set[str] = set()             # scan frames read mirrored (laser_mount)
        self.undecodable: dict[str, int] = {}             # topic -> messages that failed to decode
        self._last_log_ns = 0                             # log time of the message _iter yielded last
        self._open()

    # -- opening -----------------------------------------------------------------------------
    def _open(self) -> None:
        p = self.path
        if not p.exists():
            raise LogError(f"{p}: log file not found")
        if p.is_dir():
            p = self.path = _bag_file(p)
        size = p.stat().st_size
        if size == 0:
            raise LogError(f"{p}: empty file (0 bytes), not an MCAP log")
        with p.open("rb") as f:
            magic = f.read(len(MCAP_MAGIC))
        if magic != MCAP_MAGIC:
            if magic.startswith(b"#ROSBAG"):
                raise LogError(f"{p}: a ROS 1 bag, not an MCAP log; convert it with 'fgloc import'")
            raise LogError(f"{p}: not an MCAP file (bad magic bytes)")
        summary = self._read_summary()
        if summary is not None and summary.statistics is not None and summary.chunk_indexes:
            self._indexed = True
            st = summary.statistics
            for cid, ch in summary.channels.items():
                schema = summary.schemas.get(ch.schema_id)
                info = self._topic_info.setdefault(ch.topic, _TopicInfo(
                    _normalize_type(schema.name) if schema else "?"))
                info.count += st.channel_message_counts.get(cid, 0)
            self._n = st.message_count
            if self._n:
                self._start_ns, self._end_ns = st.message_start_time, st.message_end_time
        else:
            self._scan_stream()
        if self._n == 0:
            if self.truncated:
                raise LogError(f"{p}: empty log, no complete message before the break ({self.truncated})")
            raise LogError(f"{p}: empty log (no messages)")

    def _read_summary(self) -> Any:
        from mcap.reader import SeekingReader

        try:
            with self.path.open("rb") as f:
                s = SeekingReader(f).get_summary()
            size = self.path.stat().st_size
            if s is not None and any(c.chunk_start_offset + c.chunk_length > size for c in s.chunk_indexes):
                return None
            return s
        except Exception:  # noqa: BLE001 - no readable footer/summary: stream instead
            return None

    def _footer_ok(self) -> bool:
        """The file ends with a readable Footer record and the magic bytes."""
        size = self.path.stat().st_size
        if size < 2 * len(MCAP_MAGIC) + 29:
            return False
        with self.path.open("rb") as f:
            f.seek(size - len(MCAP_MAGIC) - 29)
            tail = f.read()
        return tail[0] == 0x02 and tail[-len(MCAP_MAGIC):] == MCAP_MAGIC

    def _scan_stream(self) -> None:
        from mcap.records import Channel, Message, Schema

        w = _Walker(self.path)
        schemas: dict[int, str] = {}
        chans: dict[int, str] = {}
        for rec in w.records():
            if isinstance(rec, Schema):
                schemas[rec.id] = _normalize_type(rec.name)
            elif isinstance(rec, Channel):
                chans[rec.id] = rec.topic
                self._topic_info.setdefault(rec.topic, _TopicInfo(schemas.get(rec.schema_id, "?")))
            elif isinstance(rec, Message):
                topic = chans.get(rec.channel_id)
                if topic is not None:
                    self._topic_info[topic].count += 1
                self._n += 1
                t = rec.log_time
                self._start_ns = t if self._start_ns is None else min(self._start_ns, t)
                self._end_ns = t if self._end_ns is None else max(self._end_ns, t)
        if w.broke is None and not self._footer_ok():
            self.truncated = (f"file ends at byte {self.path.stat().st_size} in the index after the data; "
                              f"all {self._n} messages intact")
        if w.broke is not None:
            self.truncated = w.broke.describe()
        if self.truncated and self._n:
            log.warning("%s: truncated log: %s; reading the messages before the break", self.path, self.truncated)

    # -- queries -----------------------------------------------------------------------------
    def topic_types(self) -> dict[str, str]:
        return {t: i.type for t, i in self._topic_info.items()}

    def has(self, topic: str) -> bool:
        return topic in self._topic_info and self._topic_info[topic].count > 0

    def require(self, *topics: str) -> None:
        """Raise :class:`LogError` naming the file, the topic and the topics that exist."""
        for t in topics:
            if not self.has(t):
                have = ", ".join(sorted(self._topic_info)) or "none"
                raise LogError(f"{self.path}: topic '{t}' not in log (topics: {have})")

    def summary(self) -> dict:
        """``{"path", "topics": {name: {"type", "count"}}, "messages", "start", "end",
        "duration", "indexed", "truncated"}`` (times in seconds of log time)."""
        start = None if self._start_ns is None else self._start_ns * 1e-9
        end = None if self._end_ns is None else self._end_ns * 1e-9
        return {
            "path": str(self.path),
            "topics": {t: {"type": i.type, "count": i.count} for t, i in sorted(self._topic_info.items())},
            "messages": self._n,
            "start": start,
            "end": end,
            "duration": (end - start) if start is not None and end is not None else 0.0,
            "indexed": self._indexed,
            "truncated": self.truncated,
        }

    # -- messages ----------------------------------------------------------------------------
    def _wanted(self, topics: Iterable[str] | None) -> set[str]:
        if topics is None:
            roles = self.topics.roles()
            return {t for t in roles if self.has(t)}
        want = set(topics)
        self.require(*sorted(want))
        return want

    def messages(self, topics: set[str] | None = None) -> Iterator[tuple[str, object]]:
        """``(topic, message)`` in log-time order; ``topics`` None = every role topic present.

        A requested topic that is not in the log raises :class:`LogError` (before the
        first message); topics of an unknown type are skipped with a warning.
        """
        want = self._wanted(topics)
        return self._iter(want)

    def _iter(self, want: set[str]) -> Iterator[tuple[str, object]]:
        from mcap_ros2.decoder import DecoderFactory

        factory = DecoderFactory()
        Conv = tuple[Callable[[bytes], Any], Callable[[Any, str], object]]
        converters: dict[int, Conv | None] = {}
        it = self._raw(want)
        while True:
            try:
                item = next(it)
            except StopIteration:
                return
            except Exception as e:  # noqa: BLE001 - a corrupt chunk in an indexed file
                self.truncated = f"unreadable data after the messages read so far ({type(e).__name__}: {e})"
                log.warning("%s: %s", self.path, self.truncated)
                return
            schema, channel, message = item
            self._last_log_ns = int(message.log_time)
            if channel.id in converters:
                conv = converters[channel.id]
            else:
                conv = None
                tname = _normalize_type(schema.name) if schema is not None else "?"
                fn = FROM_ROS.get(tname)
                if fn is None:
                    log.warning("%s: topic %s has type %s, which fgloc does not read; skipped",
                                self.path, channel.topic, tname)
                elif channel.message_encoding != "cdr":
                    log.warning("%s: topic %s has message encoding %s, not cdr; skipped",
                                self.path, channel.topic, channel.message_encoding)
                else:
                    dec = self._decoder(factory, schema, tname, channel.topic)
                    if dec is not None:
                        conv = (dec, fn)
                converters[channel.id] = conv
            if conv is None:
                continue
            dec, fn = conv
            try:
                if fn is _scan_from_ros:
                    scan = _scan_from_cdr(message.data, channel.topic)
                    if scan is None:
                        scan = _scan_from_ros(dec(message.data), channel.topic)
                    if self._mirror_frames and scan.frame_id.lstrip("/") in self._mirror_frames:
                        scan = _mirror_scan(scan)
                    out: object = scan
                elif fn is _tf_from_ros:
                    ros = dec(message.data)
                    tfs = _tf_from_ros(ros, channel.topic)
                    for tr, flip in zip(tfs, _tf_flips(ros), strict=True):
                        if flip:
                            self._tf_flip[(tr.parent, tr.child)] = True
                    out = tfs
                else:
                    out = fn(dec(message.data), channel.topic)
            except Exception as e:  # noqa: BLE001 - one undecodable message is skipped, not fatal
                n = self.undecodable.get(channel.topic, 0)
                self.undecodable[channel.topic] = n + 1
                if n == 0:
                    log.warning("%s: cannot decode a message on %s (%s: %s); skipping such messages",
                                self.path, channel.topic, type(e).__name__, e)
                continue
            yield channel.topic, out

    def _decoder(self, factory: Any, schema: Any, tname: str, topic: str) -> Callable[[bytes], Any] | None:
        """The CDR decoder of a topic of a type fgloc reads.  A schema that is missing, empty or
        not ``ros2msg`` (rosbag2 writes ``ros2idl`` or an empty definition when it cannot find
        the ``.msg``) is replaced by the standard ROS 2 definition of ``tname``: the CDR layout
        of a standard message is fixed by its type."""
        from mcap.records import Schema

        if schema is None or schema.encoding != "ros2msg" or not bytes(schema.data).strip():
            log.info("%s: topic %s has no ros2msg definition (%s); decoding it as the standard %s",
                     self.path, topic, "none" if schema is None else schema.encoding or "empty", tname)
            schema = Schema(id=0 if schema is None else schema.id, name=tname, encoding="ros2msg",
                            data=full_text(tname).encode())
        try:
            return factory.decoder_for("cdr", schema)  # type: ignore[no-any-return]
        except Exception as e:  # noqa: BLE001
            log.warning("%s: cannot decode topic %s (%s); skipped", self.path, topic, e)
            return None

    def _raw(self, want: set[str]) -> Iterator[tuple[Any, Any, Any]]:
        if self._indexed:
            from mcap.reader import SeekingReader

            with self.path.open("rb") as f:
                yield from SeekingReader(f).iter_messages(topics=sorted(want), log_time_order=True)
            return
        yield from self._raw_stream(want)

    def _raw_stream(self, want: set[str]) -> Iterator[tuple[Any, Any, Any]]:
        """Time order without an index: flush buffered messages older than each new chunk."""
        from mcap.records import Channel, Message, Schema

        w = _Walker(self.path)
        schemas: dict[int, Any] = {}
        chans: dict[int, Any] = {}
        heap: list[tuple[int, int, Any, Any, Any]] = []
        seq = 0
        for rec in w.records():
            if isinstance(rec, tuple):
                start = rec[1]
                while heap and heap[0][0] <= start:
                    _, _, s, c, m = heapq.heappop(heap)
                    yield s, c, m
            elif isinstance(rec, Schema):
                schemas[rec.id] = rec
            elif isinstance(rec, Channel):
                chans[rec.id] = rec
            elif isinstance(rec, Message):
                ch = chans.get(rec.channel_id)
                if ch is None or ch.topic not in want:
                    continue
                heapq.heappush(heap, (rec.log_time, seq, schemas.get(ch.schema_id), ch, rec))
                seq += 1
        while heap:
            _, _, s, c, m = heapq.heappop(heap)
            yield s, c, m

    # -- derived -----------------------------------------------------------------------------
    def clock_offsets(self, topics: Iterable[str]) -> dict[str, float]:
        """``{topic: header stamp - log time}`` (s) of the first message of each topic present.

        A recorder stamps log time on its own clock; sensors on one clock show (nearly) the same
        offset, whatever that clock is (wall time, sim time, or equal for fgloc's own logs).
        """
        out: dict[str, float] = {}
        for t in topics:
            if not self.has(t):
                continue
            for _, m in self._iter({t}):
                st = getattr(m, "stamp", None)
                if st is not None and math.isfinite(float(st)):
                    out[t] = float(st) - self._last_log_ns * 1e-9
                break
        return out

    def clock_skew(self, topics: Iterable[str], tolerance_s: float = 10.0) -> str | None:
        """None, or a one-line description of topics stamped by different clocks: their
        :meth:`clock_offsets` differ by more than ``tolerance_s`` (e.g. a laser driver on
        sim time or its own device clock while the odometry is on wall time)."""
        off = self.clock_offsets(topics)
        if len(off) < 2:
            return None
        lo, hi = min(off, key=lambda t: off[t]), max(off, key=lambda t: off[t])
        d = off[hi] - off[lo]
        if d <= tolerance_s:
            return None
        return (f"{hi} and {lo} are stamped by different clocks: relative to the recording time their "
                f"header stamps differ by {d:.1f} s")

    def laser_mount(self) -> StaticTransform:
        """``base_link -> <scan frame>`` from /tf_static (or the first /tf), identity if absent.

        The scan's ``frame_id`` (of the first scan) names the laser frame; a chain of
        transforms from ``base_link`` (or ``base_footprint``) to it is composed.  A scanner
        mounted upside down (its z axis pointing down, as tf2 would transform its beams) is
        returned as the equivalent upright mount, and from then on :meth:`messages` yields
        its scans mirrored (``angle_min`` and ``angle_increment`` negated), as nav2 does.
        """
        frame = "laser"
        if self.has(self.topics.scan):
            for _, m in self._iter({self.topics.scan}):
                frame = getattr(m, "frame_id", "laser").lstrip("/") or "laser"
                break
        parents: dict[str, StaticTransform] = {}
        sources = [t for t in (self.topics.tf_static, self.topics.tf) if self.has(t)]
        for src in sources:
            n = 0
            for _, m in self._iter({src}):
                for tr in m:  # type: ignore[attr-defined]
                    parents.setdefault(tr.child, tr)
                n += 1
                found = self._chain(parents, frame)
                if found is not None:
                    return self._use_mount(found, frame)
                if src == self.topics.tf and n >= 2000:
                    break
        found = self._chain(parents, frame)
        if found is not None:
            return self._use_mount(found, frame)
        log.warning("%s: no transform base_link -> %s in %s; assuming the laser at the robot centre",
                    self.path, frame, " or ".join(sources) or "the log (no tf topics)")
        return StaticTransform("base_link", frame, np.zeros(3))

    def _use_mount(self, found: tuple[StaticTransform, bool], frame: str) -> StaticTransform:
        mount, mirrored = found
        if mirrored:
            self._mirror_frames.add(frame)
            log.info("%s: laser %s is mounted upside down; its scans are read mirrored", self.path, frame)
        return mount

    def _chain(self, parents: dict[str, StaticTransform], frame: str) -> tuple[StaticTransform, bool] | None:
        """``(base -> frame, mirrored)``: the 2-D mount and whether an odd number of the
        transforms on the way turn the z axis down."""
        pose, z, cur, mirrored = np.zeros(3), 0.0, frame, False
        for _ in range(32):
            if cur in ("base_link", "base_footprint"):
                return StaticTransform(cur, frame, pose, z), mirrored
            tr = parents.get(cur)
            if tr is None:
                return None
            if self._tf_flip.get((tr.parent, tr.child), False):
                # R = Rz(yaw) Rx(pi): a child pose (x, y, th) is (x, -y, -th) before the yaw
                pose = np.array([pose[0], -pose[1], -pose[2]])
                z = -z
                mirrored = not mirrored
            pose = compose(tr.pose, pose)
            z += tr.z
            cur = tr.parent
        return None

    def ground_truth(self) -> Trajectory | None:
        """The ``/ground_truth`` topic as a trajectory (map frame), or None if absent."""
        topic = self.topics.ground_truth
        if not self.has(topic):
            return None
        stamps, poses = [], []
        for _, m in self._iter({topic}):
            if isinstance(m, Odometry) and m.pose is not None:
                stamps.append(m.stamp)
                poses.append(m.pose)
        if not stamps:
            return None
        frame = "map"
        return Trajectory.from_unsorted(np.asarray(stamps), np.asarray(poses), frame)
