"""The default layout (no config) levels the wheel odometry by the IMU's roll / pitch: a robot
climbing a ramp travels ``v cos(pitch)`` horizontally.  A written log (MCAP: /odom, /imu) run
through ``fgloc run``'s path with each back-end: the final horizontal position against the truth,
levelled and not; a tilt no ground robot drives on and a roll / pitch variance that says "not
estimated" are not used, and counted."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from fgloc.app.run import RunRequest, run_log
from fgloc.frames.imu import imu_in_base
from fgloc.io.mcap_writer import LogWriter
from fgloc.io.tum import read_tum
from fgloc.localization.sources import parse_sources
from fgloc.localization.sources.imu import tilt_usable
from fgloc.types import Imu, Odometry

SPEED_MPS = 1.0
RATE_HZ = 20
#: 2 s level, 6 s up the ramp, 2 s level: (start s, end s) of the ramp
RAMP_S = (2.0, 8.0)
DURATION_S = 10.0


def _pitch(t: float, ramp_deg: float) -> float:
    """The base's pitch (rad, ZYX; nose up is negative about y) at ``t`` s into the drive."""
    return -math.radians(ramp_deg) if RAMP_S[0] <= t < RAMP_S[1] else 0.0


def _truth_x_m(ramp_deg: float, end_s: float) -> float:
    """The horizontal distance driven at SPEED_MPS along the wheels by ``end_s``."""
    on_ramp = max(0.0, min(end_s, RAMP_S[1]) - RAMP_S[0])
    return SPEED_MPS * ((end_s - on_ramp) + on_ramp * math.cos(math.radians(ramp_deg)))


def _write(path: Path, ramp_deg: float, tilt_var: float = 1e-4) -> Path:
    """A straight drive along x over a ramp: wheel odometry (its speed along the base's x) and an
    IMU in base_link reporting the base's attitude (roll / pitch variance ``tilt_var``)."""
    with LogWriter(path) as w:
        n = int(DURATION_S * RATE_HZ) + 1
        for i in range(n):
            t = 100.0 + i / RATE_HZ
            w.write("/odom", Odometry(t, np.array([SPEED_MPS, 0.0, 0.0]), np.diag([1e-4, 1e-4, 1e-4]), None, None,
                                      "odom", "base_link"))
            q = Rotation.from_euler("ZYX", [0.0, _pitch(i / RATE_HZ + 0.005, ramp_deg), 0.0]).as_quat()
            w.write("/imu", Imu(t + 0.005, q, np.zeros(3), np.diag([tilt_var, tilt_var, 1e-4]),
                                np.diag([1e-6] * 3), frame_id="base_link"))
    return path


def _run(log: Path, out: Path, backend: str, sources: dict | None = None) -> tuple[float, float, float, object]:
    """(final x m, its error m against the truth at the last pose's stamp, final |y| m, the run's result)."""
    cfg = None
    if sources is not None:
        cfg = out.with_suffix(".yaml")
        cfg.write_text(yaml.safe_dump({"sources": sources}))
    r = run_log(RunRequest(log=log, outdir=out, backend=backend, config=cfg, force=True, view_channels=False))
    tum = read_tum(out / "trajectory.tum")
    t0, t_end = float(tum.stamps[0]) - 100.0, float(tum.stamps[-1]) - 100.0
    x = float(tum.poses[-1, 0]) - float(tum.poses[0, 0])
    return x, abs(x - (_truth_x_m(12.0, t_end) - _truth_x_m(12.0, t0))), abs(float(tum.poses[-1, 1])), r


@pytest.fixture(scope="module")
def ramp_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _write(tmp_path_factory.mktemp("ramp") / "ramp.mcap", 12.0)


