"""Real SICK telegrams (public recordings from TiM571, TiM55x and LMS5xx devices; sources in
tests/live/real_telegrams.py) parse to ranges in metres and REP 103 angles: counter-clockwise
from the laser's x axis, the device's 90 deg (straight ahead) at 0."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fgloc.live.sick import parse_lmdscandata, telegram_to_scan

from .real_telegrams import LMS5XX_SCALE2, TIM55X_RSSI8, TIM571_NAME_BLOCK, TIM571_RSSI16

# telegram, beams, angle_min deg, step deg, first range m (inf: no echo), beam time s, scan time s
REAL = {
    "tim571_name_block": (TIM571_NAME_BLOCK, 811, -135.0, 0.3333, 0x24B / 1000, 1 / 16200, 1 / 15),
    "tim571_rssi16": (TIM571_RSSI16, 811, -135.0, 0.3333, math.inf, 1 / 16200, 1 / 15),
    "tim55x_rssi8": (TIM55X_RSSI8, 271, -135.0, 1.0, 0x1B8 / 1000, 1 / 5400, 1 / 15),
    "lms5xx_scale2": (LMS5XX_SCALE2, 241, -90.0, 0.5, 2 * 0x363 / 1000, 1 / 36000, 1 / 50),
}


@pytest.mark.parametrize("name", sorted(REAL))
def test_real_device_telegram_parses_to_metres_and_rep103_angles(name):
    payload, n, amin_deg, step_deg, r0, dt, period = REAL[name]
    t = parse_lmdscandata(payload)
    assert len(t.values) == n and t.channel == "DIST1"
    s = telegram_to_scan(t, stamp=0.0, range_max=50.0)
    assert math.degrees(s.angle_min) == pytest.approx(amin_deg, abs=1e-9)
    assert math.degrees(s.angle_increment) == pytest.approx(step_deg, abs=1e-9)
    assert s.ranges[0] == pytest.approx(r0) if math.isfinite(r0) else np.isposinf(s.ranges[0])
    assert s.time_increment == pytest.approx(dt, rel=1e-6) and s.scan_time == pytest.approx(period)
    fin = s.ranges[np.isfinite(s.ranges)]
    assert len(fin) > 0.5 * n and np.all((fin > 0) & (fin <= 50.0))
    # the device's 90 deg (its forward axis) is REP 103's 0 (x forward)
    k = round((90.0 - t.start_angle_deg) / t.step_deg)
    assert math.degrees(s.angle_min + k * s.angle_increment) == pytest.approx(0.0, abs=0.02)


def test_real_telegram_values_are_the_distance_channel_not_the_remission():
    """TiM571 with RSSI1 as a second 16-bit channel: DIST1's values, never RSSI1's, in metres."""
    tok = TIM571_RSSI16.split()
    i = tok.index(b"DIST1")
    dist_mm = np.array([int(v, 16) for v in tok[i + 6 : i + 6 + 811]], dtype=float)
    s = telegram_to_scan(parse_lmdscandata(TIM571_RSSI16), 0.0, range_max=50.0)
    fin = dist_mm > 0
    assert np.allclose(s.ranges[fin], dist_mm[fin] / 1000.0, atol=1e-6)
    assert np.all(np.isposinf(s.ranges[~fin]))


def test_lms5xx_scale_2_ranges_in_2_mm_units_beyond_range_max_is_inf():
    s = telegram_to_scan(parse_lmdscandata(LMS5XX_SCALE2), 0.0, range_max=50.0)
    tok = LMS5XX_SCALE2.split()
    i = tok.index(b"DIST1")
    raw = np.array([int(v, 16) for v in tok[i + 6 : i + 6 + 241]])
    assert raw.max() == 0x7BA9  # 63.314 m at scale 2: beyond the 50 m range_max
    assert np.isposinf(s.ranges[raw == 0x7BA9]).all()
    ok = (raw > 0) & (2 * raw <= 50000)
    assert np.allclose(s.ranges[ok], 2 * raw[ok] / 1000.0, atol=1e-6)
