"""``fgloc map --config`` takes the file ``fgloc run --config`` reads: its ``sources.static_transforms``
mount the scans (under ``--static-transform`` of the same frame) and
the mapper keeps its own options; it was refused ("unknown mapping option 'sources'")."""

from __future__ import annotations

import numpy as np

from fgloc.testing.cli import run_cli


def _short_log(tmp_path):
    """A simulated log along three corners (odometry on /odom, scans, no config)."""
    scen = tmp_path / "short.yaml"
    scen.write_text("route: [[3.0, 3.0], [8.0, 3.0], [8.0, 6.0]]\n")
    rc, _out, err = run_cli("simulate", "scenario", scen, "-o", tmp_path / "sim", "--seed", "2")
    assert rc == 0, err
    return tmp_path / "sim" / "log.mcap"


def test_a_run_config_mounts_the_laser_for_the_mapper(tmp_path):
    log = _short_log(tmp_path)
    run_cfg = tmp_path / "robot.yaml"
    run_cfg.write_text("sources:\n  static_transforms:\n"
                       "    - {parent: base_link, child: laser, xyz: [0.5, 0.0, 0.2], rpy_deg: [0, 0, 10]}\n"
                       "pipeline: {}\n")

    def mapped(name, *extra):
        rc, _out, err = run_cli("map", log, "-o", tmp_path / name, "-q", "--no-check", *extra)
        assert rc == 0, err
        return np.loadtxt(tmp_path / name / "trajectory.tum")

    with_cfg = mapped("cfg", "--config", run_cfg)
    with_cli = mapped("cli", "--static-transform", "base_link", "laser", "0.5", "0", "0.2", "0", "0", "10")
    plain = mapped("plain")
    assert np.array_equal(with_cfg, with_cli)
    assert np.abs(with_cfg[:, 1:3] - plain[:, 1:3]).max() > 0.05  # the config's mount, not the log's
    # the command line's mount of the same frame wins over the config's
    both = mapped("both", "--config", run_cfg, "--static-transform", "base_link", "laser", "0.5", "0", "0.2",
                  "0", "0", "10")
    assert np.array_equal(both, with_cli)


def test_a_run_configs_odometry_source_is_the_mappers(tmp_path):
    """A run config whose one odometry source reads another topic than /odom: fgloc map read /odom
    regardless (fgloc run reads the config's); now the config's, said, unless --odom-topic names one."""
    log = _short_log(tmp_path)
    cfg = tmp_path / "robot.yaml"
    cfg.write_text("sources:\n  inputs:\n    wheels: {type: odometry, topic: /wheels/odom, use: [vx, vyaw]}\n")
    rc, _out, err = run_cli("map", log, "-o", tmp_path / "a", "-q", "--no-check", "--config", cfg)
    assert rc == 2 and "the odometry of sources.inputs.wheels, /wheels/odom (as fgloc run reads it)" in err, err
    assert "no odometry on /wheels/odom" in err, err
    rc, _out, err = run_cli("map", log, "-o", tmp_path / "b", "-q", "--no-check", "--config", cfg,
                            "--odom-topic", "/odom")
    assert rc == 0 and "sources.inputs" not in err, err
    rc, _out, err = run_cli("map", log, "-o", tmp_path / "c", "-q", "--no-check")
    assert rc == 0, err
    assert np.array_equal(np.loadtxt(tmp_path / "b" / "trajectory.tum"), np.loadtxt(tmp_path / "c" / "trajectory.tum"))
