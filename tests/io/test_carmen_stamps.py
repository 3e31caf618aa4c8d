"""CARMEN stamps that go backwards: repaired in file order when the poses say the file order is
right, sorted by stamp as before otherwise."""

from __future__ import annotations

import numpy as np

from fgloc.io import open_log


def _write(path, stamps, xs, laser_every: int = 0) -> None:
    lines = []
    for i, (t, x) in enumerate(zip(stamps, xs, strict=True)):
        lines.append(f"ODOM {x:.3f} 0.000 0.000000 0.0 0.0 0.0 {t:.6f} host {t:.6f}")
        if laser_every and i % laser_every == 0:
            ranges = " ".join(["2.0"] * 180)
            pose = f"{x:.3f} 0.000 0.000000"
            lines.append(f"FLASER 180 {ranges} {pose} {pose} {t + 0.001:.6f} host {t:.6f}")
    path.write_text("\n".join(lines) + "\n")


def _odom(path):
    src = open_log(path)
    msgs = [m for _, m in src.messages(["/odom"])]
    return src, np.array([m.stamp for m in msgs]), np.array([m.pose[0] for m in msgs])


def test_one_line_stamped_early_keeps_its_file_place(tmp_path):
    """A line stamped 0.45 s before its neighbours while its pose is between theirs (the robot drives
    0.1 m per 0.1 s): stamped halfway between its file neighbours; the poses stay in file order."""
    stamps = 100.0 + 0.1 * np.arange(20)
    xs = 0.1 * np.arange(20)
    stamps[10] -= 0.45
    _write(tmp_path / "early.clf", stamps, xs)
    src, t, x = _odom(tmp_path / "early.clf")
    assert src.repaired == {"/odom": 1}
    assert src.skipped == {"backward stamps repaired /odom": 1}
    np.testing.assert_allclose(x, xs)                       # file order
    assert t[10] == 0.5 * (t[9] + t[11]) and np.all(np.diff(t) > 0)


def test_one_line_stamped_late_keeps_its_file_place(tmp_path):
    """A line stamped 0.25 s after the next ones (the others in order, moving): repaired too."""
    stamps = 100.0 + 0.1 * np.arange(20)
    xs = 0.1 * np.arange(20)
    stamps[7] += 0.25
    _write(tmp_path / "late.clf", stamps, xs, laser_every=3)
    src, t, x = _odom(tmp_path / "late.clf")
    assert src.repaired.get("/odom") == 1
    np.testing.assert_allclose(x, xs)
    assert t[7] == 0.5 * (t[6] + t[8])


def test_pose_that_fits_its_stamp_is_sorted_as_before(tmp_path):
    """A line written late in the file whose pose belongs where its stamp puts it: no repair, sorted
    by stamp (the existing behaviour); so is a line out of place while the robot stands still."""
    stamps = 100.0 + 0.1 * np.arange(20)
    xs = 0.1 * np.arange(20)
    order = list(range(20))
    order.insert(12, order.pop(5))  # line 5 (its stamp and pose) written after line 12
    _write(tmp_path / "moved.clf", stamps[order], xs[order])
    src, t, x = _odom(tmp_path / "moved.clf")
    assert src.repaired == {}
    np.testing.assert_allclose(x, xs)                       # stamp order = the poses' order
    still = np.zeros(20)
    early = stamps.copy()
    early[10] -= 0.45
    _write(tmp_path / "still.clf", early, still)
    src, t, _ = _odom(tmp_path / "still.clf")
    assert src.repaired == {} and np.all(np.diff(t) >= 0)  # no evidence: sorted
    np.testing.assert_allclose(t, np.sort(early))


def test_file_order_reading_has_open_logs_stamps(repo_data):
    """carmen_file_order: the file's order with the stamps open_log gives (intel-head: repaired lines)."""
    from fgloc.io import open_log
    from fgloc.io.carmen import carmen_file_order, iter_carmen

    log = repo_data / "radish" / "intel-head.clf.bz2"
    for topic in ("/scan", "/odom"):
        fixed = [m.stamp for t, m in carmen_file_order(log) if t == topic]
        raw = [m.stamp for t, m in iter_carmen(log) if t == topic]
        seen = [m.stamp for t, m in open_log(log).messages([topic])]
        assert len(fixed) == len(raw) == len(seen)
        assert sum(a != b for a, b in zip(fixed, raw, strict=True)) > 10  # repaired lines
        assert sorted(fixed) == sorted(seen)
