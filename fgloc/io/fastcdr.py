"""Fixed-layout CDR codecs (little-endian XCDR1, as ROS 2 writes it) for the types fgloc reads.

The generic ``mcap_ros2`` codec walks every field in Python; for the standard layouts of
``sensor_msgs/msg/LaserScan``, ``nav_msgs/msg/Odometry``, ``sensor_msgs/msg/Imu``,
``tf2_msgs/msg/TFMessage`` and ``geometry_msgs/msg/PoseWithCovarianceStamped`` the byte
offsets follow from two string lengths, so these codecs read and write them with ``struct``
and numpy, decoding a whole batch of messages (one MCAP chunk's messages of one channel) at
once.  Their results are identical to the generic codec's followed by :mod:`fgloc.io.ros`'s
conversion (tested on every message of the bundled and foreign logs), and the encoders'
bytes are identical to the generic encoder's.

A decoder returns None for a message it does not handle (big-endian or another
representation, a buffer too short for the layout, a string that is not UTF-8): the caller
then uses the generic codec, which reads it correctly or reports it as undecodable.  Whether
a schema has the standard layout at all is decided by :func:`fgloc.io.msgdefs.is_standard`.

Layouts after the 4-byte encapsulation header ``00 01 00 00`` (alignment counted from the
end of that header; ``header`` = ``int32 sec, uint32 nanosec, uint32 len(frame_id)+1,
frame_id, NUL``):

* LaserScan: ``header``, pad to 4, 7 x float32 (angle_min, angle_max, angle_increment,
  time_increment, scan_time, range_min, range_max), uint32 n, n x float32 ranges, uint32 m,
  m x float32 intensities.
* Odometry: ``header``, pad to 4, child_frame_id string, pad to 8, 85 x float64 (position 3,
  orientation 4, pose covariance 36, linear 3, angular 3, twist covariance 36).
* Imu: ``header``, pad to 8, 37 x float64 (orientation 4, covariance 9, angular velocity 3,
  covariance 9, linear acceleration 3, covariance 9).
* PoseWithCovarianceStamped: ``header``, pad to 8, 43 x float64 (position, orientation, cov).
* TFMessage: uint32 count, then per transform: pad to 4, ``header``, pad to 4, child_frame_id
  string, pad to 8, 7 x float64 (translation 3, rotation 4).
"""

from __future__ import annotations

import functools
import math
import struct
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

import numpy as np

from fgloc.geometry import quaternion_to_yaw
from fgloc.io.ros import COV_IDX9, cov6_of, cov9_full, cov9_of, stamp_to_sec_nsec
from fgloc.types import CompassHeading, Imu, LaserScan, Odometry, PoseFix, StaticTransform, Transform3D, Twist

CDR_LE = b"\x00\x01\x00\x00"
_F7 = struct.Struct("<7f")
_HDR = struct.Struct("<iII")
_U32 = struct.Struct("<I")
_D7 = struct.Struct("<7d")

Buffer = bytes | bytearray | memoryview
F = TypeVar("F", bound=Callable[..., Any])


# --------------------------------------------------------------------------------------------
def _pad(n: int, align: int) -> int:
    """Bytes of padding after ``n`` bytes of payload (offsets relative to the CDR header)."""
    return (-n) % align


def _header_bytes(stamp: float, frame_id: str) -> bytes:
    sec, nsec = stamp_to_sec_nsec(stamp)
    fid = frame_id.encode() + b"\x00"
    return _HDR.pack(sec, nsec, len(fid)) + fid


def _string_bytes(pos: int, s: str) -> bytes:
    """A CDR string starting at payload offset ``pos`` (padding to 4 included)."""
    b = s.encode() + b"\x00"
    return b"\x00" * _pad(pos, 4) + _U32.pack(len(b)) + b


def _quat(yaw: float) -> tuple[float, float, float, float]:
    """:func:`fgloc.geometry.yaw_to_quaternion` of one yaw in scalar maths (numpy's sin / cos of a
    float64 are libm's: the same bits; a numpy call per message cost ~20 us)."""
    h = 0.5 * float(yaw)
    return 0.0, 0.0, math.sin(h), math.cos(h)


