"""``fgloc batch run`` over real logs of every format resolves each log's topics as ``fgloc run`` does:
robot_localization's two bags (no /scan, no /imu: /imu/data), a rosbag2 folder with /scan and /odom
and no IMU (written here with rosbags from the bundled Intel excerpt) and a CARMEN log.  Each
trajectory is byte-identical to the single run's."""

from __future__ import annotations

from pathlib import Path

import pytest

from .helpers import fgloc_cli


def write_rosbag2(src_mcap: Path, dst: Path) -> Path:
    """A rosbag2 folder (sqlite3 storage, rosbags' writer) holding the CDR messages of a ROS 2 MCAP."""
    from mcap.reader import make_reader
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    conns = {}
    with open(src_mcap, "rb") as fh, Writer(dst, version=8) as w:
        for schema, channel, msg in make_reader(fh).iter_messages(log_time_order=True):
            if channel.topic not in conns:
                conns[channel.topic] = w.add_connection(channel.topic, schema.name, typestore=store)
            w.write(conns[channel.topic], msg.log_time, msg.data)
    return dst


@pytest.fixture(scope="module")
def four_logs(shared_data, repo_data, tmp_path_factory) -> list[Path]:
    root = tmp_path_factory.mktemp("real-batch")
    rc, _, err = fgloc_cli("import", repo_data / "radish" / "intel-head.clf.bz2", "-o", root / "intel.mcap")
    assert rc == 0, err
    bag2 = write_rosbag2(root / "intel.mcap", root / "intel_rosbag2")
    rl = shared_data / "robot_localization"
    return [rl / "test1.bag", rl / "test2.bag", bag2, repo_data / "radish" / "fr079-head.clf.bz2"]


def test_batch_run_gives_the_single_runs_trajectories(four_logs, tmp_path):
    """Each log's trajectory is the single run's, byte for byte, and batch judges each log as ``fgloc
    run`` does: a run that exits 3 (its result unusable, e.g. the smoother diverging from dead reckoning
    on test1.bag with the defaults) is ``lost`` in the summary (its outputs written), the batch exits 1."""
    import csv

    names = ["test1", "test2", "intel_rosbag2", "fr079-head"]
    single_rc = {}
    for log, name in zip(four_logs, names, strict=True):
        rc, _, err = fgloc_cli("run", log, "-o", tmp_path / "single" / name, "-q")
        assert rc in (0, 3), err
        single_rc[name] = rc
    assert list(single_rc.values()).count(0) >= 2, single_rc  # not a comparison of failures only
    rc, out, err = fgloc_cli("batch", "run", *four_logs, "-o", tmp_path / "batch", "-j", "2", "-q")
    n_ok = list(single_rc.values()).count(0)
    assert rc == (0 if n_ok == len(names) else 1), out + err
    assert f"{n_ok}/{len(names)} done" in out
    with open(tmp_path / "batch" / "summary.csv", newline="") as fh:
        status = {row["log"]: row["status"] for row in csv.DictReader(fh)}
    assert status == {name: "ok" if single_rc[name] == 0 else "lost" for name in names}, (status, single_rc)
    for name in names:
        single = (tmp_path / "single" / name / "trajectory.tum").read_bytes()
        assert single.count(b"\n") > 100
        assert (tmp_path / "batch" / name / "trajectory.tum").read_bytes() == single, name
    # the rosbag2 folder and the bags are found in a folder too, as logs of their own
    from fgloc.batch.inputs import RUN_SUFFIXES, discover_logs

    found = discover_logs([str(four_logs[2].parent)], RUN_SUFFIXES)
    assert four_logs[2].resolve() in found
