"""ROS 1 bags that ``rosbags`` cannot open through their index are read by walking their records.

Each case is a bag this test writes and then damages the way real recorders did: the 2010 C++
recorder's index-data length fields (20 bytes an entry for 12-byte entries), a recording killed
before its index was written (``index_pos`` 0), a file cut inside its last chunk, and the
format 1.2 bags of ROS before 1.1.  The walked bag must give the same records as the intact one.
"""

from __future__ import annotations

import logging
import struct

import numpy as np
import pytest

from fgloc.cli import main
from fgloc.errors import LogError
from fgloc.io import open_log
from fgloc.io.tum import read_tum
from fgloc.types import LaserScan, Odometry

N = 12
T0 = 1_282_836_371
TOPICS = {"/scan", "/odom", "/tf"}


def _store():
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    for name in ("tf2_msgs/msg/TFMessage", "tf/msg/tfMessage"):  # tf/tfMessage: ROS before Hydro
        if name not in ts.fielddefs:
            ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", name))
    return ts


def _messages(ts, tf_type="tf2_msgs/msg/TFMessage"):
    """``(topic, type, time ns, ROS 1 bytes)`` of a short drive: scans, odometry and tf."""
    T = ts.types
    Time, Header = T["builtin_interfaces/msg/Time"], T["std_msgs/msg/Header"]
    V3, Q = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]
    out = []
    for i in range(N):
        ns = (T0 + i // 4) * 10**9 + (i % 4) * 250_000_000
        stamp = Time(sec=ns // 10**9, nanosec=ns % 10**9)
        ranges = np.linspace(0.5, 5.0 + i, 61).astype(np.float32)
        scan = T["sensor_msgs/msg/LaserScan"](
            header=Header(seq=i, stamp=stamp, frame_id="laser"), angle_min=-1.5, angle_max=1.5,
            angle_increment=0.05, time_increment=0.0, scan_time=0.1, range_min=0.1, range_max=30.0,
            ranges=ranges, intensities=np.zeros(0, np.float32))
        odom = T["nav_msgs/msg/Odometry"](
            header=Header(seq=i, stamp=stamp, frame_id="odom"), child_frame_id="base_link",
            pose=T["geometry_msgs/msg/PoseWithCovariance"](
                pose=T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=0.1 * i, y=0.0, z=0.0),
                                                 orientation=Q(x=0.0, y=0.0, z=0.0, w=1.0)),
                covariance=np.zeros(36)),
            twist=T["geometry_msgs/msg/TwistWithCovariance"](
                twist=T["geometry_msgs/msg/Twist"](linear=V3(x=0.4, y=0.0, z=0.0), angular=V3(x=0.0, y=0.0, z=0.0)),
                covariance=np.zeros(36)))
        tf = T[tf_type](transforms=[T["geometry_msgs/msg/TransformStamped"](
            header=Header(seq=0, stamp=stamp, frame_id="base_link"), child_frame_id="laser",
            transform=T["geometry_msgs/msg/Transform"](translation=V3(x=0.2, y=0.0, z=0.1),
                                                       rotation=Q(x=0.0, y=0.0, z=0.0, w=1.0)))])
        # odometry written before the scan of the same time: ties stay in file order
        for topic, msg in (("/odom", odom), ("/scan", scan), ("/tf", tf)):
            out.append((topic, msg.__msgtype__, ns + (i % 3) * 1000, ts.serialize_ros1(msg, msg.__msgtype__)))
    return out


def _write_v2(path, chunk_bytes=None, bz2=False, by_topic=False, tf_type="tf2_msgs/msg/TFMessage"):
    """``by_topic``: every message of one topic before the next's (a script's bag: file order is
    not time order, the chunks' times overlap)."""
    from rosbags.rosbag1 import Writer

    ts = _store()
    msgs = _messages(ts, tf_type)
    if by_topic:
        msgs = sorted(msgs, key=lambda m: m[0])
    w = Writer(path)
    if chunk_bytes is not None:
        w.chunk_threshold = chunk_bytes
    if bz2:
        w.set_compression(Writer.CompressionFormat.BZ2)
    with w:
        conns = {}
        for topic, typ, t, raw in msgs:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, typ, typestore=ts)
            w.write(conns[topic], t, raw)
    return msgs


