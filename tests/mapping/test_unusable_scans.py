"""Unusable scans into ``fgloc map`` and ``fgloc run``: every range NaN, inf or 0, or
``angle_increment`` 0 (beams without directions).  Before, ``fgloc map`` wrote an empty or a
23-cell garbage map with exit 0 and a self-check that 'passed'; ``fgloc run`` matched the
direction-less scans into fixes.  Now: a log with nothing to map is a one-line error and no
folder; a log with some unusable scans maps the rest and says how many it skipped, and why;
``fgloc run`` counts every such scan as a no-fix with its reason and makes no fix of one."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from fgloc.cli import main
from fgloc.io.mcap_writer import LogWriter
from fgloc.testing.soak import lap_world

N_SCANS = 150


def _log(path, kind: str, bad_every: int = 1):
    """The lap world's first 6 s (150 scans at 25 Hz) with every ``bad_every``-th scan made ``kind``."""
    w = lap_world()
    with LogWriter(path) as out:
        out.write("/tf_static", [w.mount], 0.0)
        k = 0
        for topic, m in w.messages(N_SCANS / 25.0):
            if topic == "/scan":
                if k % bad_every == 0:
                    r = {"nan": np.full_like(m.ranges, np.nan), "inf": np.full_like(m.ranges, np.inf),
                         "zero": np.zeros_like(m.ranges)}.get(kind, m.ranges)
                    inc = 0.0 if kind == "inc0" else m.angle_increment
                    m = type(m)(m.stamp, m.angle_min, inc, m.range_min, m.range_max, r, scan_time=m.scan_time,
                                time_increment=m.time_increment)
                k += 1
            out.write(topic, m)
    return w, path


@pytest.mark.parametrize("kind", ["nan", "inf", "zero", "inc0"])
def test_map_of_unusable_scans_is_a_one_line_error_and_no_folder(tmp_path, capsys, kind):
    _, log = _log(tmp_path / f"{kind}.mcap", kind)
    out = tmp_path / "map"
    rc = main(["map", str(log), "-o", str(out), "--no-progress"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and err[0].startswith(f"fgloc: error: {log}: "), err
    want = "no usable scan (150 with angle_increment 0" if kind == "inc0" else \
        "no scan has a return within range (150 scans"
    assert want in err[0]
    assert not out.exists()


def test_map_with_some_direction_less_scans_skips_and_counts_them(tmp_path, capsys):
    _, log = _log(tmp_path / "some.mcap", "inc0", bad_every=3)
    out = tmp_path / "map"
    rc = main(["map", str(log), "-o", str(out), "--no-progress"])
    err = capsys.readouterr().err
    assert rc == 0, err
    assert "50 of 150 scans skipped as unusable: 50 with angle_increment 0" in err
    doc = yaml.safe_load((out / "mapping.yaml").read_text())
    assert doc["scans"] == 100 and sum(doc["skipped_scans"].values()) == 50
    assert doc["warnings"][0].startswith("50 of 150 scans skipped as unusable")


@pytest.mark.parametrize("kind", ["nan", "inc0"])
def test_run_counts_unusable_scans_and_makes_no_fix_of_them(tmp_path, capsys, kind):
    w, log = _log(tmp_path / f"{kind}.mcap", kind, bad_every=2)
    map_yaml = w.map.save(tmp_path / "room.yaml")
    x, y, yaw = w.pose(0.0)
    rc = main(["run", str(log), "--map", str(map_yaml), "--initial-pose", str(x), str(y), str(yaw),
               "-o", str(tmp_path / "run"), "--allow-lost"])
    cap = capsys.readouterr()
    err = cap.out + cap.err
    assert rc == 0, err
    # the unusable scans are no-fixes counted under their reason; no fix is stamped at one of them
    reason = "angle_increment" if kind == "inc0" else "valid beams"
    counted = [line.split() for line in err.splitlines() if reason in line]
    assert counted and sum(int(c[0]) for c in counted if c[0].isdigit()) >= 10, err
    fixes = tmp_path / "run" / "fixes.tum"
    stamps = [float(line.split()[0]) for line in fixes.read_text().splitlines() if line.strip() and line[0] != "#"] \
        if fixes.exists() else []
    bad = {round(k / 25.0 + 0.001, 6) for k in range(0, N_SCANS, 2)}
    assert not bad & {round(t, 6) for t in stamps}
    assert kind == "nan" or stamps  # (the good half of the scans made fixes)
