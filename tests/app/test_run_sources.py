"""Which sources a run reads, and what its summary says of them.  A source of the default layout the
log has nothing for (no IMU at all on a wheels-only log) is one quiet line; a configured source that
stays silent, or a default topic the log has under other names, keeps its health line saying no
message came.  ``--odom-topic`` / ``--imu-topic`` with a config that lists its own sources (a
converted robot_localization file naming another robot's topics) point that config's input at the
named topic."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from fgloc.app.run import RunRequest, run_log
from fgloc.commands.run import run_summary_lines
from fgloc.testing import rosmsgs

T0 = 1_695_826_859_000_000_000
N = 100  # odometry messages, 20 Hz: 5 s driving 0.2 m/s along x


def _imu(types, ns: int):
    T = types
    V3, Q = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]
    cov = np.diag([1e-3, 1e-3, 1e-3]).ravel()
    return T["sensor_msgs/msg/Imu"](
        header=rosmsgs.header(T, ns, "imu_link"), orientation=Q(x=0.0, y=0.0, z=0.0, w=1.0),
        orientation_covariance=cov, angular_velocity=V3(x=0.0, y=0.0, z=0.0), angular_velocity_covariance=cov,
        linear_acceleration=V3(x=0.0, y=0.0, z=9.81), linear_acceleration_covariance=cov)


def _write(folder, imu_topics: tuple[str, ...] = ()) -> None:
    """A rosbag2 folder: /odom, and an IMU on each of ``imu_topics``."""
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    with Writer(folder, version=8) as w:
        co = w.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=ts)
        ci = [w.add_connection(t, "sensor_msgs/msg/Imu", typestore=ts) for t in imu_topics]
        for i in range(N):
            ns = T0 + i * 50_000_000
            msg = rosmsgs.odometry(ts.types, ns, 0.01 * i)
            w.write(co, ns, ts.serialize_cdr(msg, msg.__msgtype__))
            for c in ci:
                imu = _imu(ts.types, ns + 1000)
                w.write(c, ns + 1000, ts.serialize_cdr(imu, imu.__msgtype__))


def _summary(tmp_path, log, config=None, **kw) -> str:
    r = run_log(RunRequest(log=log, outdir=tmp_path / "out", config=config, view_channels=False, **kw))
    assert r.poses > 0
    return "\n".join(run_summary_lines(r))


def test_a_log_without_any_imu_says_so_in_one_quiet_line(tmp_path):
    _write(tmp_path / "log")
    said = _summary(tmp_path, tmp_path / "log")
    assert "\n  imu: no IMU in the log\n" in said, said
    assert "no message on the topic" not in said and "imu (imu /imu" not in said, said
    assert "  odom (odometry /odom: " in said, said  # the odometry's own line as before


def test_a_configured_imu_the_log_lacks_keeps_its_line(tmp_path):
    _write(tmp_path / "log")
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text("sources:\n  inputs:\n"
                   "    odom0: {type: odometry, topic: /odom, use: [vx, vyaw]}\n"
                   "    imu0: {type: imu, topic: /imu, use: [vyaw]}\n")
    said = _summary(tmp_path, tmp_path / "log", config=cfg)
    assert "imu0 (imu /imu: vyaw): 0 accepted, no message on the topic in the whole log" in said, said
    assert "no IMU in the log" not in said, said


def test_imus_under_other_names_keep_the_default_line(tmp_path):
    """Two IMU topics, neither /imu: which one is the robot's is the user's to name; not 'no IMU'."""
    _write(tmp_path / "log", ("/imu_a/data", "/imu_b/data"))
    said = _summary(tmp_path, tmp_path / "log")
    assert "imu (imu /imu: " in said and "no message on the topic in the whole log" in said, said
    assert "no IMU in the log" not in said, said


def _ported_config(path):
    """robot_localization's layout for another robot: its wheels on /odom_diff."""
    path.write_text("sources:\n  inputs:\n"
                    "    odom0: {type: odometry, topic: /odom_diff, use: [vx, vyaw]}\n"
                    "    imu0: {type: imu, topic: /imu, use: [vyaw]}\n")
    return path


