"""CARMEN logs: message counts of the real Radish logs, beam geometry, mount, odd lines."""

from __future__ import annotations

import bz2
import gzip
import logging
import math
from collections import Counter

import numpy as np
import pytest

from fgloc.cli import main
from fgloc.errors import LogError
from fgloc.io import open_log
from fgloc.io.carmen import CarmenReader, iter_carmen
from fgloc.io.convert import import_log
from fgloc.types import LaserScan, Odometry


def _count_lines(path) -> Counter:
    """Independent grep-like count of the message lines of a (compressed) CARMEN file."""
    opener = bz2.open if str(path).endswith(".bz2") else gzip.open if str(path).endswith(".gz") else open
    c: Counter = Counter()
    with opener(path, "rt") as f:
        for line in f:
            word = line.split(" ", 1)[0].strip()
            if word in ("ODOM", "FLASER", "RLASER", "ROBOTLASER1"):
                c[word] += 1
    return c


def _topic_counts(it) -> Counter:
    return Counter(t for t, _ in it)


def test_intel_counts(shared_data):
    path = shared_data / "radish" / "intel.clf.bz2"
    lines = _count_lines(path)
    reader = CarmenReader(path)
    got = _topic_counts(reader)
    assert got["/scan"] == lines["FLASER"] + lines["RLASER"] + lines["ROBOTLASER1"] == 13631
    # its ODOM stamps come in bursts (median spacing 28.2 ms for a mean of 124.3 ms in the peek
    # window): the odometry is the pose each FLASER line carries, the ODOM lines are read, not used
    assert reader.stats["counts"]["ODOM"] == lines["ODOM"] == 26915
    assert got["/odom"] == reader.stats["counts"]["odom_from_laser"] == lines["FLASER"] == 13631
    assert reader.stats["odom_bursts"]["median_spacing_s"] < 0.5 * reader.stats["odom_bursts"]["mean_spacing_s"]
    assert got["/tf_static"] == 1


def test_aces_import_to_mcap_counts(shared_data, tmp_path):
    path = shared_data / "radish" / "aces.clf.bz2"
    lines = _count_lines(path)
    res = import_log(path, tmp_path / "aces.mcap", progress=False)
    r = open_log(res.dst)
    s = r.summary()
    assert s["topics"]["/scan"]["count"] == lines["FLASER"] == 7374
    assert s["topics"]["/odom"]["count"] == lines["ODOM"] == 7375
    assert s["truncated"] is None
    n_scan = n_odom = 0
    last = -math.inf
    for topic, m in r.messages():
        if topic == "/scan":
            n_scan += 1
            assert isinstance(m, LaserScan)
        elif topic == "/odom":
            n_odom += 1
            assert isinstance(m, Odometry)
        last = max(last, m.stamp) if not isinstance(m, list) else last
    assert (n_scan, n_odom) == (7374, 7375)
    assert r.laser_mount().pose == pytest.approx([0.0, 0.0, 0.0])


LX, LY = 1.0 + 0.1 * math.cos(0.5), 2.0 + 0.1 * math.sin(0.5)


def test_flaser_geometry_and_no_return(tmp_path):
    # 180 beams: CARMEN's 1 deg spacing from -90 deg; 50.0 is this log's no-return code
    ranges = [50.0] * 180
    ranges[0] = 1.0  # beam 0 at -90 deg (right of the robot)
    ranges[90] = 2.0  # beam 90 straight ahead
    ranges[179] = 3.0  # beam 179 at +89 deg
    lines = [
        "PARAM robot_use_laser on nohost 0",
        "ODOM 0.0 0.0 0.0 0.3 0.1 0.0 10.0 nohost 0.0",
        "FLASER 180 " + " ".join(f"{r:.2f}" for r in ranges) + f" {LX:.6f} {LY:.6f} 0.5 1.0 2.0 0.5 10.05 nohost 0.05",
        "FLASER 180 " + " ".join("50.00" for _ in ranges) + f" {LX:.6f} {LY:.6f} 0.5 1.0 2.0 0.5 10.10 nohost 0.10",
    ]
    p = tmp_path / "tiny.log"
    p.write_text("\n".join(lines) + "\n")
    msgs = list(iter_carmen(p))
    assert [t for t, _ in msgs] == ["/tf_static", "/odom", "/scan", "/scan"]
    mount = msgs[0][1][0]  # type: ignore[index]
    # laser pose = odometry pose (1, 2, 0.5) (+) (0.1, 0, 0): 10 cm ahead of base_link
    assert (mount.parent, mount.child) == ("base_link", "laser")
    assert mount.pose == pytest.approx([0.1, 0.0, 0.0], abs=1e-6)
    odom = msgs[1][1]
    assert isinstance(odom, Odometry) and odom.stamp == 10.0
    assert odom.twist == pytest.approx([0.3, 0.0, 0.1]) and odom.pose == pytest.approx([0, 0, 0])
    scan = msgs[2][1]
    assert isinstance(scan, LaserScan) and scan.stamp == 10.05
    assert scan.angle_min == pytest.approx(-math.pi / 2)
    assert scan.angle_increment == pytest.approx(math.radians(1.0))
    assert scan.angles[90] == pytest.approx(0.0, abs=1e-12)
    assert scan.angles[179] == pytest.approx(math.radians(89.0))
    assert scan.range_max == 50.0
    assert np.isinf(scan.ranges[1]) and np.isposinf(scan.ranges[1])
    pts = scan.points()
    assert len(pts) == 3
    assert pts[0] == pytest.approx([0.0, -1.0], abs=1e-9)
    assert pts[1] == pytest.approx([2.0, 0.0], abs=1e-9)
    assert pts[2] == pytest.approx([3 * math.cos(math.radians(89)), 3 * math.sin(math.radians(89))])


