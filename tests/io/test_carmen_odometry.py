"""CARMEN odometry: ODOM lines when their stamps are regular, the laser lines' carried poses when
the ODOM stamps come in bursts (the stamps then say when a line was written, not measured)."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from fgloc.geometry import between
from fgloc.io import open_log
from fgloc.io.carmen import BURST_REGULAR, CARRIED_LEAD_S, CarmenReader, stamp_spacing
from fgloc.localization.clock import REGULAR
from fgloc.types import LaserScan, Odometry

T0 = 1000.0
N_SCANS = 40           # 10 Hz, 4 s
SPEED = 0.5            # m/s along x
RANGES = " ".join(["5.0"] * 180)


def _carried(k: int) -> tuple[float, float, float]:
    """The odometry pose the k-th laser line carries (true pose at its stamp)."""
    return SPEED * 0.1 * k, 0.0, 0.01 * k


def _flaser(k: int, posed: bool = True) -> tuple[float, str]:
    t = T0 + 0.1 * k
    x, y, th = _carried(k)
    pose = f"{x:.6f} {y:.6f} {th:.6f} {x:.6f} {y:.6f} {th:.6f} " if posed else ""
    return t, f"FLASER 180 {RANGES} {pose}{t:.6f} host {t:.6f}"


def _odom(t_meas: float, t_stamp: float) -> tuple[float, str]:
    x = SPEED * (t_meas - T0)
    return t_stamp, f"ODOM {x:.6f} 0.000000 0.000000 {SPEED} 0.0 0.0 {t_stamp:.6f} host {t_stamp:.6f}"


def _regular_odom() -> list[tuple[float, str]]:
    """One ODOM line 50 ms after each scan, stamped when measured."""
    return [_odom(T0 + 0.1 * k + 0.05, T0 + 0.1 * k + 0.05) for k in range(N_SCANS)]


def _bursty_odom() -> list[tuple[float, str]]:
    """Every 0.4 s the last four 0.1 s measurements written within 1.5 ms (intel's kind of logger)."""
    out = []
    for m in range(1, N_SCANS // 4 + 1):
        for i in range(4):
            t_meas = T0 + 0.4 * (m - 1) + 0.1 * i + 0.05
            out.append(_odom(t_meas, T0 + 0.4 * m + 0.0005 * i))
    return out


def _write(tmp_path, odom: list[tuple[float, str]], posed: bool = True):
    lines = sorted([_flaser(k, posed) for k in range(N_SCANS)] + odom, key=lambda tl: tl[0])
    path = tmp_path / "log.clf"
    path.write_text("\n".join(line for _, line in lines) + "\n")
    return path


def test_burst_threshold_is_the_clocks():
    assert BURST_REGULAR == REGULAR == 0.5


def test_stamp_spacing_keeps_increasing_stamps():
    assert stamp_spacing([1.0, 2.0]) is None                     # fewer than 3 stamps
    med, mean = stamp_spacing([0.0, 0.001, 0.002, 0.5, 0.501, 0.502, 1.0])  # type: ignore[misc]
    assert med == pytest.approx(0.001) and mean == pytest.approx(1.0 / 6)
    med, mean = stamp_spacing([0.0, 0.1, 0.05, 0.2, 0.3])  # type: ignore[misc]  # 0.05 goes back: left out
    assert med == pytest.approx(0.1) and mean == pytest.approx(0.1)


def test_regular_odom_lines_are_the_odometry(tmp_path, caplog):
    path = _write(tmp_path, _regular_odom())
    with caplog.at_level(logging.WARNING, logger="fgloc.io.carmen"):
        reader = CarmenReader(path)
        msgs = list(reader)
    odom = [m for t, m in msgs if t == "/odom"]
    assert len(odom) == N_SCANS
    assert [o.stamp for o in odom] == pytest.approx([T0 + 0.1 * k + 0.05 for k in range(N_SCANS)])
    assert odom[3].pose == pytest.approx([SPEED * 0.35, 0.0, 0.0])   # the ODOM line's pose
    assert odom[3].twist == pytest.approx([SPEED, 0.0, 0.0])
    assert reader.stats["odom_from_laser"] is False and "odom_bursts" not in reader.stats
    assert "bursts" not in caplog.text


def test_bursty_odom_gives_the_laser_lines_poses(tmp_path, caplog):
    path = _write(tmp_path, _bursty_odom())
    with caplog.at_level(logging.WARNING, logger="fgloc.io.carmen"):
        reader = CarmenReader(path)
        msgs = list(reader)
    odom = [m for t, m in msgs if t == "/odom"]
    scans = [m for t, m in msgs if t == "/scan"]
    assert len(odom) == len(scans) == N_SCANS and reader.stats["counts"]["ODOM"] == N_SCANS  # read, not used
    assert all(isinstance(o, Odometry) for o in odom) and all(isinstance(s, LaserScan) for s in scans)
    for k, (o, s) in enumerate(zip(odom, scans, strict=True)):
        assert o.pose == pytest.approx(_carried(k), abs=1e-9)
        assert o.stamp == pytest.approx(s.stamp - CARRIED_LEAD_S, abs=1e-9)
    # each odometry message comes just before its scan
    topics = [t for t, _ in msgs[1:]]
    assert topics[:4] == ["/odom", "/scan", "/odom", "/scan"]
    # finite difference of the poses, in the robot frame: 0.5 m/s, 0.1 rad/s
    assert odom[5].twist == pytest.approx(between(np.array(_carried(4)), np.array(_carried(5))) / 0.1, abs=1e-6)
    assert odom[5].twist[[0, 2]] == pytest.approx([SPEED, 0.1], abs=1e-3)
    # 4 ODOM lines 0.5 ms apart every 0.4 s: median 0.5 ms, mean 3.6015 s / 39
    b = reader.stats["odom_bursts"]
    assert b["median_spacing_s"] == pytest.approx(0.0005, abs=1e-6)
    assert b["mean_spacing_s"] == pytest.approx(3.6015 / 39, abs=1e-6)
    assert reader.stats["odom_from_laser"] is True
    warned = [r.getMessage() for r in caplog.records if "bursts" in r.getMessage()]
    assert len(warned) == 1 and "\n" not in warned[0]
    assert "median spacing 0.5 ms for a mean of 92.3 ms" in warned[0]


def test_bursty_odom_through_open_log(tmp_path):
    src = open_log(_write(tmp_path, _bursty_odom()))
    msgs = [(t, m) for t, m in src.messages(["/odom", "/scan"])]
    assert [t for t, _ in msgs[:4]] == ["/odom", "/scan", "/odom", "/scan"]
    odom = [m for t, m in msgs if t == "/odom"]
    assert len(odom) == N_SCANS
    assert odom[10].pose == pytest.approx(_carried(10), abs=1e-9)
    assert np.all(np.diff([m.stamp for _, m in msgs]) > 0)
    # the twist over the stamps yielded: 0 for the first, then the poses' finite difference
    assert odom[0].twist == pytest.approx([0.0, 0.0, 0.0])
    dt = odom[10].stamp - odom[9].stamp
    assert odom[10].twist == pytest.approx(between(np.array(_carried(9)), np.array(_carried(10))) / dt, abs=1e-9)


def test_bursty_odom_without_carried_poses_keeps_the_odom_lines(tmp_path):
    # old-format FLASER lines carry no pose: the ODOM lines are all the odometry there is
    reader = CarmenReader(_write(tmp_path, _bursty_odom(), posed=False))
    odom = [m for t, m in reader if t == "/odom"]
    assert len(odom) == N_SCANS
    assert reader.stats["odom_from_laser"] is False and "odom_bursts" not in reader.stats
    assert odom[0].pose == pytest.approx([SPEED * 0.05, 0.0, 0.0])