def test_a_config_naming_another_robots_odometry_says_so(tmp_path):
    from fgloc.errors import LogError

    _write(tmp_path / "log", ("/imu",))
    with pytest.raises(LogError) as e:
        _summary(tmp_path, tmp_path / "log", config=_ported_config(tmp_path / "cfg.yaml"))
    assert "no odometry (the config's odometry source reads /odom_diff, not in the log)" in str(e.value), e.value
    assert "--odom-topic" in str(e.value)


@pytest.mark.parametrize("backend", ["ekf", "smoother"])
def test_odom_topic_points_the_configs_odometry_at_the_logs(tmp_path, caplog, backend):
    """It was ignored: the run read the config's /odom_diff, estimated no pose and exited 3."""
    _write(tmp_path / "log", ("/imu",))
    with caplog.at_level(logging.WARNING):
        r = run_log(RunRequest(log=tmp_path / "log", outdir=tmp_path / "out", backend=backend,
                               config=_ported_config(tmp_path / "cfg.yaml"), odom_topic="/odom", view_channels=False))
    assert "--odom-topic /odom: sources.inputs.odom0 reads it (the config names /odom_diff)" in caplog.text
    assert r.stats.sources["odom0"].topic == "/odom" and r.stats.sources["odom0"].accepted == N
    assert r.stats.sources["imu0"].accepted == N
    tr = np.loadtxt(tmp_path / "out" / "trajectory.tum")
    assert len(tr) > 5 and tr[-1, 0] - tr[0, 0] > 3.5
    # 0.2 m/s along x, as the wheels on /odom say
    assert tr[:, 1] - tr[0, 1] == pytest.approx(0.2 * (tr[:, 0] - tr[0, 0]), abs=0.01)
    assert np.abs(tr[:, 2]).max() < 0.01


def test_a_named_topic_with_no_or_several_configured_inputs_of_its_type_is_an_error(tmp_path):
    from fgloc.errors import ConfigError

    _write(tmp_path / "log", ("/imu",))
    imu_only = tmp_path / "imu.yaml"
    imu_only.write_text("sources:\n  inputs:\n    imu0: {type: imu, topic: /imu, use: [vyaw]}\n")
    with pytest.raises(ConfigError) as e:
        _summary(tmp_path, tmp_path / "log", config=imu_only, odom_topic="/odom")
    assert str(e.value) == ("--odom-topic /odom: the config's sources.inputs list no odometry source: add one, "
                            "sources.inputs.NAME: {type: odometry, topic: /odom}")
    two = tmp_path / "two.yaml"
    two.write_text("sources:\n  inputs:\n    odom0: {type: odometry, topic: /a, use: [vx]}\n"
                   "    odom1: {type: odometry, topic: /b, use: [vyaw]}\n")
    with pytest.raises(ConfigError) as e:
        _summary(tmp_path, tmp_path / "log", config=two, odom_topic="/odom")
    assert "2 odometry sources (odom0, odom1): set the one to read in sources.inputs.NAME.topic" in str(e.value)


def test_no_imu_named_leaves_the_configs_imu_out(tmp_path, caplog):
    """--imu-topic "" ("none") was ignored with a config that lists an IMU: the run read it anyway."""
    from fgloc.errors import ConfigError

    _write(tmp_path / "log", ("/imu",))
    with caplog.at_level(logging.WARNING):
        r = run_log(RunRequest(log=tmp_path / "log", outdir=tmp_path / "out", odom_topic="/odom", imu_topic="",
                               config=_ported_config(tmp_path / "c.yaml"), view_channels=False))
    assert '--imu-topic "": sources.inputs.imu0 (/imu) is not read' in caplog.text
    assert set(r.stats.sources) == {"odom0"} and r.stats.sources["odom0"].accepted == N
    imu_only = tmp_path / "imu.yaml"
    imu_only.write_text("sources:\n  inputs:\n    imu0: {type: imu, topic: /imu, use: [vyaw]}\n")
    with pytest.raises(ConfigError) as e:
        _summary(tmp_path, tmp_path / "log", config=imu_only, imu_topic="")
    assert str(e.value) == '--imu-topic "": the config\'s sources.inputs list nothing else to localize with'