# --------------------------------------------------------------------------------------------
# encoders (byte-identical to mcap_ros2's generic encoder; tested)
def encode_scan(stamp_sec: int, stamp_nsec: int, frame_id: str, floats7: tuple[float, ...],
                ranges: np.ndarray, intensities: np.ndarray | None) -> bytes:
    fid = frame_id.encode() + b"\x00"
    head = _HDR.pack(stamp_sec, stamp_nsec, len(fid)) + fid
    pad = (-len(head)) % 4
    r = np.ascontiguousarray(ranges, dtype="<f4")
    i = np.zeros(0, "<f4") if intensities is None else np.ascontiguousarray(intensities, dtype="<f4")
    return b"".join([
        CDR_LE, head, b"\x00" * pad, _F7.pack(*floats7),
        _U32.pack(r.size), r.tobytes(), _U32.pack(i.size), i.tobytes(),
    ])


def encode_laser_scan(m: LaserScan, stamp: float) -> bytes:
    n = len(m.ranges)
    sec, nsec = stamp_to_sec_nsec(stamp)
    floats = (m.angle_min, m.angle_min + m.angle_increment * max(n - 1, 0), m.angle_increment,
              m.time_increment, m.scan_time, m.range_min, m.range_max)
    return encode_scan(sec, nsec, m.frame_id, floats, m.ranges, m.intensities)


def encode_odometry(m: Odometry, stamp: float) -> bytes:
    head = _header_bytes(stamp, m.frame_id)
    child = _string_bytes(len(head), m.child_frame_id)
    n = len(head) + len(child)
    pose = (0.0, 0.0, 0.0) if m.pose is None else tuple(float(v) for v in m.pose)
    tw = [float(v) for v in m.twist]
    pcov = cov6_of(m.pose_cov)
    if m.pose is None:
        pcov[0] = -1.0
    vals = [pose[0], pose[1], 0.0, *_quat(pose[2]), *pcov, tw[0], tw[1], 0.0, 0.0, 0.0, tw[2], *cov6_of(m.twist_cov)]
    return b"".join([CDR_LE, head, child, b"\x00" * _pad(n, 8), struct.pack("<85d", *vals)])


def encode_twist(m: Twist, stamp: float) -> bytes:
    """A ``geometry_msgs/TwistWithCovarianceStamped`` (z, roll and pitch rates 0)."""
    head = _header_bytes(stamp, m.frame_id)
    tw = [float(v) for v in m.twist]
    vals = [tw[0], tw[1], 0.0, 0.0, 0.0, tw[2], *cov6_of(m.twist_cov)]
    return b"".join([CDR_LE, head, b"\x00" * _pad(len(head), 8), struct.pack("<42d", *vals)])


def encode_compass(m: CompassHeading, stamp: float) -> bytes:
    head = _header_bytes(stamp, m.frame_id)
    vals = [*_quat(0.0 if m.yaw_rad is None else float(m.yaw_rad)),
            *cov9_of(m.yaw_var, m.yaw_rad is None),
            0.0, 0.0, 0.0 if m.yaw_rate_radps is None else float(m.yaw_rate_radps),
            *cov9_of(m.yaw_rate_var, m.yaw_rate_radps is None),
            0.0, 0.0, 0.0, *cov9_of(float("nan"), True)]
    return b"".join([CDR_LE, head, b"\x00" * _pad(len(head), 8), struct.pack("<37d", *vals)])


def _vec(v: Any, n: int, absent: tuple[float, ...]) -> list[float]:
    return list(absent) if v is None else [float(x) for x in np.asarray(v, dtype=float).reshape(n)]


def encode_imu(m: Imu, stamp: float) -> bytes:
    """A whole :class:`Imu` (absent fields as :func:`fgloc.io.ros.imu_to_ros` writes them)."""
    head = _header_bytes(stamp, m.frame_id)
    q, w, a = m.orientation_xyzw, m.angular_velocity_radps, m.linear_acceleration_mps2
    vals = [*_vec(q, 4, (0.0, 0.0, 0.0, 1.0)), *cov9_full(m.orientation_cov, q is None),
            *_vec(w, 3, (0.0, 0.0, 0.0)), *cov9_full(m.angular_velocity_cov, w is None),
            *_vec(a, 3, (0.0, 0.0, 0.0)), *cov9_full(m.linear_acceleration_cov, a is None)]
    return b"".join([CDR_LE, head, b"\x00" * _pad(len(head), 8), struct.pack("<37d", *vals)])


