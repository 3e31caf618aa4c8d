"""The wheels' yaw-rate scale (reported / true) is learnt beside whichever source measures the heading,
not only beside a gyro: a compass's (or an IMU's) absolute yaw, or a differential orientation's
increments.  A skid steer's wheels report twice the turn; unlearnt, each turn's extra wheel yaw
throws the online heading off until the heading source pulls it back."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import drive_skid_turns

from fgloc.backends.ekf_backend import EKFBackend

SCRUB = 2.0                  # the wheels report twice the turn
YAW_SIGMA = math.radians(0.5)
AHRS_OFFSET = 1.3            # a differential orientation's frame, its own


def _drive(backend, heading: str) -> tuple[float, float]:
    """The four turns with odometry at 50 Hz (scrubbed yaw rate), the heading source at 100 Hz, a
    keyframe at 25 Hz; returns the largest online heading error (deg) over the last three turns and
    the scale learnt."""
    rng = np.random.default_rng(2)
    backend.initialize(0.0, np.zeros(3), np.diag([1e-4, 1e-4, 1e-4]))
    if heading == "absolute":
        backend.set_compass_offset(0.0)   # an odometry-frame run: the compass's frame is the frame

    def feed(t: float, th: float) -> None:
        z = th + float(rng.normal(0.0, YAW_SIGMA))
        if heading == "absolute":
            backend.add_compass(t, z, YAW_SIGMA**2, None, 0.0)
        else:
            backend.add_relative_yaw(t, z + AHRS_OFFSET, YAW_SIGMA**2, "ahrs")

    worst, _ = drive_skid_turns(backend, feed, SCRUB, 0.5, rng)
    backend.finish()
    return worst, float(backend.odom_scales()[1])


@pytest.mark.parametrize("heading", ["absolute", "differential"])
def test_the_ekfs_wheel_yaw_rate_scale_is_learnt_beside_a_heading_source(heading: str) -> None:
    # before (the scale a state only beside a gyro): 17.7 deg (absolute) and 90 deg (differential) off
    worst_deg, scale = _drive(EKFBackend(), heading)
    assert scale == pytest.approx(SCRUB, rel=0.1), scale
    assert worst_deg < 2.0, worst_deg
