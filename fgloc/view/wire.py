"""The recorded scan (``/fgloc/scan``) as bytes, written directly: byte-identical to what
:func:`fgloc.view.encode.scan_message`'s ``foxglove.LaserScan`` encodes to, without making it.

The SDK's object takes the ranges as a Python list of floats, one conversion per beam; the
protobuf wire format stores them packed, which is the float64 array's own bytes.  The message
is written as the SDK writes it (proto3: fields in field-number order, a scalar equal to zero,
``-0.0`` too, omitted, a message field present even when empty, doubles as fixed 64-bit
little-endian, repeated doubles packed); ``tests/view/test_wire.py`` checks it against the SDK.
"""

from __future__ import annotations

import math
import struct

import numpy as np

from fgloc.io.ros import stamp_to_sec_nsec
from fgloc.types import LaserScan

_F64 = struct.Struct("<d")


def varint(n: int) -> bytes:
    """``n >= 0`` as a protobuf varint."""
    out = bytearray()
    while n >= 0x80:
        out.append((n & 0x7F) | 0x80)
        n >>= 7
    out.append(n)
    return bytes(out)


def _len(tag: bytes, body: bytes) -> bytes:
    """A length-delimited field (a message, a string, packed numbers)."""
    return tag + varint(len(body)) + body


def _f64(tag: bytes, v: float) -> bytes:
    return tag + _F64.pack(v) if v != 0.0 else b""  # 0.0 and -0.0 omitted, NaN written


def timestamp(stamp: float) -> bytes:
    """``foxglove.Timestamp`` of a stamp in seconds (as :func:`fgloc.view.encode.timestamp`)."""
    sec, nsec = stamp_to_sec_nsec(max(float(stamp), 0.0) if math.isfinite(stamp) else 0.0)
    if sec > 0xFFFFFFFF:
        raise OverflowError(f"stamp {stamp} s: past the 32-bit seconds of foxglove.Timestamp")
    return (b"\x08" + varint(sec) if sec else b"") + (b"\x10" + varint(nsec) if nsec else b"")


# the scan's pose in its own frame: position 0 (an empty Vector3), orientation w = 1
_ORIGIN_POSE = _len(b"\x0a", b"") + _len(b"\x12", _f64(b"\x21", 1.0))


def laser_scan(scan: LaserScan) -> bytes:
    """:func:`fgloc.view.encode.scan_message`'s bytes (beams the localizer does not use are NaN)."""
    n = len(scan.ranges)
    r = np.where(scan.valid_mask(), np.asarray(scan.ranges, dtype=np.float64), np.nan).astype("<f8", copy=False)
    end = float(scan.angle_min + scan.angle_increment * max(n - 1, 0))
    out = (_len(b"\x0a", timestamp(scan.stamp)) + _len(b"\x12", (scan.frame_id or "laser").encode())
           + _len(b"\x1a", _ORIGIN_POSE) + _f64(b"\x21", float(scan.angle_min)) + _f64(b"\x29", end))
    if n:
        out += _len(b"\x32", r.tobytes())
        if scan.intensities is not None and len(scan.intensities) == n:
            out += _len(b"\x3a", np.asarray(scan.intensities, dtype="<f8").tobytes())
    return out
