"""rosbag2 SQLite recordings that did not end cleanly: no metadata.yaml, messages in the -wal.

The recorder writes ``metadata.yaml`` when it closes, and with SQLite's write-ahead log
(Foxy's and Galactic's recorder, Humble's ``resilient`` preset) the last transactions sit in
``<file>.db3-wal`` until a checkpoint.  The test writes a bag with rosbags, then appends
messages through a WAL connection and copies the files while it is still open: what a killed
recorder leaves on disk.
"""

from __future__ import annotations

import logging
import shutil
import sqlite3

import pytest

from fgloc.cli import main
from fgloc.io import open_log
from fgloc.testing import rosmsgs
from fgloc.types import LaserScan, Odometry

N = 20      # scans and odometry messages the database holds
EXTRA = 8   # odometry messages only in the -wal
T0 = 1_695_826_859_000_000_000


def _write(folder):
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)

    def odom(i):
        ns = T0 + i * 50_000_000
        return ns, rosmsgs.odometry(ts.types, ns, 0.01 * i)

    with Writer(folder, version=8) as w:
        cs = w.add_connection("/scan", "sensor_msgs/msg/LaserScan", typestore=ts)
        co = w.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=ts)
        for i in range(N):
            ns, msg = odom(i)
            w.write(co, ns, ts.serialize_cdr(msg, msg.__msgtype__))
            scan = rosmsgs.laser_scan(ts.types, ns, 1.0 + 0.01 * i)
            w.write(cs, ns + 1000, ts.serialize_cdr(scan, scan.__msgtype__))
    return [odom(i) for i in range(N, N + EXTRA)], ts


def _killed(tmp_path, with_metadata=False):
    """A folder as a killed recorder leaves it: the database, its -wal holding EXTRA more
    odometry messages, and (unless ``with_metadata``) no metadata.yaml."""
    good = tmp_path / "good"
    more, ts = _write(good)
    db = next(good.glob("*.db3"))
    killed = tmp_path / "killed"
    killed.mkdir()
    con = sqlite3.connect(db)
    con.execute("PRAGMA journal_mode=WAL")
    con.execute("PRAGMA wal_autocheckpoint=0")
    topic_id = con.execute("SELECT id FROM topics WHERE name='/odom'").fetchone()[0]
    con.executemany("INSERT INTO messages (topic_id, timestamp, data) VALUES (?, ?, ?)",
                    [(topic_id, ns, ts.serialize_cdr(m, m.__msgtype__)) for ns, m in more])
    con.commit()
    for f in good.iterdir():  # copied while the recorder still has the database open
        if f.name != "metadata.yaml" or with_metadata:
            shutil.copyfile(f, killed / f.name)
    con.close()
    assert (killed / (db.name + "-wal")).stat().st_size > 0
    return good, killed, db.name


def _odom_x(src):
    return [round(m.pose[0], 6) for t, m in src.messages(["/odom"]) if isinstance(m, Odometry)]


def test_folder_without_metadata_and_its_wal(tmp_path, caplog, capsys):
    _, killed, name = _killed(tmp_path)
    with caplog.at_level(logging.WARNING):
        src = open_log(killed)
    assert "no metadata.yaml" in caplog.text
    assert f"{name}-wal holds {EXTRA} messages not yet merged" in caplog.text
    s = src.summary()
    assert {t: v["count"] for t, v in s["topics"].items()} == {"/odom": N + EXTRA, "/scan": N}
    assert _odom_x(src) == [round(0.01 * i, 6) for i in range(N + EXTRA)]
    scans = [m for _, m in src.messages(["/scan"])]
    assert all(isinstance(m, LaserScan) for m in scans) and len(scans) == N
    assert (killed / (name + "-wal")).stat().st_size > 0  # the user's files are left as they were
    assert main(["info", str(killed)]) == 0
    assert f"{N + EXTRA}  nav_msgs/msg/Odometry" in capsys.readouterr().out


def test_lone_database_file_with_its_wal(tmp_path):
    _, killed, name = _killed(tmp_path)
    src = open_log(killed / name)
    assert src.summary()["topics"]["/odom"]["count"] == N + EXTRA


def test_folder_without_metadata_nor_wal(tmp_path, caplog):
    good = tmp_path / "good"
    _write(good)
    (good / "metadata.yaml").unlink()
    with caplog.at_level(logging.WARNING):
        src = open_log(good)
    assert "no metadata.yaml" in caplog.text and "-wal" not in caplog.text
    assert src.summary()["messages"] == 2 * N


def test_split_recording_without_metadata(tmp_path, capsys):
    good = tmp_path / "good"
    _write(good)
    (good / "metadata.yaml").unlink()
    db = next(good.glob("*.db3"))
    shutil.copyfile(db, good / "rosbag2_1.db3")
    assert main(["info", str(good)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert "no metadata.yaml beside its 2 storage files" in err and "ros2 bag reindex" in err


def test_wal_of_a_bag_with_metadata(tmp_path, caplog):
    """A single uncompressed database is read merged with its -wal even beside a metadata.yaml
    (which counts only what was in the database)."""
    _, killed, name = _killed(tmp_path, with_metadata=True)
    with caplog.at_level(logging.WARNING):
        src = open_log(killed)
    assert f"holds {EXTRA} messages" in caplog.text and "no metadata.yaml" not in caplog.text
    assert src.summary()["topics"]["/odom"]["count"] == N + EXTRA


@pytest.mark.parametrize("wal", [False, True])
def test_run_reads_every_message(tmp_path, capsys, wal):
    """Without the -wal the database's own N odometry messages are read, with it all of them."""
    _, killed, _ = _killed(tmp_path)
    if not wal:
        for f in killed.glob("*-wal"):
            f.unlink()
    assert main(["run", str(killed), "-o", str(tmp_path / "out"), "-q"]) == 0
    out = capsys.readouterr().out
    assert f"scans {N}, " in out and f"odometry {N + EXTRA if wal else N}, " in out


def test_info_calls_a_clean_folder_indexed(tmp_path, capsys):
    """``fgloc info``: a folder read through its metadata.yaml is indexed (every rosbag2 folder
    was "not indexed" before); one without it, or with messages left in a -wal, is not."""
    good, killed, _ = _killed(tmp_path)
    _, with_meta, _ = _killed(tmp_path / "m", with_metadata=True)
    for folder, word in ((good, "indexed"), (killed, "not indexed"), (with_meta, "not indexed")):
        capsys.readouterr()
        assert main(["info", str(folder)]) == 0
        assert capsys.readouterr().out.splitlines()[0].endswith(f"), {word}"), folder


def test_a_rosbag2_folder_given_by_its_metadata_yaml_is_read_as_the_folder(tmp_path):
    """``fgloc info BAG/metadata.yaml`` answered "not a CARMEN log?" (probe10, on a public
    TurtleBot3 recording): the metadata file names the folder's log, so the folder is read."""
    bag = tmp_path / "rec"
    _write(bag)
    via_yaml = open_log(bag / "metadata.yaml").summary()["topics"]
    assert {t: v["count"] for t, v in via_yaml.items()} == {"/scan": N, "/odom": N}
    assert via_yaml == open_log(bag).summary()["topics"]
