"""Two topics of one log stamped on two clocks (a Gazebo /ground_truth on the simulator's clock, a
student's EKF output on the wall clock; both recorded on the recorder's): `fgloc eval LOG:/ekf
LOG:/ground_truth` said only that they do not overlap in time.  The log times put them on one
clock: the error now gives the --t-offset that does, and that offset pairs them."""

from __future__ import annotations

import json

import numpy as np

from fgloc.cli import main
from fgloc.io.mcap_writer import LogWriter
from fgloc.types import Odometry

SIM0 = 7844.0  # the simulator's clock at the first message, s
WALL0 = 1_732_210_209.5  # the wall clock (and the recorder's) at the first message, s
N = 100  # 20 Hz, 5 s driving 0.2 m/s along x


def _write(path) -> None:
    with LogWriter(path) as w:
        for i in range(N):
            dt = 0.05 * i
            pose = np.array([0.2 * dt, 0.0, 0.0])
            log_ns = round((WALL0 + dt + 0.002) * 1e9)  # received 2 ms after the wall-clock stamp
            for topic, stamp in (("/ground_truth", SIM0 + dt), ("/ekf", WALL0 + dt)):
                w.write(topic, Odometry(stamp, np.array([0.2, 0.0, 0.0]), np.eye(3) * 1e-4, pose.copy(),
                                        np.eye(3) * 1e-4), log_time_ns=log_ns)


def test_two_clocks_in_one_log_get_the_offset_that_pairs_them(tmp_path, capsys):
    log = tmp_path / "two_clocks.mcap"
    _write(log)
    assert main(["eval", f"{log}:/ekf", f"{log}:/ground_truth", "--align-start"]) == 2
    err = capsys.readouterr().err
    shift = SIM0 - WALL0
    assert "do not overlap in time; their log times put them on one clock: --t-offset " in err, err
    given = float(err.split("--t-offset ")[1].split()[0])
    assert abs(given - shift) < 1e-3, (given, shift)
    assert main(["eval", f"{log}:/ekf", f"{log}:/ground_truth", "--align-start", "--t-offset", f"{given:.3f}",
                 "--json"]) == 0
    m = json.loads(capsys.readouterr().out)["metrics"]
    assert m["n"] >= N - 2 and m["position_rmse_m"] < 1e-3


def test_no_note_when_the_log_times_do_not_bring_them_together(tmp_path, capsys):
    """A TUM estimate has no log times: the error stays as it was."""
    log = tmp_path / "two_clocks.mcap"
    _write(log)
    tum = tmp_path / "est.tum"
    tum.write_text("".join(f"{WALL0 + 0.05 * i:.6f} {0.01 * i} 0 0 0 0 0 1\n" for i in range(N)))
    assert main(["eval", str(tum), f"{log}:/ground_truth"]) == 2
    err = capsys.readouterr().err
    assert "do not overlap in time" in err and "--t-offset" not in err, err
