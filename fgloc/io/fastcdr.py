"""Vectorized CDR (little-endian XCDR1, as ROS 2 writes it) for ``sensor_msgs/msg/LaserScan``.

The generic ``mcap_ros2`` codec converts each beam in Python; scans are most of a log's
bytes, so they get this numpy codec.  The bytes are identical to the generic encoder's
(tested), and :func:`decode_scan` returns None for anything it does not handle (then the
generic decoder is used).

Layout after the 4-byte encapsulation header ``00 01 00 00`` (alignment counted from the
end of that header): ``int32 sec, uint32 nanosec, uint32 len(frame_id)+1, frame_id, NUL,
pad to 4, 7 x float32 (angle_min, angle_max, angle_increment, time_increment, scan_time,
range_min, range_max), uint32 n, n x float32 ranges, uint32 m, m x float32 intensities``.
"""

from __future__ import annotations

import struct
from typing import Any

import numpy as np

CDR_LE = b"\x00\x01\x00\x00"
_F7 = struct.Struct("<7f")


def encode_scan(stamp_sec: int, stamp_nsec: int, frame_id: str, floats7: tuple[float, ...],
                ranges: np.ndarray, intensities: np.ndarray | None) -> bytes:
    fid = frame_id.encode() + b"\x00"
    head = struct.pack("<iII", stamp_sec, stamp_nsec, len(fid)) + fid
    pad = (-len(head)) % 4
    r = np.ascontiguousarray(ranges, dtype="<f4")
    i = np.zeros(0, "<f4") if intensities is None else np.ascontiguousarray(intensities, dtype="<f4")
    return b"".join([
        CDR_LE, head, b"\x00" * pad, _F7.pack(*floats7),
        struct.pack("<I", r.size), r.tobytes(), struct.pack("<I", i.size), i.tobytes(),
    ])


def decode_scan(data: bytes | memoryview) -> dict[str, Any] | None:
    """The fields of a LaserScan CDR message, or None if it is not little-endian CDR."""
    buf = memoryview(data)
    if bytes(buf[:2]) != CDR_LE[:2]:
        return None
    try:
        sec, nsec, slen = struct.unpack_from("<iII", buf, 4)
        p = 16
        frame_id = bytes(buf[p : p + slen - 1]).decode()
        p += slen
        p += (-(p - 4)) % 4
        f7 = _F7.unpack_from(buf, p)
        p += 28
        (n,) = struct.unpack_from("<I", buf, p)
        p += 4
        ranges = np.frombuffer(buf, dtype="<f4", count=n, offset=p).astype(np.float32)
        p += 4 * n
        (m,) = struct.unpack_from("<I", buf, p)
        p += 4
        inten = np.frombuffer(buf, dtype="<f4", count=m, offset=p).astype(np.float32)
    except (struct.error, ValueError, UnicodeDecodeError):
        return None
    return {"sec": sec, "nanosec": nsec, "frame_id": frame_id, "floats": f7, "ranges": ranges,
            "intensities": inten}