@pytest.mark.parametrize("n,step_deg", [(180, 1.0), (181, 1.0), (360, 0.5), (361, 0.5), (100, 180 / 99)])
def test_flaser_beam_spacing(tmp_path, n, step_deg):
    p = tmp_path / "n.clf"
    p.write_text(f"FLASER {n} {' '.join(['5.0'] * n)} 0 0 0 0 0 0 1.0 h 1.0\n")
    (_, scan), = [m for m in iter_carmen(p) if m[0] == "/scan"]
    assert scan.angle_increment == pytest.approx(math.radians(step_deg))  # type: ignore[attr-defined]
    assert scan.angle_min == pytest.approx(-math.pi / 2)  # type: ignore[attr-defined]


def test_robotlaser1_and_odom_from_laser(shared_data):
    path = shared_data / "radish" / "fr-clinic_robotlaser.clf.bz2"
    rd = CarmenReader(path)
    it = iter(rd)
    topic, tf = next(it)
    assert topic == "/tf_static"
    assert tf[0].pose == pytest.approx([0.22, 0.0, 0.0])  # type: ignore[index]
    n = Counter()
    first_scan = None
    for topic, m in it:
        n[topic] += 1
        if topic == "/scan" and first_scan is None:
            first_scan = m
    lines = _count_lines(path)
    assert n["/scan"] == lines["ROBOTLASER1"] == 6917
    assert n["/odom"] == 6917  # no ODOM lines: one odometry per laser line
    assert rd.stats["odom_from_laser"] is True
    assert isinstance(first_scan, LaserScan)
    assert first_scan.range_max == pytest.approx(81.9)
    assert first_scan.angle_increment == pytest.approx(0.017453)
    assert np.isinf(first_scan.ranges).any()


def test_bad_lines_are_skipped_and_counted(tmp_path, caplog):
    p = tmp_path / "bad.log.gz"
    with gzip.open(p, "wt") as f:
        f.write("# a comment\n")
        f.write("ODOM 1 2 0.1 0.2 0.0 0 5.0 h 5.0\n")
        f.write("ODOM 1 2 oops 0.2 0.0 0 5.1 h 5.1\n")
        f.write("FLASER 180 1 2 3\n")
        f.write("WEIRD 1 2 3\n")
        f.write("ODOM 1 2 0.1 0.2 0.0 0 5.2 h 5.2\n")
    rd = CarmenReader(p)
    with caplog.at_level(logging.WARNING):
        got = list(rd)
    assert [t for t, _ in got] == ["/tf_static", "/odom", "/odom"]
    assert rd.stats["malformed"] == {"ODOM": 1, "FLASER": 1}
    assert rd.stats["skipped"]["WEIRD"] == 1
    assert any("malformed" in r.message for r in caplog.records)


def test_not_carmen_and_missing(tmp_path, capsys):
    p = tmp_path / "x.clf"
    p.write_text("hello\nworld\n")
    with pytest.raises(LogError, match="not a CARMEN log"):
        iter_carmen(p)
    assert main(["import", str(p), "-o", str(tmp_path / "o.mcap")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(p) in err and "Traceback" not in err
    assert not (tmp_path / "o.mcap").exists()
    with pytest.raises(LogError, match="not found"):
        iter_carmen(tmp_path / "missing.clf")


def test_fr079_mount_matches_frontlaser_offset_param(shared_data):
    path = shared_data / "radish" / "fr079.clf.bz2"
    with bz2.open(path, "rt") as f:
        offset = next(float(ln.split()[2]) for ln in f if ln.startswith("PARAM robot_frontlaser_offset"))
    assert offset == -0.04
    (mount,) = CarmenReader(path).laser_mounts  # from FLASER laser pose vs odometry pose
    assert mount.pose == pytest.approx([offset, 0.0, 0.0], abs=1e-6)