def _fields(header: bytes) -> dict[str, bytes]:
    out, i = {}, 0
    while i < len(header):
        (n,) = struct.unpack_from("<I", header, i)
        k, v = header[i + 4:i + 4 + n].split(b"=", 1)
        out[k.decode()] = v
        i += 4 + n
    return out


def _top_records(data: bytes):
    """``(offset, fields, data start, data length)`` of a format 2.0 bag's top-level records."""
    pos = data.index(b"\n") + 1
    while pos < len(data):
        (hlen,) = struct.unpack_from("<I", data, pos)
        (dlen,) = struct.unpack_from("<I", data, pos + 4 + hlen)
        yield pos, _fields(data[pos + 4:pos + 4 + hlen]), pos + 8 + hlen, dlen
        pos += 8 + hlen + dlen


def _records(path):
    with open_log(path) as src:
        return [(r.topic, r.log_time_ns, r.msg) for r in src.records(TOPICS)]


def _same(got, want):
    assert [(t, ns) for t, ns, _ in got] == [(t, ns) for t, ns, _ in want]
    for (_, _, a), (_, _, b) in zip(got, want, strict=True):
        assert type(a) is type(b)
        if isinstance(a, LaserScan):
            assert a.stamp == b.stamp
            np.testing.assert_array_equal(a.ranges, b.ranges)
        elif isinstance(a, Odometry):
            assert a.stamp == b.stamp and np.array_equal(a.pose, b.pose)


def test_index_lengths_of_the_2010_recorder(tmp_path, caplog, capsys):
    """Its index-data records say 20 bytes an entry; the entries are 12 (ROS's reader goes by the
    count).  ``rosbags`` asserted: a traceback from ``fgloc info``."""
    good, bad = tmp_path / "good.bag", tmp_path / "c_turtle.bag"
    _write_v2(good, chunk_bytes=2000)
    data = bytearray(good.read_bytes())
    n_index = 0
    for _pos, f, start, dlen in list(_top_records(bytes(data))):
        if f["op"] == b"\x04":
            count = struct.unpack("<I", f["count"])[0]
            assert dlen == 12 * count
            struct.pack_into("<I", data, start - 4, 20 * count)
            n_index += 1
    assert n_index >= 6  # several chunks, each with its connections' index records
    bad.write_bytes(bytes(data))
    want = _records(good)
    assert len(want) == 3 * N
    with caplog.at_level(logging.WARNING):
        src = open_log(bad)
    assert f"{n_index} index record(s) with a wrong length field" in caplog.text
    s = src.summary()
    assert s["messages"] == 3 * N and s["indexed"] is False and s["truncated"] is None
    assert {t: v["count"] for t, v in s["topics"].items()} == {"/scan": N, "/odom": N, "/tf": N}
    assert s["start"] == open_log(good).summary()["start"]
    _same(_records(bad), want)
    assert open_log(bad).laser_mount().pose == pytest.approx([0.2, 0.0, 0.0])
    assert main(["info", str(bad)]) == 0
    assert f"rosbag1, {3 * N} messages" in capsys.readouterr().out


@pytest.mark.parametrize("bz2", [False, True])
def test_recording_killed_before_its_index(tmp_path, bz2):
    """``index_pos`` 0 and no index section (a ``.bag.active`` file): every chunk is read."""
    good, active = tmp_path / "good.bag", tmp_path / "run.bag.active"
    _write_v2(good, chunk_bytes=2000, bz2=bz2)
    _unindexed(good, active)
    src = open_log(active)
    assert src.summary()["indexed"] is False and src.truncated is None
    _same(_records(active), _records(good))


def _unindexed(good, path):
    """``good`` with ``index_pos`` 0 and its index section cut off (a killed recording)."""
    data = bytearray(good.read_bytes())
    recs = list(_top_records(bytes(data)))
    first_conn_outside = min(pos for pos, f, _, _ in recs if f["op"] == b"\x07")
    i = data.index(b"index_pos=", recs[0][0])
    struct.pack_into("<Q", data, i + len("index_pos="), 0)
    path.write_bytes(bytes(data[:first_conn_outside]))


