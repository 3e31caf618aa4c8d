"""fgloc as a ROS 2 node: ``ros_discovery_info`` and the type hashes in USER_DATA.

Sources (read from their public repositories): rmw_cyclonedds_cpp 3.2.0 ``rmw_node.cpp``
(``rmw_context_impl_s::init``: the ``ros_discovery_info`` writer, reliable, transient local, keep
last 1; ``convert_guid_to_gid``; ``create_readwrite_qos``: USER_DATA ``typehash=...;``),
rmw_dds_common 3.2.0 (``msg/*.msg``; ``Gid.msg`` is ``char[16]`` since "Change Gid.msg to be 16
bytes", first in 2.0.0 = Iron; ``qos.cpp`` ``encode_type_hash_for_user_data_qos``; ``graph_cache.cpp``),
rosidl (``rosidl_generator_type_description``: ``calculate_type_hash``, FieldType ids;
``rosidl_adapter``: ``char`` is ``uint8`` in IDL).

The expected hashes are the values rosidl generated into public code (not computed here):
micro-ROS's generated ``*__struct.h`` headers (``<type>__TYPE_HASH``, e.g. micro-ROS/micro_ros_arduino),
rosidl_generator_c's ``*__description.c`` (``<type>__get_type_hash``: Imu, ParticipantEntitiesInfo) and
eclipse-zenoh/zenoh-plugin-ros2dds (``ROS_DISCOVERY_INFO_TYPE_HASH``, "in Iron and Jazzy").
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import uuid

import pytest

from fgloc.ros2 import graph, typehash

from .conftest import LOOPBACK, wait_for

PUBLISHED = {
    "sensor_msgs/msg/LaserScan": "64c191398013af96509d518dac71d5164f9382553fce5c1f8cca5be7924bd828",
    "sensor_msgs/msg/Imu": "7d9a00ff131080897a5ec7e26e315954b8eae3353c3f995c55faf71574000b5b",
    "nav_msgs/msg/Odometry": "3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0",
    "nav_msgs/msg/OccupancyGrid": "8d348150c12913a31ee0ec170fbf25089e4745d17035792a1ba94d6f0bc0cfc7",
    "tf2_msgs/msg/TFMessage": "e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087",
    "geometry_msgs/msg/PoseWithCovarianceStamped": "26432f9803e43727d3c8f668d1fdb3c630f548af631e2f4e31382371bfea3b6e",
    "std_msgs/msg/Header": "f49fb3ae2cf070f793645ff749683ac6b06203e41c891e17701b1cb597ce6a01",
    "diagnostic_msgs/msg/DiagnosticArray": "5a8a36efb05fb25070fa0fb3810290c0e6cd4862b54a8fb975a1ee8dc55a333e",
    "rosgraph_msgs/msg/Clock": "692f7a66e93a3c83e71765d033b60349ba68023a8c689a79e48078bcb5c58564",
    "rmw_dds_common/msg/ParticipantEntitiesInfo":
        "91a0593bacdcc50ea9bdcf849a938b128412cc1ea821245c663bcd26f83c295e",
}


# ----------------------------------------------------------------------------- type hashes
@pytest.mark.parametrize("type_name", list(PUBLISHED))
def test_type_hashes_are_the_published_ones(type_name: str) -> None:
    assert typehash.type_hash(type_name) == "RIHS01_" + PUBLISHED[type_name]
    assert typehash.type_hash(type_name.replace("/msg/", "/")) == typehash.type_hash(type_name)


def test_type_description_follows_rosidl() -> None:
    """FieldType ids (type_description_interfaces/msg/FieldType.msg), capacities and the order of
    the referenced types, as rosidl_generator_type_description serializes them."""
    d = typehash.type_description("sensor_msgs/msg/LaserScan")
    top = d["type_description"]
    assert top["type_name"] == "sensor_msgs/msg/LaserScan"
    f = {x["name"]: x["type"] for x in top["fields"]}
    assert list(f)[0] == "header" and list(f)[-1] == "intensities"   # the .msg order
    assert f["header"] == {"type_id": 1, "capacity": 0, "string_capacity": 0, "nested_type_name": "std_msgs/msg/Header"}
    assert f["angle_min"]["type_id"] == 10          # float32 -> FIELD_TYPE_FLOAT
    assert f["ranges"]["type_id"] == 10 + 144       # float32[] -> FIELD_TYPE_FLOAT_UNBOUNDED_SEQUENCE
    assert [r["type_name"] for r in d["referenced_type_descriptions"]] == [
        "builtin_interfaces/msg/Time", "std_msgs/msg/Header"]  # sorted by name
    pose = {x["name"]: x["type"] for x in typehash.type_description("geometry_msgs/msg/PoseWithCovariance")
            ["type_description"]["fields"]}
    assert pose["covariance"]["type_id"] == 11 + 48 and pose["covariance"]["capacity"] == 36  # float64[36]
    gid = typehash.type_description("rmw_dds_common/msg/ParticipantEntitiesInfo")["referenced_type_descriptions"]
    by = {t["type_name"]: {x["name"]: x["type"] for x in t["fields"]} for t in gid}
    assert by["rmw_dds_common/msg/Gid"]["data"] == {"type_id": 3 + 48, "capacity": 16, "string_capacity": 0,
                                                    "nested_type_name": ""}      # char[16]: uint8 array
    assert by["rmw_dds_common/msg/NodeEntitiesInfo"]["node_name"]["type_id"] == 21           # string<=256
    assert by["rmw_dds_common/msg/NodeEntitiesInfo"]["node_name"]["string_capacity"] == 256
    refs = typehash.type_description("diagnostic_msgs/msg/DiagnosticArray")["referenced_type_descriptions"]
    status = {x["name"]: x["type"] for r in refs if r["type_name"] == "diagnostic_msgs/msg/DiagnosticStatus"
              for x in r["fields"]}
    assert status["level"]["type_id"] == 16 and "OK" not in status   # byte -> FIELD_TYPE_BYTE; no constants
    odom = PUBLISHED["nav_msgs/msg/Odometry"]
    assert typehash.user_data("nav_msgs/msg/Odometry") == f"typehash=RIHS01_{odom};".encode()


# ----------------------------------------------------------------------------- ParticipantEntitiesInfo bytes
def _sample(size: int = 16) -> graph.ParticipantEntities:
    g = [bytes(range(k, k + 16)) for k in range(0, 80, 16)]
    return graph.ParticipantEntities(g[0], [
        graph.NodeEntities("fgloc", "/", readers=[g[1], g[2]], writers=[g[3]]),
        graph.NodeEntities("x" * 256, "/robot1", readers=[], writers=[g[4]]),
    ])


def test_participant_entities_info_bytes_are_cyclones() -> None:
    """fgloc's bytes are Cyclone's XCDR1 serialization of the message typed out by hand from
    rmw_dds_common's .msg files (tests/ros2/independent.py), and read back the same."""
    pytest.importorskip("cyclonedds")
    from . import independent as ind

    info = _sample()
    mine = graph.encode(info)
    nodes = [ind.NodeEntitiesInfo(n.namespace, n.name, [ind.Gid(list(g)) for g in n.readers],
                                  [ind.Gid(list(g)) for g in n.writers]) for n in info.nodes]
    theirs = ind.ParticipantEntitiesInfo(ind.Gid(list(info.gid)), nodes).serialize(use_version_2=False)
    assert mine[:4] == b"\x00\x01\x00\x00"                    # CDR_LE, as every rmw writes
    assert mine == theirs + b"\x00" * (-len(theirs) % 4)
    back = ind.ParticipantEntitiesInfo.deserialize(mine)
    assert bytes(back.gid.data) == info.gid and back.node_entities_info_seq[1].node_name == "x" * 256
    assert graph.decode(mine) == info
    with pytest.raises(ValueError, match="256"):
        graph.encode(graph.ParticipantEntities(info.gid, [graph.NodeEntities("y" * 257)]))
    for bad in (mine[:30], b"\x00\x01\x00\x00" + b"\x00" * 16 + b"\xff\xff\xff\x7f", b"\x00\x00\x00\x00" + mine[4:]):
        with pytest.raises(ValueError):
            graph.decode(bad)


