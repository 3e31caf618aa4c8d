"""The vectorized LaserScan codec is byte-identical to mcap_ros2's generic CDR codec."""

from __future__ import annotations

import numpy as np
import pytest

from fgloc.io.fastcdr import decode_laser_scans, decode_scan, encode_laser_scan
from fgloc.io.msgdefs import full_text
from fgloc.io.ros import scan_from_ros, scan_to_ros
from fgloc.io.topics import LASER_SCAN
from fgloc.types import LaserScan


@pytest.mark.parametrize("frame", ["", "l", "la", "las", "laser", "base_laser_link"])
@pytest.mark.parametrize("n,with_int", [(0, False), (1, True), (181, False), (1081, True)])
def test_bytes_equal_generic_codec(frame, n, with_int):
    from mcap_ros2._dynamic import generate_dynamic, serialize_dynamic

    enc = serialize_dynamic(LASER_SCAN, full_text(LASER_SCAN))[LASER_SCAN]
    dec = generate_dynamic(LASER_SCAN, full_text(LASER_SCAN))[LASER_SCAN]
    rng = np.random.default_rng(n)
    r = rng.uniform(0, 30, n).astype(np.float32)
    if n > 3:
        r[:3] = [np.inf, -np.inf, np.nan]
    scan = LaserScan(1234.000000567, -2.35, 0.0043633, 0.05, 40.0, r, 1e-5, 0.04,
                     rng.uniform(0, 1, n).astype(np.float32) if with_int else None, frame)
    fast = encode_laser_scan(scan, scan.stamp)
    assert fast == enc(scan_to_ros(scan, scan.stamp))
    (a,) = decode_laser_scans([fast])
    b = scan_from_ros(dec(fast), "/scan")
    assert a is not None
    for f in ("stamp", "angle_min", "angle_increment", "range_min", "range_max", "time_increment",
              "scan_time", "frame_id"):
        assert getattr(a, f) == getattr(b, f)
    np.testing.assert_array_equal(a.ranges, b.ranges)
    assert (a.intensities is None) == (b.intensities is None) == (not with_int or n == 0)


def test_big_endian_falls_back():
    assert decode_scan(b"\x00\x00\x00\x00" + bytes(40)) is None
    assert decode_scan(b"\x00\x01\x00\x00" + bytes(5)) is None
