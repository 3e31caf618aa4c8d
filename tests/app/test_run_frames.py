"""fgloc run with a mount the log lacks (--static-transform / sources.static_transforms), no scans."""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from fgloc.app.run import RunRequest, run_log
from fgloc.frames.static import static_transform_entry
from fgloc.io.mcap_writer import LogWriter
from fgloc.io.tum import read_tum
from fgloc.types import CompassHeading, Odometry

HEADING = 0.5  # rad: the base's true heading; the IMU is yawed -90 deg on it


@pytest.fixture(scope="module")
def log_and_config(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    d = tmp_path_factory.mktemp("mount")
    with LogWriter(d / "log.mcap") as w:
        for i in range(201):  # 10 s at 20 Hz, 1 m/s straight ahead
            t = 100.0 + 0.05 * i
            w.write("/wheels/odom", Odometry(t, np.array([1.0, 0.0, 0.0]), np.diag([1e-3, 1e-3, 1e-3]),
                                             np.array([0.05 * i, 0.0, 0.0]), np.diag([1e-3, 1e-3, 1e-3])))
            # the IMU's x axis is the base's -y axis: it reads the base's heading - 90 deg
            w.write("/imu/data", CompassHeading(t + 0.01, HEADING - math.pi / 2, 0.0, 1e-4, 1e-4,
                                                frame_id="imu_link"))
    cfg = d / "fgloc.yaml"
    cfg.write_text(yaml.safe_dump({"sources": {"inputs": {
        "odom0": {"type": "odometry", "topic": "/wheels/odom", "use": ["vx", "vy"]},
        "imu0": {"type": "imu", "topic": "/imu/data", "use": ["yaw"]}}}}))
    return d / "log.mcap", cfg


@pytest.mark.parametrize("backend", ["ekf", "smoother"])
def test_static_transform_turns_the_imu_into_base_link(log_and_config: tuple[Path, Path], tmp_path: Path,
                                                        backend: str, caplog: pytest.LogCaptureFixture) -> None:
    log, cfg = log_and_config
    finals = {}
    for name, tfs in (("without", []), ("with", [static_transform_entry("base_link", "imu_link", 0, 0, 0, 0, 0, -90)])):
        with caplog.at_level(logging.WARNING):
            # no --odom-topic / --imu-topic: the config's sources name the topics
            r = run_log(RunRequest(log=log, outdir=tmp_path / name, backend=backend, config=cfg, force=True,
                                   view_channels=False, static_transforms=tfs))
        assert r.stats.sources["odom0"].accepted == 201
        assert r.stats.sources["imu0"].accepted == 201
        # odom0 does not fuse its yaw: no noise figure for it in the health (and no 'noise_noise_' key)
        assert not r.stats.sources["odom0"].noise, r.stats.sources["odom0"]
        finals[name] = read_tum(tmp_path / name / "trajectory.tum").poses[-1]
    # 10 m along the base's heading, read through the mount; without it, along the IMU's x axis
    x, y = finals["with"][:2]
    assert math.atan2(y, x) == pytest.approx(HEADING, abs=0.01) and 9.5 < math.hypot(x, y) <= 10.01
    assert finals["with"][2] == pytest.approx(HEADING, abs=0.01)
    assert finals["without"][2] == pytest.approx(HEADING - math.pi / 2, abs=0.01)
    # no scans: no 'no transform base_link -> laser' warning; the IMU frame was given
    assert [r.getMessage() for r in caplog.records if "no transform" in r.getMessage()] == [  # 'without' only
        "no transform chain base_link -> imu_link (no transform names it); the IMU is used unmounted (as if its "
        "axes were the base's): set sources.base_frame or give the mount (sources.static_transforms, "
        "--static-transform)"], caplog.text
    assert yaml.safe_load((tmp_path / "with" / "config.yaml").read_text())["sources"]["static_transforms"] == tfs


def test_no_default_topics_and_several_of_a_type_names_the_options(tmp_path: Path) -> None:
    """A log with two odometries and two IMUs, none by the default names (r_l's groovy test1): no
    config picks one; the error names the options and the topics to give them."""
    from fgloc.errors import LogError

    log = tmp_path / "two_of_each.mcap"
    with LogWriter(log) as w:
        for i in range(20):
            t = 100.0 + 0.05 * i
            for topic in ("/wheel_odometry", "/stereo/odometry"):
                w.write(topic, Odometry(t, np.array([1.0, 0.0, 0.0]), np.diag([1e-3] * 3),
                                        np.array([0.05 * i, 0.0, 0.0]), np.diag([1e-3] * 3)))
            for topic in ("/xsens/imu_data", "/ref/imu_data"):
                w.write(topic, CompassHeading(t, 0.0, 0.0, 1e-4, 1e-4, frame_id="imu_link"))
    with pytest.raises(LogError) as e:
        run_log(RunRequest(log=log, outdir=tmp_path / "out", force=True, view_channels=False))
    msg = str(e.value)
    assert "\n" not in msg
    assert "--odom-topic /stereo/odometry | /wheel_odometry" in msg, msg
    assert "--imu-topic /ref/imu_data | /xsens/imu_data" in msg and "--scan-topic" not in msg, msg
    assert not (tmp_path / "out").exists()
