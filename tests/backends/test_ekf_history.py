"""The EKF's measurements in stamp order (fgloc.backends.ekf_history): odometry delivered 0.3 s after its
stamps is applied at its stamps, the later measurements again after it, so the filter is the one it is
with the odometry on time; applied at the filter time instead (``ekf.history_s: 0``) the velocity lags
0.3 s, the pose runs ahead while the robot accelerates and the filter rejects its own right fixes."""

from __future__ import annotations

import numpy as np
import pytest

from fgloc.backends.ekf import EKFConfig
from fgloc.backends.ekf_backend import EKFBackend
from fgloc.types import PoseFix

FIX_COV = np.diag([0.01**2, 0.01**2, 1e-4])


def _x(t):
    """The truth along x: 1 m/s^2 for a second, then 1 m/s."""
    t = np.asarray(t, dtype=float)
    return np.where(t < 1.0, 0.5 * t**2, 0.5 + (t - 1.0))


def _messages(late_s):
    """(arrival, stamp, kind, value): odometry at 50 Hz (each twist the mean over its step), compass at
    10 Hz, fixes at the truth at 10 Hz; the odometry arriving ``late_s`` after its stamps."""
    out = []
    prev = 0.0
    for t in np.arange(0.02, 3.0001, 0.02):
        out.append((t + late_s, t, "odom", np.array([float(_x(t) - _x(prev)) / (t - prev), 0.0, 0.0])))
        prev = t
    out += [(t, t, "compass", None) for t in np.arange(0.05, 3.0, 0.1)]
    out += [(t + 1e-4, t, "fix", np.array([float(_x(t)), 0.0, 0.0])) for t in np.arange(0.1, 3.0, 0.1)]
    return sorted(out, key=lambda m: m[0])


def _run(late_s, history_s):
    be = EKFBackend(EKFConfig(history_s=history_s))
    be.set_compass_offset(0.0)
    be.initialize(0.0, np.zeros(3), np.diag([1e-4, 1e-4, 1e-4]))
    for _, t, kind, value in _messages(late_s):
        if kind == "odom":
            be.add_odometry(t, value, None)
        elif kind == "compass":
            be.add_compass(t, 0.0, 1e-4, None, 0.0)
        else:
            be.add_keyframe(t, PoseFix(t, value, FIX_COV, source="test"))
    final = be.finish()
    return be, final, np.abs(final.poses[:, 0] - _x(final.stamps))


def test_late_odometry_is_applied_at_its_stamps():
    _, on_time, _ = _run(0.0, 1.0)
    be, final, err = _run(0.3, 1.0)
    # every odometry message put in its place (all but the last three, stamped after every other message)
    assert be.stats["reordered"] == 147 and be.stats["late"] == 0
    assert be.stats["fixes_rejected"] == 0
    np.testing.assert_array_equal(final.stamps, on_time.stamps)
    assert float(np.max(np.abs(final.poses - on_time.poses))) < 0.002  # measured 0.0010 m
    assert float(err.max()) < 0.002
    # the online poses are as known then: the fix's, with the odometry 0.3 s behind
    online = be.online_trajectory()
    assert float(np.max(np.abs(online.poses[:, 0] - _x(online.stamps)))) > float(err.max())


def test_without_the_history_late_odometry_lags_and_fixes_are_rejected():
    be, _, err = _run(0.3, 0.0)
    assert be.stats["late"] == 147 and be.stats.get("reordered", 0) == 0
    assert be.stats["fixes_rejected"] >= 10          # measured 20 of 29
    assert float(err.max()) > 0.1                    # measured 0.23 m


@pytest.mark.parametrize("history_s", [1.0, 0.0])
def test_in_order_input_is_unchanged_by_the_history(history_s):
    be, final, err = _run(0.0, history_s)
    assert be.stats["reordered"] == 0 and be.stats["late"] == 0
    assert float(err.max()) < 1e-3
