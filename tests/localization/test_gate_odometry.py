"""The jump gate with odometry that is late, stops or is absent for a while (fgloc.localization.gate):
the odometry's motion counts only where its stamps cover the time since the previous fix; elsewhere a
fix follows the previous one as the fixes themselves moved, so a wrong fix is not explained by an
extrapolated motion nor a right one held by a frozen odometry."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from fgloc.localization.gate import JumpGate, OdometryCoverage
from fgloc.localization.monitor import IntegrityConfig
from fgloc.types import PoseFix

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "frontends"))
from synth import MOUNT, make_map, make_scan  # noqa: E402

TIGHT = np.diag([0.003**2, 0.003**2, np.radians(0.05) ** 2])
PRED_COV = np.diag([0.004**2, 0.004**2, np.radians(0.2) ** 2])
SPEED = 0.8  # m/s along +y at x = 8 m in the synthetic room
DT = 0.08    # s between fixes (25 Hz scans, every second one matched)


@pytest.fixture(scope="module")
def room():
    return make_map()


def _truth(t):
    return np.array([8.0, 2.0 + SPEED * t, np.pi / 2])


def _fix(pose, t):
    return PoseFix(t, np.asarray(pose, dtype=float), TIGHT.copy(), quality=0.9, source="test")


def _odom(t):
    """The wheels' odom pose at t (their frame: along x)."""
    return np.array([SPEED * t, 0.0, 0.0])


def _track(gate, room, stamps, odom, covered=True):
    """Fixes at the truth at ``stamps``, the prediction right, the odometry pose ``odom(t)``; all taken."""
    for t in stamps:
        v = gate.check(_fix(_truth(t), t), _truth(t), PRED_COV, make_scan(room, _truth(t)), odom(t), t,
                       motion_covered=covered)
        assert v.take
        gate.accepted()


def test_coverage_by_stamps():
    cov = OdometryCoverage(0.25)
    assert not cov.covers(0.0, 1.0)  # nothing yet
    for t in np.arange(0.0, 2.0001, 0.02):  # 50 Hz until 2 s, silent until 3 s, again until 4 s
        cov.add(float(t))
    for t in np.arange(3.0, 4.0001, 0.02):
        cov.add(float(t))
    assert cov.covers(0.5, 1.5) and cov.covers(3.2, 3.9)
    assert not cov.covers(1.5, 2.3)       # the newest stamp 0.3 s behind the scan: late, or stopped
    assert not cov.covers(1.0, 3.5)       # a second without odometry in between
    assert cov.covers(1.0, 2.2)           # the newest stamp within the gap allowed
    assert not cov.covers(3.5, 4.3)       # late by 0.3 s
    assert cov.uncovered_s(1.0, 3.5) == pytest.approx(1.0, abs=0.03)
    assert cov.uncovered_s(0.5, 1.5) == 0.0


def test_stopped_odometry_the_fixes_motion_carries_the_previous_fix(room):
    """The wheel driver died: the odometry pose stands still while the robot drives on at 0.8 m/s.  After
    0.6 s without a fix the right one is 0.48 m from the previous: the frozen odometry makes it a jump,
    the fixes' own motion explains it."""
    frozen = _odom(1.0)
    for covered, follows in ((True, False), (False, True)):
        gate = JumpGate(IntegrityConfig(), room, MOUNT)
        _track(gate, room, np.arange(1.0, 1.41, DT), lambda t: frozen, covered)
        t = 2.0
        stale = _truth(1.4)  # a back-end without odometry: its prediction stays at the last fix
        v = gate.check(_fix(_truth(t), t), stale, PRED_COV, make_scan(room, _truth(t)), frozen, t,
                       motion_covered=covered)
        assert v.d2 > 50 and v.d2_previous is not None and v.covered is covered
        assert (v.d2_previous < 1.0) is follows, v.d2_previous  # measured 0.01 following the fixes, 46 frozen
        if follows:
            assert v.take and not v.confirmed


def test_late_odometry_does_not_explain_a_wrong_fix(room):
    """The odometry arrives 0.3 s late, carried on at its last speed while the robot has stopped: a fix
    0.24 m ahead (where the extrapolated odometry says) is not taken as explained by motion.  Taken as
    covering, the odometry would explain it from the previous fix; that counts only where the back-end's
    prediction left the previous fix further than the fix did, and here the prediction (the robot still)
    is the nearer."""
    stop = 1.0
    still = _truth(stop)
    wrong = still + np.array([0.0, 0.24, 0.0])
    for covered in (True, False):
        gate = JumpGate(IntegrityConfig(), room, MOUNT)
        _track(gate, room, np.arange(0.6, 1.01, DT), _odom, True)  # driving, the odometry in time
        for t in (1.08, 1.16, 1.24):  # stopped; the fixes say so, the late odometry is carried on
            v = gate.check(_fix(still, t), still, PRED_COV, make_scan(room, still), _odom(t), t,
                           motion_covered=covered)
            assert v.take
            gate.accepted()
        t = 1.32
        v = gate.check(_fix(wrong, t), still, PRED_COV, make_scan(room, still), _odom(t), t, motion_covered=covered)
        assert not v.take and "held back" in v.why and v.d2_previous is not None, v
        # measured 8.7 with the extrapolated odometry, 127 with the fixes' own motion
        assert (v.d2_previous > 13.82) is not covered, v.d2_previous


def test_odometry_that_resumes_counts_again(room):
    """After a stretch without odometry its motion counts again once it covers the time since the fix."""
    gate = JumpGate(IntegrityConfig(), room, MOUNT)
    _track(gate, room, np.arange(1.0, 1.41, DT), _odom, True)
    _track(gate, room, np.arange(1.48, 2.01, DT), lambda t: _odom(1.4), False)  # absent 0.6 s
    _track(gate, room, np.arange(2.08, 2.41, DT), _odom, True)                # resumed
    # a 0.3 m step sideways: the odometry (moving straight) does not explain it
    t = 2.48
    v = gate.check(_fix(_truth(t) + [0.3, 0.0, 0.0], t), _truth(t), PRED_COV, make_scan(room, _truth(t)), _odom(t), t)
    assert not v.take and v.covered and v.d2_previous is not None and v.d2_previous > 20
