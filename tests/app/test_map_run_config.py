"""``fgloc map --config`` takes the file ``fgloc run --config`` reads: its ``sources.static_transforms``
mount the scans (under ``--static-transform`` of the same frame) and
the mapper keeps its own options; it was refused ("unknown mapping option 'sources'")."""

from __future__ import annotations

import numpy as np

from fgloc.testing.cli import run_cli


def test_a_run_config_mounts_the_laser_for_the_mapper(tmp_path):
    scen = tmp_path / "short.yaml"
    scen.write_text("route: [[3.0, 3.0], [8.0, 3.0], [8.0, 6.0]]\n")
    rc, _out, err = run_cli("simulate", "scenario", scen, "-o", tmp_path / "sim", "--seed", "2")
    assert rc == 0, err
    log = tmp_path / "sim" / "log.mcap"
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