_FIX_COV_AT = 7 + COV_IDX9  # the x, y, yaw covariance entries among a PoseWithCovariance's 43 doubles


def encode_pose_fix(m: PoseFix, stamp: float) -> bytes:
    head = _header_bytes(stamp, m.frame_id)
    # the 43 doubles (position, orientation, 6x6 covariance) in one little-endian buffer: the same
    # bytes as struct.pack of the list, without the 36-float list of cov6_of per message
    vals = np.zeros(43, dtype="<f8")
    p = m.pose
    vals[0], vals[1] = float(p[0]), float(p[1])
    _, _, vals[5], vals[6] = _quat(float(p[2]))
    if m.cov is not None:
        vals[_FIX_COV_AT] = np.asarray(m.cov, dtype=float).reshape(9)
    return b"".join([CDR_LE, head, b"\x00" * _pad(len(head), 8), vals.tobytes()])


def encode_tf(m: Sequence[StaticTransform], stamp: float) -> bytes:
    parts = [CDR_LE, _U32.pack(len(m))]
    n = 4
    for t in m:
        head = b"\x00" * _pad(n, 4) + _header_bytes(stamp, t.parent)
        n += len(head)
        child = _string_bytes(n, t.child)
        n += len(child)
        pad = b"\x00" * _pad(n, 8)
        n += len(pad) + 56
        q = getattr(t, "rotation_xyzw", None)
        rot = _quat(float(t.pose[2])) if q is None else tuple(float(v) for v in np.asarray(q, dtype=float).reshape(4))
        vals = (float(t.pose[0]), float(t.pose[1]), float(t.z), *rot)
        parts += [head, child, pad, _D7.pack(*vals)]
    return b"".join(parts)


# --------------------------------------------------------------------------------------------
# decoders
def _string_at(buf: Buffer, p: int) -> tuple[str, int]:
    """The CDR string whose length field is at ``p`` (already aligned); ``(text, end)``.

    As the generic decoder: the length counts the NUL, which is dropped."""
    (n,) = _U32.unpack_from(buf, p)
    end = p + 4 + n
    if end > len(buf):
        raise ValueError("string overruns the message")
    return bytes(buf[p + 4 : end - 1 if n else end]).decode(), end


def _aligned(p: int, align: int) -> int:
    return p + (-(p - 4)) % align


def _scan_layout(data: Buffer) -> tuple[str, int, int, int] | None:
    """``(frame_id, offset of the 7 floats, beams, intensities)`` of a LaserScan, or None."""
    if len(data) < 16 or data[0] != 0 or data[1] != 1:
        return None
    try:
        frame_id, p = _string_at(data, 12)
        p = _aligned(p, 4)
        (n,) = _U32.unpack_from(data, p + 28)
        q = p + 32 + 4 * n
        (m,) = _U32.unpack_from(data, q)
    except (struct.error, ValueError, UnicodeDecodeError):
        return None
    if q + 4 + 4 * m > len(data):
        return None
    return frame_id, p, n, m


