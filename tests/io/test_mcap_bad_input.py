"""Truncated, empty, non-MCAP and missing-topic logs: read up to the break or one-line errors."""

from __future__ import annotations

import re

import numpy as np
import pytest

from fgloc.cli import main
from fgloc.errors import LogError
from fgloc.io import open_log
from fgloc.io.mcap_writer import LogWriter
from fgloc.types import CompassHeading, LaserScan, Odometry, StaticTransform

N_STEPS = 400


@pytest.fixture(scope="module")
def full_log(tmp_path_factory):
    """A ~300 kB log in several small chunks (like a recorder that was killed mid-run)."""
    path = tmp_path_factory.mktemp("trunc") / "full.mcap"
    rng = np.random.default_rng(0)
    with LogWriter(path, chunk_size=16 * 1024) as w:
        w.write("/tf_static", [StaticTransform("base_link", "laser", np.array([0.1, 0.0, 0.0]))])
        for i in range(N_STEPS):
            t = 100.0 + 0.04 * i
            w.write("/scan", LaserScan(t, -2.0, 0.01, 0.1, 30.0, rng.uniform(1, 9, 400).astype(np.float32)))
            w.write("/odom", Odometry(t + 0.01, np.array([0.5, 0.0, 0.01 * i])))
            w.write("/imu", CompassHeading(t + 0.02, yaw_rad=0.001 * i))
    return path


def _one_line_no_traceback(text: str) -> None:
    assert "Traceback" not in text
    assert len(text.strip().splitlines()) == 1


@pytest.mark.parametrize("frac", [0.2, 0.5, 0.77, 0.95])
def test_truncated_read_up_to_break(full_log, tmp_path, frac):
    data = full_log.read_bytes()
    cut = int(len(data) * frac)
    path = tmp_path / "cut.mcap"
    path.write_bytes(data[:cut])
    r = open_log(path)
    assert r.truncated is not None
    m = re.search(r"file ends at byte (\d+).*?(\d+) complete messages read, the last at t=([\d.]+) s", r.truncated)
    assert m, r.truncated
    assert int(m.group(1)) == cut
    got = list(r.messages())
    assert int(m.group(2)) == len(got)
    # every message before the break, in order, and at least the complete chunks
    full = list(open_log(full_log).messages())
    assert len(full) == 1 + 3 * N_STEPS
    assert 0.8 * frac * len(full) - 40 < len(got) < len(full)
    for (ta, a), (tb, b) in zip(full, got, strict=False):
        assert ta == tb
        assert getattr(a, "stamp", None) == getattr(b, "stamp", None)
    assert float(m.group(3)) == pytest.approx(got[-1][1].stamp, abs=1e-3)  # type: ignore[attr-defined]
    assert r.summary()["messages"] == len(got)
    assert "\n" not in r.truncated


def test_summary_cut_off_keeps_all_messages(full_log, tmp_path):
    data = full_log.read_bytes()
    path = tmp_path / "cut.mcap"
    path.write_bytes(data[:-20])
    r = open_log(path)
    assert r.truncated is not None and "all 1201 messages intact" in r.truncated
    assert len(list(r.messages())) == 1201


def test_info_on_truncated_log_says_where(full_log, tmp_path, capsys):
    data = full_log.read_bytes()
    cut = len(data) // 2
    path = tmp_path / "cut.mcap"
    path.write_bytes(data[:cut])
    assert main(["info", str(path)]) == 0
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err
    lines = [ln for ln in out.splitlines() if ln.startswith("TRUNCATED:")]
    assert len(lines) == 1 and f"file ends at byte {cut}" in lines[0]
    assert re.search(r"/scan\s+\d+\s+sensor_msgs/msg/LaserScan", out)
    assert len(err.strip().splitlines()) <= 1


def test_info_on_good_log(full_log, capsys):
    assert main(["info", str(full_log)]) == 0
    out, _ = capsys.readouterr()
    assert re.search(r"1201 messages, 15\.98\d s", out)
    assert re.search(r"/odom\s+400\s+nav_msgs/msg/Odometry", out)
    assert "TRUNCATED" not in out


def _error_of(path, capsys) -> str:
    assert main(["info", str(path)]) == 2
    out, err = capsys.readouterr()
    _one_line_no_traceback(err)
    assert err.startswith("fgloc: error: ")
    assert str(path) in err
    return err


def test_missing_file(tmp_path, capsys):
    assert "not found" in _error_of(tmp_path / "nope.mcap", capsys)


def test_not_an_mcap(tmp_path, capsys):
    p = tmp_path / "notes.mcap"
    p.write_text("hello, this is not a log\n")
    assert "not an MCAP file" in _error_of(p, capsys)


def test_zero_byte_file(tmp_path, capsys):
    p = tmp_path / "zero.mcap"
    p.write_bytes(b"")
    assert "empty file" in _error_of(p, capsys)


def test_empty_log(tmp_path, capsys):
    p = tmp_path / "empty.mcap"
    with LogWriter(p):
        pass
    assert "empty log (no messages)" in _error_of(p, capsys)
    with pytest.raises(LogError, match="empty log"):
        open_log(p)


def test_cut_before_first_message(full_log, tmp_path, capsys):
    p = tmp_path / "tiny.mcap"
    p.write_bytes(full_log.read_bytes()[:60])
    err = _error_of(p, capsys)
    assert "no complete message before the break" in err and "file ends at byte 60" in err


def test_missing_topic_names_file_topic_and_existing(full_log):
    r = open_log(full_log)
    with pytest.raises(LogError) as e:
        r.messages({"/scan", "/base_scan"})
    msg = str(e.value)
    assert "\n" not in msg
    assert str(full_log) in msg and "'/base_scan'" in msg
    assert "/imu, /odom, /scan, /tf_static" in msg


@pytest.mark.parametrize("chunked", [False, True])
def test_unindexed_mcap_is_streamed_not_truncated(tmp_path, chunked):
    """A complete MCAP without summary/index (other writers' option) reads fully, in order."""
    from mcap.writer import CompressionType, IndexType
    from mcap.writer import Writer as McapWriter
    from mcap_ros2._dynamic import serialize_dynamic

    from fgloc.io.msgdefs import full_text
    from fgloc.io.ros import odom_to_ros
    from fgloc.io.topics import ODOMETRY

    path = tmp_path / "plain.mcap"
    enc = serialize_dynamic(ODOMETRY, full_text(ODOMETRY))[ODOMETRY]
    with path.open("wb") as f:
        w = McapWriter(f, chunk_size=2048, compression=CompressionType.NONE, index_types=IndexType.NONE,
                       use_chunking=chunked, use_statistics=False, use_summary_offsets=False,
                       repeat_channels=False, repeat_schemas=False)
        w.start(profile="ros2", library="test")
        sid = w.register_schema(ODOMETRY, "ros2msg", full_text(ODOMETRY).encode())
        cid = w.register_channel("/odom", "cdr", sid)
        for i in range(50):
            m = Odometry(10.0 + 0.1 * i, np.array([0.1 * i, 0.0, 0.0]))
            w.add_message(cid, int(m.stamp * 1e9), enc(odom_to_ros(m, m.stamp)), int(m.stamp * 1e9))
        w.finish()
    r = open_log(path)
    assert r.truncated is None and not r.summary()["indexed"]
    got = [m for _, m in r.messages()]
    assert len(got) == 50 and r.summary()["topics"]["/odom"]["count"] == 50
    assert [o.twist[0] for o in got] == pytest.approx([0.1 * i for i in range(50)])  # type: ignore[attr-defined]
