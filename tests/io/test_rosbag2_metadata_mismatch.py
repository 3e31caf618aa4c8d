"""A rosbag2 folder whose metadata.yaml disagrees with its storage file is read whole, with a
warning: other QoS or type hash for a topic (Jazzy's QoS notation rewritten for Humble by a tool,
a hand-edited file: ``rosbags`` matches a file's topics to the metadata's on topic, type,
serialization, QoS and hash, and read none of such a topic's messages, with no word), or a
database renamed after recording (the metadata names a file the folder lacks)."""

from __future__ import annotations

import logging
from pathlib import Path

import yaml

from fgloc.io import open_log
from fgloc.testing import rosmsgs
from fgloc.types import LaserScan, Odometry

N = 20
T0 = 1_733_500_000_000_000_000
JAZZY_QOS = [{"history": "keep_last", "depth": 10, "reliability": "reliable", "durability": "volatile",
              "deadline": {"sec": 9223372036, "nsec": 854775807}, "lifespan": {"sec": 9223372036, "nsec": 854775807},
              "liveliness": "automatic", "liveliness_lease_duration": {"sec": 9223372036, "nsec": 854775807},
              "avoid_ros_namespace_conventions": False}]


def _write(folder: Path) -> None:
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    with Writer(folder, version=8) as w:
        cs = w.add_connection("/scan", "sensor_msgs/msg/LaserScan", typestore=ts)
        co = w.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=ts)
        for i in range(N):
            ns = T0 + i * 50_000_000
            odom = rosmsgs.odometry(ts.types, ns, 0.01 * i)
            w.write(co, ns, ts.serialize_cdr(odom, odom.__msgtype__))
            scan = rosmsgs.laser_scan(ts.types, ns, 1.0)
            w.write(cs, ns + 1000, ts.serialize_cdr(scan, scan.__msgtype__))


def _requalified(folder: Path, topics: tuple[str, ...], hashed: tuple[str, ...] = ()) -> None:
    """metadata.yaml in a Jazzy recorder's layout (version 9, QoS as a list of mappings), with other
    QoS than the storage file's for ``topics`` and another type hash for ``hashed``."""
    meta = folder / "metadata.yaml"
    data = yaml.safe_load(meta.read_text())
    info = data["rosbag2_bagfile_information"]
    info["version"] = 9
    info["ros_distro"] = "jazzy"
    for t in info["topics_with_message_count"]:
        tm = t["topic_metadata"]
        if tm["name"] in topics:
            tm["offered_qos_profiles"] = JAZZY_QOS
        if tm["name"] in hashed:
            tm["type_description_hash"] = "RIHS01_" + "0" * 64
    meta.write_text(yaml.safe_dump(data, sort_keys=False))


def _read(folder: Path) -> dict[str, int]:
    src = open_log(folder)
    n = {"/odom": 0, "/scan": 0}
    for _, m in src.messages(["/odom", "/scan"]):
        n["/odom" if isinstance(m, Odometry) else "/scan"] += isinstance(m, (Odometry, LaserScan))
    return n


def test_a_metadata_yaml_with_other_qos_than_the_storage_is_read_whole(tmp_path: Path, caplog) -> None:
    from rosbags.rosbag2 import Reader

    bag = tmp_path / "bag"
    _write(bag)
    _requalified(bag, ("/odom",), hashed=("/scan",))
    with Reader(bag) as r:  # the library alone: the metadata's topics match none of the file's
        assert sum(1 for _ in r.messages()) == 0
    with caplog.at_level(logging.WARNING):
        got = _read(bag)
    assert got == {"/odom": N, "/scan": N}
    assert ("metadata.yaml's QoS / serialization / type hash of /odom, /scan differ from the storage files'"
            in caplog.text)
    # the counts fgloc info prints are the metadata's, once per topic
    s = open_log(bag).summary()
    assert {t: v["count"] for t, v in s["topics"].items()} == {"/odom": N, "/scan": N}


def test_a_clean_bag_reads_as_before_and_says_nothing(tmp_path: Path, caplog) -> None:
    bag = tmp_path / "bag"
    _write(bag)
    _requalified(bag, ())  # Jazzy's metadata layout, the storage's own QoS
    with caplog.at_level(logging.WARNING):
        assert _read(bag) == {"/odom": N, "/scan": N}
    assert "metadata.yaml" not in caplog.text


def test_a_database_renamed_after_recording_is_read_alone(tmp_path: Path, caplog) -> None:
    bag = tmp_path / "bag"
    _write(bag)
    (db,) = bag.glob("*.db3")
    db.rename(bag / "renamed_0.db3")
    with caplog.at_level(logging.WARNING):
        assert _read(bag) == {"/odom": N, "/scan": N}
    assert f"metadata.yaml names {db.name}, not in the folder; reading renamed_0.db3 alone" in caplog.text
    assert "no metadata.yaml" not in caplog.text
    # given by its database file, the same
    assert _read(bag / "renamed_0.db3") == {"/odom": N, "/scan": N}