def decode_laser_scans(datas: Sequence[Buffer]) -> list[LaserScan | None]:
    """LaserScans of a batch (None where the layout does not apply).  Scans of one layout
    (length, frame id, beam counts) are read as one strided array; each scan gets its own
    copy of its ranges (a kept scan never holds a whole chunk's memory)."""
    out: list[LaserScan | None] = [None] * len(datas)
    groups: dict[tuple[int, bytes, int, int], tuple[list[int], str, int]] = {}
    key: tuple[int, bytes, int, int] | None = None
    cur: list[int] = []
    P = Q = 0  # offsets of the 7 floats and the intensity count in the current layout
    for i, data in enumerate(datas):
        if key is not None and len(data) == key[0] and data[12:P] == key[1] and data[0] == 0 and data[1] == 1 \
                and _U32.unpack_from(data, P + 28)[0] == key[2] and _U32.unpack_from(data, Q)[0] == key[3]:
            cur.append(i)
            continue
        lay = _scan_layout(data)
        if lay is None:
            continue
        frame_id, P, n, m = lay
        Q = P + 32 + 4 * n
        key = (len(data), bytes(data[12:P]), n, m)
        g = groups.get(key)
        if g is None:
            g = groups[key] = ([], frame_id, P)
        cur = g[0]
        cur.append(i)
    for (L, _, n, m), (members, frame_id, p) in groups.items():
        buf = b"".join(bytes(datas[i]) for i in members)
        k = len(members)
        sec = np.ndarray((k,), dtype="<i4", buffer=buf, offset=4, strides=(L,)).astype(np.float64)
        nsec = np.ndarray((k,), dtype="<u4", buffer=buf, offset=8, strides=(L,)).astype(np.float64)
        stamps = (sec + nsec * 1e-9).tolist()
        f7 = np.ndarray((k, 7), dtype="<f4", buffer=buf, offset=p, strides=(L, 4)).astype(np.float64).tolist()
        ranges = np.ndarray((k, n), dtype="<f4", buffer=buf, offset=p + 32, strides=(L, 4))
        inten = np.ndarray((k, m), dtype="<f4", buffer=buf, offset=p + 36 + 4 * n, strides=(L, 4)) if m else None
        for j, i in enumerate(members):
            amin, _amax, inc, tinc, stime, rmin, rmax = f7[j]
            out[i] = LaserScan(stamps[j], amin, inc, rmin, rmax, ranges[j].astype(np.float32),
                               tinc, stime, None if inten is None else inten[j].astype(np.float32), frame_id)
    return out


def _layout(data: Buffer, strings: int, align: int, n_doubles: int) -> tuple[tuple[str, ...], int] | None:
    """``(strings, offset of the doubles)`` of a header(+child string) message, or None."""
    if len(data) < 16 or data[0] != 0 or data[1] != 1:
        return None
    try:
        s0, p = _string_at(data, 12)
        texts: tuple[str, ...] = (s0,)
        if strings == 2:
            s1, p = _string_at(data, _aligned(p, 4))
            texts = (s0, s1)
    except (struct.error, ValueError, UnicodeDecodeError):
        return None
    p = _aligned(p, align)
    if p + 8 * n_doubles > len(data):
        return None
    return texts, p


def decode_columns(datas: Sequence[Buffer], strings: int, n_doubles: int
             ) -> tuple[list[int], list[tuple[str, ...]], np.ndarray, np.ndarray] | None:
    """Decode a batch's fixed part: ``(indices decoded, strings, stamps, doubles (k, n))``.

    Messages with the same length and the same bytes from the frame id to the doubles (a
    channel's messages, as a rule) share one layout and are read as one strided array."""
    groups: dict[tuple[int, bytes], tuple[list[int], tuple[str, ...], int]] = {}
    L = P = -1
    pref = b""
    cur: list[int] = []
    for i, data in enumerate(datas):
        if len(data) == L and data[12:P] == pref and data[0] == 0 and data[1] == 1:
            cur.append(i)
            continue
        lay = _layout(data, strings, 8, n_doubles)
        if lay is None:
            continue
        texts, P = lay
        L, pref = len(data), bytes(data[12:P])
        g = groups.get((L, pref))
        if g is None:
            g = groups[(L, pref)] = ([], texts, P)
        cur = g[0]
        cur.append(i)
    if not groups:
        return None
    idx: list[int] = []
    text_l: list[tuple[str, ...]] = []
    stamps, vals = [], []
    for (n, _), (members, texts, p) in groups.items():
        buf = b"".join(bytes(datas[i]) for i in members)
        k = len(members)
        sec = np.ndarray((k,), dtype="<i4", buffer=buf, offset=4, strides=(n,)).astype(np.float64)
        nsec = np.ndarray((k,), dtype="<u4", buffer=buf, offset=8, strides=(n,)).astype(np.float64)
        stamps.append(sec + nsec * 1e-9)
        vals.append(np.ndarray((k, n_doubles), dtype="<f8", buffer=buf, offset=p, strides=(n, 8)).astype(np.float64))
        idx += members
        text_l += [texts] * k
    if len(groups) == 1:
        return idx, text_l, stamps[0], vals[0]
    return idx, text_l, np.concatenate(stamps), np.concatenate(vals)


def _damaged_values_as_generic(decode: F) -> F:
    """Overflow / invalid values in damaged messages decode to inf / nan silently, as the generic codec."""
    @functools.wraps(decode)
    def quiet(*args: Any, **kwargs: Any) -> Any:
        with np.errstate(over="ignore", invalid="ignore"):
            return decode(*args, **kwargs)

    return quiet  # type: ignore[return-value]