@pytest.mark.parametrize("backend", ["ekf", "smoother"])
def test_the_default_layout_levels_the_odometry_on_a_ramp(ramp_log: Path, tmp_path: Path, backend: str) -> None:
    # 6 m up a 12 deg ramp: 6 (1 - cos 12 deg) = 0.131 m less horizontal travel than the wheels say
    x_level, err_level, y_level, r = _run(ramp_log, tmp_path / "level", backend)
    x_flat, err_flat, _, r_flat = _run(ramp_log, tmp_path / "flat", backend, {"level_by_imu": False})
    shorter = 6.0 * (1.0 - math.cos(math.radians(12.0)))
    assert x_flat - x_level == pytest.approx(shorter, abs=0.002)
    # (the EKF's final x lags the truth by its first odometry interval, 0.033 m, levelled or not)
    assert err_level < 0.04 and y_level < 0.01 and err_flat > 0.09
    rep = r.stats.sources["odom"]
    assert rep.levelled >= 0.99 * rep.accepted and rep.tilt_max_deg == pytest.approx(12.0, abs=1e-6)
    assert r_flat.stats.sources["odom"].levelled == 0


def test_tilts_no_ground_robot_has_and_unestimated_ones_are_not_used(tmp_path: Path) -> None:
    # a 40 deg "ramp" (a mis-mounted IMU): the odometry is not levelled, each message counted
    steep = _write(tmp_path / "steep.mcap", 40.0)
    r = run_log(RunRequest(log=steep, outdir=tmp_path / "s", backend="ekf", force=True, view_channels=False))
    rep = r.stats.sources["odom"]
    on_ramp = int((RAMP_S[1] - RAMP_S[0]) * RATE_HZ)
    # (the first odometry message precedes the first IMU reading: nothing to level it by)
    assert abs(rep.tilt_implausible - on_ramp) <= 2 and rep.levelled + rep.tilt_implausible == rep.accepted - 1
    # a roll / pitch variance of 1e6 (a driver's "not estimated"): not used, counted on the IMU
    vague = _write(tmp_path / "vague.mcap", 12.0, tilt_var=1e6)
    r = run_log(RunRequest(log=vague, outdir=tmp_path / "v", backend="ekf", force=True, view_channels=False))
    assert r.stats.sources["odom"].levelled == 0
    assert r.stats.sources["imu"].tilt_unusable == int(DURATION_S * RATE_HZ) + 1


def tilt_estimated(cov: np.ndarray | None, R_bi: list[float]) -> bool:
    """The handler's verdict on a level reading's orientation covariance through the mount ``R_bi``."""
    base, problems = imu_in_base(Imu(0.0, np.array([0.0, 0.0, 0.0, 1.0]), None, cov, None, frame_id="imu"), R_bi)
    assert not problems and base.roll_pitch_rad is not None
    return tilt_usable(base.roll_pitch_var)


def test_which_covariances_carry_a_tilt() -> None:
    eye = np.eye(3).ravel().tolist()
    assert tilt_estimated(None, eye) and tilt_estimated(np.zeros((3, 3)), eye)  # REP 145 "unknown": used
    assert tilt_estimated(np.diag([0.1, 0.1, 1e6]), eye)  # only the yaw not estimated
    assert not tilt_estimated(np.diag([1e6, 1e6, 1e-3]), eye)
    # an IMU turned 90 deg about x: its z variance is the base's pitch variance
    rx = Rotation.from_euler("x", 90, degrees=True).as_matrix().ravel().tolist()
    assert not tilt_estimated(np.diag([1e-3, 1e-3, 1e6]), rx) and tilt_estimated(np.diag([1e-3, 1e6, 1e-3]), rx)
    # the key: the default layout's IMU levels unless switched off; listed inputs say it in `use`
    from fgloc.localization.sources import SourcesConfig

    assert parse_sources(None)[1].use == ("yaw", "vyaw", "roll", "pitch")
    assert parse_sources(SourcesConfig(level_by_imu=False))[1].use == ("yaw", "vyaw")
    assert parse_sources({"imu0": {"type": "imu"}})[0].use == ("yaw", "vyaw")
