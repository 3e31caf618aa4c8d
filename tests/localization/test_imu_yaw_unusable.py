"""An IMU yaw whose variance says it is not estimated (an xsens on robot_localization's groovy test1 claims
10 rad^2) is no heading: taken as one, a hundred readings a second of it add up to a confident
heading, and a yaw that runs against the turn pulls the fused heading off the sources that are
right.  A written log (MCAP: wheel odometry's speed, two differential IMU yaws: an honest one and
one claiming sigma 181 deg that turns the wrong way and drifts) through ``fgloc run``'s path."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from fgloc.app.run import RunRequest, run_log
from fgloc.io.mcap_writer import LogWriter
from fgloc.io.tum import read_tum
from fgloc.localization.sources.imu import yaw_usable
from fgloc.types import Imu, Odometry

RATE_HZ = 100
ODOM_HZ = 10
DURATION_S = 55.0
SPEED_MPS = 1.0


def _yaw(t: float) -> float:
    """The robot's heading: straight, a 90 deg turn every 15 s (5 s at 0.314 rad/s)."""
    turns, rest = divmod(t, 15.0)
    return turns * math.pi / 2 + (0.0 if rest < 10.0 else (rest - 10.0) * math.pi / 10.0)


def _write(path: Path) -> Path:
    rng = np.random.default_rng(3)
    with LogWriter(path) as w:
        x = y = 0.0
        for i in range(int(DURATION_S * RATE_HZ) + 1):
            t = i / RATE_HZ
            th = _yaw(t)
            if i % (RATE_HZ // ODOM_HZ) == 0:
                w.write("/odom", Odometry(100.0 + t, np.array([SPEED_MPS, 0.0, 0.0]), np.diag([1e-4, 1e-4, 1e6]),
                                          np.array([x, y, th]), None, "odom", "base_link"))
                w_true = (_yaw(t + 0.05) - _yaw(t - 0.05)) / 0.1
                w.write("/vo", Odometry(100.0 + t, np.array([SPEED_MPS, 0.0, w_true + float(rng.normal(0.0, 0.02))]),
                                        np.diag([1e-2, 1e-2, 1e-2]), None, None, "odom", "base_link"))
            x += SPEED_MPS * math.cos(th) / RATE_HZ
            y += SPEED_MPS * math.sin(th) / RATE_HZ
            good = th + float(rng.normal(0.0, math.radians(0.2)))
            bad = -0.7 * th + 0.02 * t   # the wrong way round, and drifting
            for topic, yaw, var in (("/imu_good", good, math.radians(0.5) ** 2), ("/ahrs", bad, 10.0)):
                q = Rotation.from_euler("z", yaw).as_quat()
                w.write(topic, Imu(100.0 + t + 0.003, q, None, np.diag([1e-3, 1e-3, var]), None, frame_id="base_link"))
    return path


SOURCES = {"inputs": {
    "odom0": {"type": "odometry", "topic": "/odom", "use": ["vx"]},
    "odom1": {"type": "odometry", "topic": "/vo", "use": ["vx", "vy", "vyaw"]},
    "imu0": {"type": "imu", "topic": "/ahrs", "use": ["yaw"], "differential": True},
    "imu1": {"type": "imu", "topic": "/imu_good", "use": ["yaw"], "differential": True},
}}


@pytest.fixture(scope="module")
def log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _write(tmp_path_factory.mktemp("ahrs") / "ahrs.mcap")


@pytest.mark.parametrize("backend", ["ekf", "smoother"])
def test_a_yaw_claiming_no_heading_is_not_one(log: Path, tmp_path: Path, backend: str) -> None:
    cfg = tmp_path / "c.yaml"
    cfg.write_text(yaml.safe_dump({"sources": SOURCES}))
    r = run_log(RunRequest(log=log, outdir=tmp_path / "o", backend=backend, config=cfg, force=True,
                           view_channels=False))
    tum = read_tum(tmp_path / "o" / "trajectory.tum")
    t_end, yaw_end = float(tum.stamps[-1]) - 100.0, float(tum.poses[-1][2])
    # 4 turns, the last 10 s straight: the honest source's heading (either way: the AHRS's weight is small
    # here; on r_l's groovy test1 its 13334 readings pulled the EKF's heading 1-3 deg, 2.3 m at the end)
    assert abs(math.remainder(yaw_end - _yaw(t_end), math.tau)) < math.radians(1.0)
    rep = r.stats.sources["imu0"]
    assert rep.yaw_unusable == int(DURATION_S * RATE_HZ) + 1 and rep.accepted == 0
    assert r.stats.sources["imu1"].yaw_unusable == 0


def test_which_yaw_variances_carry_a_heading() -> None:
    assert yaw_usable(math.nan) and yaw_usable(0.0) and yaw_usable(1e-4) and yaw_usable((math.pi / 2) ** 2)
    assert not yaw_usable(10.0) and not yaw_usable(1e6) and not yaw_usable(math.inf)