def test_walked_messages_come_in_time_order(tmp_path):
    """A bag written topic by topic (all scans, then all odometry, ...) in small chunks: the
    walked bag gives the records in log-time order, as the indexed read does."""
    good, walked = tmp_path / "good.bag", tmp_path / "walked.bag"
    _write_v2(good, chunk_bytes=1500, by_topic=True)
    _unindexed(good, walked)
    want = _records(good)
    times = [ns for _, ns, _ in want]
    assert times == sorted(times) and [t for t, _, _ in want][:3] == ["/odom", "/scan", "/tf"]
    assert open_log(walked).summary()["indexed"] is False
    _same(_records(walked), want)


def test_file_cut_inside_its_last_chunk(tmp_path, caplog):
    """The complete messages of an uncompressed chunk the file ends in are read; where it broke
    is reported."""
    good, cut = tmp_path / "good.bag", tmp_path / "cut.bag"
    _write_v2(good, chunk_bytes=2000)
    data = good.read_bytes()
    chunks = [(pos, start, dlen) for pos, f, start, dlen in _top_records(data) if f["op"] == b"\x05"]
    pos, start, dlen = chunks[-1]
    cut.write_bytes(data[:start + dlen // 2])
    want = _records(good)
    with caplog.at_level(logging.WARNING):
        src = open_log(cut)
    assert src.truncated is not None and f"inside a record starting at byte {pos}" in src.truncated
    got = _records(cut)
    assert 0 < len(got) < len(want)
    assert src.truncated.endswith(f"; {len(got)} complete messages read")
    assert "the file is cut short" in caplog.text
    # every complete chunk and the complete part of the cut one: the first messages of the log
    assert len(got) > sum(1 for t, ns, _ in want if ns < _chunk_start_ns(data, pos))
    _same(got, [w for w in want if (w[0], w[1]) in {(t, ns) for t, ns, _ in got}])
    assert "read by walking its records" in caplog.text


def _chunk_start_ns(data: bytes, chunk_pos: int) -> int:
    for _pos, f, _start, _dlen in _top_records(data):
        if f["op"] == b"\x06" and struct.unpack("<Q", f["chunk_pos"])[0] == chunk_pos:
            sec, nsec = struct.unpack("<II", f["start_time"])
            return sec * 10**9 + nsec
    raise AssertionError("no chunk info for that chunk")


def _record(fields: dict[str, bytes], data: bytes = b"") -> bytes:
    head = b"".join(struct.pack("<I", len(k) + 1 + len(v)) + k.encode() + b"=" + v for k, v in fields.items())
    return struct.pack("<I", len(head)) + head + struct.pack("<I", len(data)) + data


def _write_v12(path, msgs, ts):
    """A format 1.2 bag (``#ROSRECORD V1.2``, ROS before 1.1): a file header record padded to
    4096 bytes, a definition record before each topic's first message, the index at the end."""
    out = bytearray(b"#ROSRECORD V1.2\n")
    out += b"\x00" * 4096  # the file header record, written last
    seen: dict[str, list[tuple[int, int]]] = {}
    for topic, typ, t, raw in msgs:
        ros1 = typ.replace("/msg/", "/")
        definition, md5 = (x.encode() for x in ts.generate_msgdef(typ))
        if topic not in seen:
            out += _record({"op": b"\x01", "topic": topic.encode(), "md5": md5, "type": ros1.encode(),
                            "def": definition})
            seen[topic] = []
        seen[topic].append((t, len(out)))
        out += _record({"op": b"\x02", "topic": topic.encode(), "md5": md5, "type": ros1.encode(),
                        "sec": struct.pack("<I", t // 10**9), "nsec": struct.pack("<I", t % 10**9)}, raw)
    index_pos = len(out)
    for topic, entries in seen.items():
        typ = next(m[1] for m in msgs if m[0] == topic).replace("/msg/", "/")
        body = b"".join(struct.pack("<IIQ", t // 10**9, t % 10**9, p) for t, p in entries)
        out += _record({"op": b"\x04", "ver": struct.pack("<I", 0), "topic": topic.encode(),
                        "type": typ.encode(), "count": struct.pack("<I", len(entries))}, body)
    header = _record({"op": b"\x03", "index_pos": struct.pack("<Q", index_pos)})
    header = header[:-4] + struct.pack("<I", 4096 - len(header)) + b" " * (4096 - len(header))
    out[16:16 + 4096] = header
    path.write_bytes(bytes(out))


def test_format_1_2_bag(tmp_path, capsys):
    good, old = tmp_path / "good.bag", tmp_path / "rosrecord.bag"
    msgs = _write_v2(good)
    _write_v12(old, msgs, _store())
    src = open_log(old)
    assert src.format == "rosbag1" and src.summary()["messages"] == 3 * N
    _same(_records(old), _records(good))
    assert main(["info", str(old)]) == 0
    assert f"{N}  nav_msgs/msg/Odometry" in capsys.readouterr().out


def test_relative_topic_names_are_the_root_namespaces(tmp_path, capsys, caplog):
    """A recorder that stored relative names (``scan``, ``odom``, ``tf``: format-1.2 bags, The
    Construct's ``laser_scan``) is read under the names ROS resolves them to (``/scan`` ...): the
    default topics match with no fallback said, and a name given with its slash is found (before:
    ``--scan-topic /laser_scan`` was "no such topic" on a bag listing ``laser_scan``)."""
    good, old = tmp_path / "good.bag", tmp_path / "relative.bag"
    msgs = _write_v2(good)
    _write_v12(old, [(t.lstrip("/"), typ, ns, raw) for t, typ, ns, raw in msgs], _store())
    src = open_log(old)
    assert sorted(src.summary()["topics"]) == ["/odom", "/scan", "/tf"]
    _same(_records(old), _records(good))
    assert main(["info", str(old)]) == 0
    assert [ln.split()[0] for ln in capsys.readouterr().out.splitlines()[1:]] == ["/odom", "/scan", "/tf"]
    caplog.clear()
    out = tmp_path / "run"
    assert main(["run", str(old), "-o", str(out), "-q", "--scan-topic", "/scan", "--odom-topic", "/odom"]) == 0
    assert not [r for r in caplog.records if "the log's only topic of that type" in r.getMessage()]
    assert len(read_tum(out / "trajectory.tum")) > 0


def _message_records(data: bytes):
    """``(offset of the header, data start, fields)`` of the message records in a format 2.0
    bag's uncompressed chunks, in file order."""
    out = []
    for _pos, f, start, dlen in _top_records(data):
        if f["op"] != b"\x05":
            continue
        assert f["compression"] == b"none"
        p = start
        while p < start + dlen:
            (hlen,) = struct.unpack_from("<I", data, p)
            g = _fields(data[p + 4:p + 4 + hlen])
            (n,) = struct.unpack_from("<I", data, p + 4 + hlen)
            if g["op"] == b"\x02":
                out.append((p, p + 8 + hlen, g))
            p += 8 + hlen + n
    return out


@pytest.mark.parametrize("damage", ["op", "length"])
@pytest.mark.parametrize("indexed", [True, False])
def test_damaged_message_record_is_skipped(tmp_path, caplog, damage, indexed):
    """One damaged message record (its op byte, or its data length) in the middle of a bag:
    every other message is read (before: the read stopped there, the rest of the log lost)."""
    good, bad = tmp_path / "good.bag", tmp_path / "bad.bag"
    _write_v2(good, chunk_bytes=2000)
    data = bytearray(good.read_bytes())
    recs = _message_records(bytes(data))
    at, data_start, f = recs[len(recs) // 2]
    if damage == "op":
        i = data.index(b"op=\x02", at)
        data[i + 3] = 0x09
    else:
        struct.pack_into("<I", data, data_start - 4, 0x7FFFFFFF)
    bad.write_bytes(bytes(data))
    if not indexed:
        unindexed = tmp_path / "bad.bag.active"
        _unindexed(bad, unindexed)
        bad = unindexed
    t_lost = struct.unpack("<II", f["time"])
    lost_ns = t_lost[0] * 10**9 + t_lost[1]
    want = _records(good)
    with caplog.at_level(logging.WARNING):
        src = open_log(bad)
        got = [(r.topic, r.log_time_ns, r.msg) for r in src.records(TOPICS)]
    assert len(got) == len(want) - 1
    assert [(t, ns) for t, ns, _ in want if (t, ns) not in {(a, b) for a, b, _ in got}] == [
        (next(t for t, ns, _ in want if ns == lost_ns), lost_ns)]
    _same(got, [w for w in want if w[1] != lost_ns or (w[0], w[1]) in {(a, b) for a, b, _ in got}])
    assert src.truncated is None and src.damage() == "1 damaged chunk(s) skipped"
    assert "damaged record at byte" in caplog.text
    if indexed:
        assert "the rest read by walking its records" in caplog.text


def test_chunk_that_does_not_decompress(tmp_path, caplog):
    """A bz2 chunk whose bytes are damaged: its messages are lost, every other chunk's read."""
    good, bad = tmp_path / "good.bag", tmp_path / "bad.bag"
    _write_v2(good, chunk_bytes=2000, bz2=True)
    data = bytearray(good.read_bytes())
    chunks = [(pos, start, dlen) for pos, f, start, dlen in _top_records(bytes(data)) if f["op"] == b"\x05"]
    pos, start, dlen = chunks[len(chunks) // 2]
    for i in range(start + dlen // 3, start + dlen // 3 + 32):
        data[i] ^= 0xFF
    bad.write_bytes(bytes(data))
    want = _records(good)
    with caplog.at_level(logging.WARNING):
        src = open_log(bad)
        got = [(r.topic, r.log_time_ns, r.msg) for r in src.records(TOPICS)]
    assert 0 < len(want) - len(got) < len(want) // 2
    _same(got, [w for w in want if (w[0], w[1]) in {(a, b) for a, b, _ in got}])
    assert f"chunk at byte {pos}: chunk does not decompress" in caplog.text
    assert src.truncated is None and src.damage() == "1 damaged chunk(s) skipped"


@pytest.mark.parametrize("fmt", ["2.0", "1.2"])
def test_tf_of_ros_before_hydro(tmp_path, fmt, caplog):
    """``/tf`` as ``tf/tfMessage`` (every bag before 2013) is read as tf: the laser mount comes
    from it, and no warning says the topic is skipped or the laser assumed at the centre."""
    new, old = tmp_path / "tf2.bag", tmp_path / f"tf_{fmt}.bag"
    _write_v2(new)
    if fmt == "2.0":
        _write_v2(old, tf_type="tf/msg/tfMessage")
    else:
        _write_v12(old, _messages(_store(), "tf/msg/tfMessage"), _store())
    with caplog.at_level(logging.INFO):
        src = open_log(old)
        assert src.topic_types()["/tf"] == "tf2_msgs/msg/TFMessage"
        assert src.laser_mount().pose == pytest.approx([0.2, 0.0, 0.0])
    assert "skipped" not in caplog.text and "robot centre" not in caplog.text
    got, want = _records(old), _records(new)
    _same(got, want)
    tfs = [(m[0].parent, m[0].child, m[0].pose.tolist()) for t, _, m in got if t == "/tf"]
    assert tfs == [("base_link", "laser", pytest.approx([0.2, 0.0, 0.0]))] * N


def test_encrypted_bag_is_a_one_line_error(tmp_path, capsys):
    """``rosbag encrypt``'s bags (an ``encryptor`` in the bag header): no attempt to walk
    ciphertext, one line that says what to do."""
    good, enc = tmp_path / "good.bag", tmp_path / "secret.bag"
    _write_v2(good)
    data = good.read_bytes()
    pos, f, start, dlen = next(_top_records(data))
    assert f["op"] == b"\x03"
    fields = {"encryptor": b"rosbag/AesCbcEncryptor", **f}
    head = b"".join(struct.pack("<I", len(k) + 1 + len(v)) + k.encode() + b"=" + v for k, v in fields.items())
    size = start + dlen - pos  # the header record keeps its size: the padding shrinks
    record = struct.pack("<I", len(head)) + head
    record += struct.pack("<I", size - len(record) - 4) + b" " * (size - len(record) - 4)
    enc.write_bytes(data[:pos] + record + data[pos + size:])
    assert main(["info", str(enc)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert f"{enc}: encrypted ROS 1 bag (rosbag/AesCbcEncryptor); decrypt it first" in err


def test_unread_bag_versions_are_one_line_errors(tmp_path, capsys):
    old = tmp_path / "ancient.bag"
    old.write_bytes(b"#ROSRECORD V1.1\n" + b"\x00" * 64)
    with pytest.raises(LogError, match=r"ROS 1 bag format '#ROSRECORD V1.1' is not read"):
        open_log(old)
    assert main(["info", str(old)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(old) in err and "Traceback" not in err
    garbage = tmp_path / "garbage.bag"  # the right first line, then no record that parses
    garbage.write_bytes(b"#ROSBAG V2.0\n" + b"\xff" * 64)
    assert main(["info", str(garbage)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(garbage) in err and "Traceback" not in err