def test_humble_gids_are_24_bytes() -> None:
    """Humble and older: ``char[24]``, the 16 GUID bytes then zeros (``convert_guid_to_gid``: memset, memcpy)."""
    info = _sample()
    old = graph.encode(info, graph.GID_SIZE_BEFORE_IRON)
    assert old[4:4 + 24] == info.gid + b"\x00" * 8
    back = graph.decode(old, 24)
    assert back.nodes[0].readers[0] == info.nodes[0].readers[0] + b"\x00" * 8
    assert graph.gid_size("humble") == 24 and graph.gid_size("jazzy") == 16 and graph.gid_size("rolling") == 16
    assert graph.before_iron("Humble") and not graph.before_iron("iron")
    u = uuid.UUID("01104c7d-80df-12ba-c5af-5f93000001c1")
    assert graph.gid_of(u) == bytes.fromhex("01104c7d80df12bac5af5f93000001c1")  # dds_guid_t.v, network order


def test_distro_from_env(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("ROS_DISTRO", raising=False)
    assert graph.distro_name(None) == "jazzy"
    monkeypatch.setenv("ROS_DISTRO", "humble")
    assert graph.distro_name(None) == "humble" and graph.distro_name("kilted") == "kilted"


# ----------------------------------------------------------------------------- over DDS
def test_each_generation_is_said_and_a_mismatch_named(dds_domain: int) -> None:
    """In one domain, an Iron+ fgloc (16-byte GIDs, type hashes) and a Humble one (24 bytes, none): each
    writes its own layout, and each names the other as a peer of another generation."""
    pytest.importorskip("cyclonedds")
    from fgloc.ros2 import qos
    from fgloc.ros2.transport import CycloneTransport

    from .independent import GraphPeer

    peer = GraphPeer(dds_domain)
    new = CycloneTransport(dds_domain, LOOPBACK, node_name="a", distro="jazzy")
    old = CycloneTransport(dds_domain, LOOPBACK, node_name="b", namespace="robot", distro="humble")
    try:
        new.publisher("/x", "nav_msgs/msg/Odometry", qos.DEFAULT)
        old.publisher("/x", "nav_msgs/msg/Odometry", qos.DEFAULT)
        new.start()
        old.start()
        assert wait_for(lambda: new.graph_health.other_generation == 1 and old.graph_health.other_generation == 1)
        assert any("another ROS 2 generation" in p for p in new.graph_health.problems())
        def seen() -> bool:
            info, _, ends = peer.snapshot()
            return new.gid in info and {(e[1], e[2]) for e in ends.values()} >= {
                (old.gid, "rt/x"), (new.gid, "rt/x"), (old.gid, "ros_discovery_info")}

        assert wait_for(seen)
        info, _, ends = peer.snapshot()
        assert [(n.node_namespace, n.node_name) for n in info[new.gid].node_entities_info_seq] == [("/", "a")]
        w_old = [e for e in ends.values() if e[1] == old.gid and e[2] == "rt/x"]
        w_new = [e for e in ends.values() if e[1] == new.gid and e[2] == "rt/x"]
        assert w_old[0][4] == b"" and w_new[0][4] == typehash.user_data("nav_msgs/msg/Odometry")
        assert [e[4] for e in ends.values() if e[1] == old.gid and e[2] == "ros_discovery_info"] == [b""]
    finally:
        new.close()
        old.close()
        peer.close()
    assert graph.decode(graph.encode(graph.ParticipantEntities(old.gid, [old.node]), 24), 24).nodes[0].namespace \
        == "/robot"


def test_fgloc_live_is_a_node_of_the_ros2_graph(dds_domain: int, tmp_path) -> None:
    """`fgloc live --ros2` in its own process, read by a peer written with Cyclone DDS directly: its
    participant (the one with its process id) carries ``enclave=/;``; its ros_discovery_info sample
    names one node, /fgloc, whose reader and writer GIDs are exactly its participant's ROS endpoints
    (``rt/...``) that DDS discovery shows, each with the type hash ROS 2 generated for its type."""
    pytest.importorskip("cyclonedds")
    from .independent import GraphPeer

    peer = GraphPeer(dds_domain)
    env = dict(os.environ, ROS_DISTRO="jazzy")
    out = tmp_path / "live.json"
    p = subprocess.Popen([sys.executable, "-m", "fgloc.cli", "live", "--ros2", "--domain", str(dds_domain),
                          "--interface", LOOPBACK, "--duration", "900", "--quiet", "--json"],
                         stdout=out.open("w"), stderr=subprocess.PIPE, text=True, env=env)
    try:
        def mine() -> bytes | None:
            _, parts, _ = peer.snapshot()
            for gid, (alive, props, _) in parts.items():
                if alive and props.get("__Pid") == str(p.pid):
                    return gid
            return None

        assert wait_for(lambda: mine() is not None, timeout=30), "fgloc's participant not discovered"
        gid = mine()
        assert gid is not None

        def settled() -> bool:
            info, _, ends = peer.snapshot()
            if gid not in info:
                return False
            n = info[gid].node_entities_info_seq
            ros = {k for k, e in ends.items() if e[1] == gid and e[2].startswith("rt/")}
            done = any(e[2] == "rt/fgloc/status" for k, e in ends.items() if k in ros)  # the node's last endpoint
            return done and len(n) == 1 and {bytes(g.data) for g in n[0].reader_gid_seq + n[0].writer_gid_seq} == ros

        assert wait_for(settled, timeout=20)
        info, parts, ends = peer.snapshot()
        assert parts[gid][2] == b"enclave=/;"
        node = info[gid].node_entities_info_seq[0]
        assert (node.node_namespace, node.node_name) == ("/", "fgloc")
        readers = {ends[bytes(g.data)][2] for g in node.reader_gid_seq}
        writers = {ends[bytes(g.data)][2] for g in node.writer_gid_seq}
        assert {"rt/scan", "rt/odom", "rt/tf", "rt/tf_static", "rt/map", "rt/initialpose"} <= readers
        assert all(ends[bytes(g.data)][0] == "reader" for g in node.reader_gid_seq)
        assert "rt/fgloc/status" in writers
        assert all(ends[bytes(g.data)][0] == "writer" for g in node.writer_gid_seq)
        for g in node.reader_gid_seq + node.writer_gid_seq:
            _, _, topic, dds_type, ud = ends[bytes(g.data)]
            ros_type = dds_type.replace("::dds_::", "::").replace("::", "/")[:-1]
            assert ud == f"typehash=RIHS01_{PUBLISHED[ros_type]};".encode(), (topic, ud)
        disco = [e for e in ends.values() if e[1] == gid and e[2] == "ros_discovery_info"]
        assert len(disco) == 1 and disco[0][0] == "writer"
        assert disco[0][4] == f"typehash=RIHS01_{PUBLISHED['rmw_dds_common/msg/ParticipantEntitiesInfo']};".encode()
        p.send_signal(signal.SIGTERM)  # stopped once checked (as Ctrl-C), not after a fixed time
        assert p.wait(timeout=120) == 0, p.stderr.read() if p.stderr else ""
        # the participant leaves the graph with the process (rmw's GraphCache then drops its nodes)
        assert wait_for(lambda: not peer.snapshot()[1][gid][0], timeout=15)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
        peer.close()
    report = json.loads(out.read_text())
    assert report["waiting_for"].startswith("the map")
