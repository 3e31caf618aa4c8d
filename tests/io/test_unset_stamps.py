"""A driver that leaves header stamps unset (0) puts its topic on "another clock" than the
others: run and map refuse it in one line, which now says the stamps are 0 (before: only that
they differ by 1.7e9 s).  The log is written here."""

from __future__ import annotations

import numpy as np
import pytest

from fgloc.cli import main
from fgloc.io.mcap_writer import LogWriter
from fgloc.types import LaserScan, Odometry

T0 = 1_552_909_053.0


@pytest.mark.parametrize("command", ["run", "map"])
def test_unset_odometry_stamps_are_named(tmp_path, capsys, command):
    log = tmp_path / "unset.mcap"
    with LogWriter(log) as w:
        for i in range(20):
            t = T0 + 0.1 * i
            w.write("/odom", Odometry(stamp=0.0, twist=np.zeros(3), pose=np.zeros(3)), log_time_ns=int(t * 1e9))
            w.write("/scan", LaserScan(stamp=t, angle_min=-1.0, angle_increment=0.01, range_min=0.1, range_max=10.0,
                                       ranges=np.full(201, 2.0, np.float32), frame_id="laser"))
    extra = ["-q"] if command == "run" else ["--no-progress"]
    capsys.readouterr()
    assert main([command, str(log), "-o", str(tmp_path / "out"), *extra]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"fgloc: error: {log}: /scan and /odom are stamped by different clocks")
    assert err[0].endswith("(the first /odom header stamp is 0: does its driver leave the stamps unset?)"), err