def _cov3s(c36: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(k, 3, 3)`` covariances and whether each 6x6 is all zero ("unknown")."""
    return c36[:, COV_IDX9].reshape(-1, 3, 3), ~np.any(c36 != 0.0, axis=1)


def _odometry_poses(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The poses ``[x, y, yaw]`` of a batch of ``nav_msgs/Odometry`` doubles and whether each message
    has one (REP 145: a first pose covariance of ``-1`` says it has none)."""
    yaw = quaternion_to_yaw(v[:, 3], v[:, 4], v[:, 5], v[:, 6])
    return np.stack([v[:, 0], v[:, 1], yaw], axis=1), v[:, 7] != -1.0


@_damaged_values_as_generic
def decode_odometries(datas: Sequence[Buffer]) -> list[Odometry | None]:
    out: list[Odometry | None] = [None] * len(datas)
    cols = decode_columns(datas, 2, 85)
    if cols is None:
        return out
    idx, texts, stamps, v = cols
    poses, has = _odometry_poses(v)
    twists = v[:, (43, 44, 48)].copy()
    pcov, pzero = _cov3s(v[:, 7:43])
    tcov, tzero = _cov3s(v[:, 49:85])
    no_pose = (~has).tolist()
    pz, tz = pzero.tolist(), tzero.tolist()
    stamp_l = stamps.tolist()
    for k, i in enumerate(idx):
        has_pose = not no_pose[k]
        t = texts[k]
        out[i] = Odometry(stamp_l[k], twists[k], None if tz[k] else tcov[k], poses[k] if has_pose else None,
                          pcov[k] if has_pose and not pz[k] else None, t[0], t[1])
    return out


@_damaged_values_as_generic
def odometry_stamped_poses(datas: Sequence[Buffer]) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The stamps (s), poses ``[x, y, yaw]`` and whether each message has a pose (REP 145: not a
    ``-1`` first pose covariance) of a batch of ``nav_msgs/Odometry``, in the batch's order: what
    :func:`decode_odometries` of the same batch gives as ``stamp`` and ``pose`` (the same maths on
    the same arrays), without the message objects.  None when a message is not of the standard
    layout (decode those one by one)."""
    if not datas:
        return np.zeros(0), np.zeros((0, 3)), np.zeros(0, dtype=bool)
    cols = decode_columns(datas, 2, 85)
    if cols is None or len(cols[0]) != len(datas):
        return None
    idx, _texts, stamps, v = cols
    poses, has = _odometry_poses(v)
    order = np.empty(len(idx), dtype=np.intp)
    order[np.asarray(idx, dtype=np.intp)] = np.arange(len(idx))  # batch position -> row
    return stamps[order], poses[order], has[order]


@_damaged_values_as_generic
def decode_imus(datas: Sequence[Buffer]) -> list[Imu | None]:
    """Whole :class:`Imu` s, as :func:`fgloc.io.ros.imu_from_ros` gives them."""
    out: list[Imu | None] = [None] * len(datas)
    cols = decode_columns(datas, 1, 37)
    if cols is None:
        return out
    idx, texts, stamps, v = cols
    # doubles: orientation 0:4, its covariance 4:13, angular velocity 13:16, 16:25, acceleration 25:28, 28:37
    absent = (v[:, (4, 16, 28)] == -1.0).tolist()
    oc, wc, ac = (v[:, j : j + 9].reshape(-1, 3, 3) for j in (4, 16, 28))
    known = np.any(v[:, 4:13] != 0.0, axis=1).tolist(), np.any(v[:, 16:25] != 0.0, axis=1).tolist(), \
        np.any(v[:, 28:37] != 0.0, axis=1).tolist()
    stamp_l = stamps.tolist()
    for k, i in enumerate(idx):
        nq, nw, na = absent[k]
        out[i] = Imu(stamp_l[k],
                     None if nq else v[k, 0:4], None if nw else v[k, 13:16],
                     None if nq or not known[0][k] else oc[k], None if nw or not known[1][k] else wc[k],
                     None if na else v[k, 25:28], None if na or not known[2][k] else ac[k],
                     texts[k][0])
    return out


@_damaged_values_as_generic
def decode_pose_fixes(datas: Sequence[Buffer], topic: str = "") -> list[PoseFix | None]:
    out: list[PoseFix | None] = [None] * len(datas)
    cols = decode_columns(datas, 1, 43)
    if cols is None:
        return out
    idx, texts, stamps, v = cols
    yaw = quaternion_to_yaw(v[:, 3], v[:, 4], v[:, 5], v[:, 6])
    poses = np.stack([v[:, 0], v[:, 1], yaw], axis=1)
    cov, zero = _cov3s(v[:, 7:43])
    zl = zero.tolist()
    stamp_l = stamps.tolist()
    for k, i in enumerate(idx):
        out[i] = PoseFix(stamp=stamp_l[k], pose=poses[k], cov=np.zeros((3, 3)) if zl[k] else cov[k],
                         source=topic, frame_id=texts[k][0])
    return out


def _tf_layout(data: Buffer) -> list[tuple[str, str, int]] | None:
    """``[(parent, child, offset of the 7 doubles)]`` of a TFMessage, or None."""
    if len(data) < 8 or data[0] != 0 or data[1] != 1:
        return None
    try:
        (n,) = _U32.unpack_from(data, 4)
        if 40 * n > len(data):  # each transform takes at least 40 bytes: not this layout
            return None
        p = 8
        out = []
        for _ in range(n):
            p = _aligned(p, 4)
            parent, p = _string_at(data, p + 8)
            child, p = _string_at(data, _aligned(p, 4))
            p = _aligned(p, 8)
            if p + 56 > len(data):
                return None
            out.append((parent, child, p))
            p += 56
    except (struct.error, ValueError, UnicodeDecodeError):
        return None
    return out


@_damaged_values_as_generic
def decode_tf_messages(datas: Sequence[Buffer]) -> list[tuple[list[StaticTransform], list[bool]] | None]:
    """Per message: ``(transforms, upside-down flags)`` (see :func:`fgloc.io.ros.tf_flips`)."""
    out: list[tuple[list[StaticTransform], list[bool]] | None] = [None] * len(datas)
    lays: list[tuple[int, list[tuple[str, str, int]]]] = []
    rows: list[Buffer] = []
    prev: list[tuple[str, str, int]] | None = None
    L = 0
    spans: list[tuple[int, int]] = []
    sig = b""
    for i, data in enumerate(datas):
        # a message with the previous one's length, count and string bytes has its layout
        if prev is not None and len(data) == L and data[0] == 0 and data[1] == 1 \
                and b"".join([data[x:y] for x, y in spans]) == sig:
            lay = prev
        else:
            found = _tf_layout(data)
            if found is None:
                prev = None
                continue
            lay = prev = found
            L = len(data)
            # the bytes from each transform's frame id length to its doubles, and the count
            starts = ([8] + [p + 56 for _, _, p in lay[:-1]])[: len(lay)]
            spans = [(4, 8)] + [(_aligned(q, 4) + 8, p) for q, (_, _, p) in zip(starts, lay, strict=True)]
            sig = b"".join([data[x:y] for x, y in spans])
        lays.append((i, lay))
        rows += [data[p : p + 56] for _, _, p in lay]
    if not lays:
        return out
    v = np.frombuffer(b"".join(rows), dtype="<f8").reshape(-1, 7).astype(np.float64)
    yaw = quaternion_to_yaw(v[:, 3], v[:, 4], v[:, 5], v[:, 6]) if len(v) else np.zeros(0)
    poses = np.stack([v[:, 0], v[:, 1], yaw], axis=1)
    quats = v[:, 3:7]
    vl = v.tolist()
    k = 0
    for i, lay in lays:
        tfs: list[StaticTransform] = []
        flips: list[bool] = []
        for parent, child, _ in lay:
            x, y, z, qx, qy, qz, qw = vl[k]
            tfs.append(Transform3D(parent=parent.lstrip("/"), child=child.lstrip("/"), pose=poses[k], z=z,
                                   rotation_xyzw=quats[k]))
            nq = qx * qx + qy * qy + qz * qz + qw * qw
            flips.append(nq > 0 and 1.0 - 2.0 * (qx * qx + qy * qy) / nq < 0.0)
            k += 1
        out[i] = (tfs, flips)
    return out

