"""The smoother's own divergence measure (fgloc.backends.smoother.consistency): the fused heading
against the heading sources it fuses, keyframe by keyframe (pure maths, no graph)."""

from __future__ import annotations

import math

import numpy as np

from fgloc.backends.smoother.consistency import HeadingConsistency

DT = 0.1  # s between keyframes


def _feed(hc: HeadingConsistency, seconds: float, fused_rate: float, gyro_rate: float, compass_rate: float,
          t0: float = 0.0, yaw0: float = 0.0, compass0: float | None = None) -> float:
    """Keyframes every 0.1 s: the fused heading turning at ``fused_rate``, a gyro (1e-6 rad^2 per
    increment) at ``gyro_rate``, a compass (0.01 rad sigma) at ``compass_rate`` (rad/s), from
    ``yaw0`` and ``compass0`` (default ``yaw0``); the last stamp."""
    rng = np.random.default_rng(int(t0) + 1)
    c0 = yaw0 if compass0 is None else compass0
    t = t0
    for k in range(1, int(round(seconds / DT)) + 1):
        t = t0 + k * DT
        hc.add(t, math.remainder(yaw0 + fused_rate * k * DT, 2 * math.pi),
               {"imu.gyro": (gyro_rate * DT + rng.normal(0.0, 1e-3), 1e-6)},
               {"imu.yaw": (math.remainder(c0 + compass_rate * k * DT + rng.normal(0.0, 0.01), 2 * math.pi), 1e-4)})
    return t


def test_a_fused_heading_that_follows_one_source_is_not_diverging():
    """The gyro and the compass disagree (the compass turns 0.01 rad/s more, a magnetometer drifting
    35 deg in a minute); the fused heading follows the gyro: it follows one of its sources."""
    hc = HeadingConsistency()
    _feed(hc, 200.0, fused_rate=0.2, gyro_rate=0.2, compass_rate=0.21)
    assert hc.latest is not None and hc.latest.nearest == "imu.gyro"
    assert hc.worst is not None and hc.worst.score < 2.0   # the gyro's own random walk: 1.24
    assert hc.diverged_total_s() == 0.0 and hc.spans == 0 and not hc.diverging()


def test_a_fused_heading_that_follows_no_source_is_diverging_and_counted():
    """60 s following both sources, then 60 s turning 0.005 rad/s (17 deg a minute) away from both
    (it runs between them no more: beyond them): a divergence from its inputs, counted from when it
    exceeds the gyro's and the compass's sigmas (floored at 2 deg) fourfold, until it follows again."""
    hc = HeadingConsistency(windows_s=(20.0, 120.0), threshold=4.0)
    t = _feed(hc, 60.0, 0.1, 0.1, 0.1)
    assert not hc.diverging()
    t = _feed(hc, 70.0, 0.105, 0.1, 0.1, t0=t, yaw0=0.1 * 60.0)
    assert hc.diverging() and hc.spans == 1
    assert hc.latest is not None and abs(hc.latest.off_deg) > 4 * 2.0
    # over the 120 s window: 0.35 rad (20 deg) off the nearest source, give or take its random walk
    assert 14.0 < abs(hc.worst.off_deg) < 26.0   # type: ignore[union-attr]
    spent = hc.diverged_total_s(t)
    assert 5.0 < spent < 70.0   # from when the 120 s window holds the 0.3 rad: 9.8 s
    # back to following its sources: the span ends once the windows no longer hold the departure
    t = _feed(hc, 200.0, 0.1, 0.1, 0.1, t0=t, yaw0=0.1 * 60.0 + 0.105 * 70.0, compass0=0.1 * 130.0)
    assert not hc.diverging() and hc.spans == 1
    assert hc.diverged_total_s(t) >= spent


def test_a_gap_in_a_source_is_not_bridged():
    """A relative source missing keyframes starts its sums again: its change over a window that
    holds the gap is not compared (the fused heading turned while nothing measured it)."""
    hc = HeadingConsistency(windows_s=(5.0,))
    for k in range(1, 121):
        t = k * DT
        inc = {} if 40 <= k < 60 else {"odom": (0.0, 1e-6)}
        hc.add(t, 0.5 if k >= 50 else 0.0, inc, {})
        if 60 <= k < 110:
            assert hc.latest is None or hc.latest.t < t   # no window covers the source unbroken yet
    assert hc.latest is not None and hc.latest.nearest == "odom" and hc.latest.score < 1.0


def test_an_absolute_source_that_misses_keyframes_is_still_followed():
    """The scan fixes (an absolute source) miss a keyframe now and then; the wheels (a relative source)
    drift 0.5 deg/s (unequal wheel radii).  The fused heading follows the fixes: no divergence.
    (Was: each missed keyframe started the fixes' run again, no window held them unbroken, and the
    fused heading was compared with the wheels alone: 36 s "followed none", exit 3, on a diff-drive
    simulation with 0.018 m / 0.26 deg RMSE.)"""
    hc = HeadingConsistency()
    rng = np.random.default_rng(4)
    for k in range(1, 1501):
        t = k * DT
        yaw = 0.05 * t
        fixes = {} if k % 37 == 0 else {"scan": (math.remainder(yaw + rng.normal(0.0, 0.003), 2 * math.pi), 1e-5)}
        hc.add(t, math.remainder(yaw, 2 * math.pi), {"odom": ((0.05 + math.radians(0.5)) * DT, 1e-6)}, fixes)
    assert hc.latest is not None and hc.latest.nearest == "scan"
    assert hc.spans == 0 and hc.worst is not None and hc.worst.score < 2.0


def test_an_absolute_source_is_unwrapped_across_the_keyframes_it_missed():
    """Turning through +-180 deg while the readings miss keyframes: no 360 deg jump in the source."""
    hc = HeadingConsistency(windows_s=(10.0,))
    for k in range(1, 401):
        t = k * DT
        yaw = math.remainder(3.0 + 0.3 * t, 2 * math.pi)
        hc.add(t, yaw, {}, {} if k % 3 else {"imu.yaw": (yaw, 1e-4)})
    assert hc.worst is not None and hc.worst.score < 0.1 and hc.spans == 0
