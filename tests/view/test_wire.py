"""fgloc.view.wire writes the bytes foxglove-sdk's LaserScan encodes to."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fgloc.types import LaserScan
from fgloc.view import encode, wire

pytest.importorskip("foxglove")

# stamps before 0, not finite, rounding up to the next second, at the end of 32-bit seconds and past it
STAMPS = [0.0, -1.0, 12.5, 1.9999999999, 1.7e9 + 0.123456789, math.nan, math.inf, 4294967295.5, 5e9]
# angles a protobuf writer treats specially: zero and negative zero (omitted), NaN and infinities (written)
ANGLES = [0.0, -0.0, -2.356, 5e-324, 1e300, math.nan, math.inf, -math.inf]


def _outcome(make, *args):
    """``make(*args)``'s bytes, or the kind of error (the recorder counts either way's alike)."""
    try:
        out = make(*args)
    except (TypeError, ValueError, OverflowError) as e:
        return type(e)
    return out if isinstance(out, bytes) else out.encode()


def test_laser_scan_as_the_sdk_encodes_it() -> None:
    rng = np.random.default_rng(4)
    n_bytes = n_errors = 0
    for i, n in enumerate([0, 1, 15, 16, 17, 200, 1081, 3]):
        ranges = rng.uniform(0.0, 12.0, n).astype(np.float32)
        ranges[::7] = np.nan
        ranges[1::9] = np.inf
        ranges[2::11] = 0.01  # below range_min
        intensities = rng.uniform(0, 100, n).astype(np.float32) if i % 2 else None
        for frame in ("laser", "", "l\u00e4ser \"2\""):
            for stamp in STAMPS:
                for angle in ANGLES[i % 3::3]:
                    scan = LaserScan(stamp, angle, [0.0043, 0.0, -0.01][i % 3], 0.05, 10.0, ranges,
                                     intensities=intensities, frame_id=frame)
                    got = _outcome(wire.laser_scan, scan)
                    assert got == _outcome(encode.scan_message, scan)
                    n_bytes += isinstance(got, bytes)
                    n_errors += not isinstance(got, bytes)
    assert n_bytes > 100 and n_errors > 10  # past 32-bit seconds: an error either way
    short = LaserScan(1.0, -1.0, 0.1, 0.05, 10.0, np.ones(5, np.float32), intensities=np.ones(4, np.float32))
    assert wire.laser_scan(short) == encode.scan_message(short).encode()  # intensities of another length: left out


def test_varint() -> None:
    for v in (0, 1, 127, 128, 300, 2**32 - 1, 10**12):
        b = wire.varint(v)
        assert sum((x & 0x7F) << (7 * k) for k, x in enumerate(b)) == v
        assert all(x & 0x80 for x in b[:-1]) and not b[-1] & 0x80
