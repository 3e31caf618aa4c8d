"""The fixed-layout CDR codecs against the generic ones.

Encoders: byte-identical to mcap_ros2's generic encoder.  Decoders: field-identical (every
float bit, every NaN, every dtype) to mcap_ros2's generic decoder followed by fgloc.io.ros's
conversion, on every message of fgloc's own logs, the bundled Radish excerpts, and foreign logs
written by mcap_ros2 and by rosbags (the conformance generators), including empty arrays, odd
string lengths, and big-endian CDR (which the fixed layouts decline and the generic codec
reads).
"""

from __future__ import annotations

import io
import math
import os
import struct
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from fgloc.io import fastcdr, open_log
from fgloc.io.msgdefs import full_text
from fgloc.io.ros import (
    FROM_ROS,
    compass_to_ros,
    fix_to_ros,
    imu_to_ros,
    odom_to_ros,
    scan_to_ros,
    tf_flips,
    tf_to_ros,
)
from fgloc.io.topics import IMU, LASER_SCAN, ODOMETRY, POSE_COV_STAMPED, TF_MESSAGE
from fgloc.types import CompassHeading, Imu, LaserScan, Odometry, PoseFix, StaticTransform, Transform3D

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import test_conformance as conf  # noqa: E402 - the foreign-log generators

# fuzz examples are derandomized (CI must be reproducible); FGLOC_FUZZ_RANDOM=1 hunts with fresh ones
FUZZ_RANDOM = bool(os.environ.get("FGLOC_FUZZ_RANDOM"))

FAST: dict[str, Callable[[list[bytes]], list[Any]]] = {
    LASER_SCAN: fastcdr.decode_laser_scans,
    ODOMETRY: fastcdr.decode_odometries,
    IMU: fastcdr.decode_imus,
    TF_MESSAGE: fastcdr.decode_tf_messages,
    POSE_COV_STAMPED: lambda d: fastcdr.decode_pose_fixes(d, "/t"),
}
ENCODE = {
    LASER_SCAN: (fastcdr.encode_laser_scan, scan_to_ros),
    ODOMETRY: (fastcdr.encode_odometry, odom_to_ros),
    IMU: (fastcdr.encode_imu, imu_to_ros),
    TF_MESSAGE: (fastcdr.encode_tf, tf_to_ros),
    POSE_COV_STAMPED: (fastcdr.encode_pose_fix, fix_to_ros),
}


def _generic_decoder(type_name: str, schema_text: str | None = None) -> Callable[[bytes], Any]:
    from mcap.records import Schema
    from mcap_ros2.decoder import DecoderFactory

    text = schema_text if schema_text and schema_text.strip() else full_text(type_name)
    dec = DecoderFactory().decoder_for("cdr", Schema(id=1, name=type_name, encoding="ros2msg", data=text.encode()))
    assert dec is not None
    return dec  # type: ignore[no-any-return]


def _generic(type_name: str, data: bytes, dec: Callable[[bytes], Any], topic: str = "/t") -> Any:
    ros = dec(data)
    out = FROM_ROS[type_name](ros, topic)
    return (out, tf_flips(ros)) if type_name == TF_MESSAGE else out


def _same_float(a: float, b: float) -> bool:
    return struct.pack("<d", a) == struct.pack("<d", b) or (math.isnan(a) and math.isnan(b))


def assert_identical(a: Any, b: Any, where: str = "") -> None:
    """Field-identical: same types, same bits of every float, same arrays (dtype, NaNs)."""
    assert type(a) is type(b), where
    if isinstance(a, list | tuple):
        assert len(a) == len(b), where
        for x, y in zip(a, b, strict=True):
            assert_identical(x, y, where)
    elif isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and a.shape == b.shape, where
        assert a.tobytes() == b.tobytes() or np.array_equal(a, b, equal_nan=True), where
    elif isinstance(a, float):
        assert _same_float(a, b), (where, a, b)
    elif hasattr(a, "__dataclass_fields__"):
        for f in a.__dataclass_fields__:
            assert_identical(getattr(a, f), getattr(b, f), f"{where}.{f}")
    else:
        assert a == b, (where, a, b)


def check_all(type_name: str, datas: list[bytes], schema_text: str | None = None) -> int:
    """Fast (as one batch and one by one) == generic on every message; returns how many the
    fast decoder took (the rest it declined, and the generic one must read them)."""
    dec = _generic_decoder(type_name, schema_text)
    batch = FAST[type_name](datas)
    taken = 0
    for i, data in enumerate(datas):
        (single,) = FAST[type_name]([data])
        assert_identical(batch[i], single, f"{type_name} #{i} batch vs single")
        if batch[i] is None:
            continue
        taken += 1
        assert_identical(batch[i], _generic(type_name, data, dec), f"{type_name} #{i}")
    return taken


# ---------------------------------------------------------------------------------------------
# generic encoding through mcap_ros2's public writer, read back with mcap's reader
def _generic_bytes(type_name: str, ros: list[dict]) -> list[bytes]:
    from mcap.reader import make_reader
    from mcap_ros2.writer import Writer

    buf = io.BytesIO()
    w = Writer(buf)
    schema = w.register_msgdef(type_name, full_text(type_name))
    for i, d in enumerate(ros):
        w.write_message("/t", schema, d, log_time=i)
    w.finish()
    buf.seek(0)
    return [m.data for _, _, m in make_reader(buf).iter_messages(log_time_order=False)]


FRAMES = ["", "l", "la", "las", "lase", "laser", "base_laser_link", "ü/frame"]


def _samples(rng: np.random.Generator) -> dict[str, list[tuple[object, float]]]:
    out: dict[str, list[tuple[object, float]]] = {t: [] for t in ENCODE}
    for k, frame in enumerate(FRAMES):
        st = 1_700_000_000.0 + k + (k * 1_000_003 + 7) * 1e-9
        for n, inten in ((0, False), (1, True), (181, False), (1081, True)):
            r = rng.uniform(0, 30, n).astype(np.float32)
            if n > 3:
                r[:3] = [np.inf, -np.inf, np.nan]
            out[LASER_SCAN].append((LaserScan(st, -2.35, 0.0043633, 0.05, 40.0, r, 1e-5, 0.04,
                                              rng.uniform(0, 1, n).astype(np.float32) if inten else None,
                                              frame), st))
        c = np.diag(rng.uniform(1e-4, 1e-2, 3))
        c[0, 2] = c[2, 0] = 1e-5
        out[ODOMETRY] += [
            (Odometry(st, rng.normal(size=3), c, rng.normal(size=3), c * 2, frame, FRAMES[-1 - k]), st),
            (Odometry(st, rng.normal(size=3), None, None, None, frame, ""), st),      # no pose, unknown cov
            (Odometry(st, np.zeros(3), None, np.array([1.0, 2.0, math.pi]), None, "odom", frame), st),
        ]
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        c3 = np.diag(rng.uniform(1e-6, 1e-2, 3))
        c3[0, 1] = c3[1, 0] = 1e-7
        out[IMU] += [
            (Imu(st, q, rng.normal(size=3), c3, c3 * 0.1, rng.normal(size=3), c3 * 10, frame), st),
            (Imu(st, None, rng.normal(size=3), None, c3, None, None, frame), st),    # REP 145: no orientation
            (Imu(st, q, None, c3, None, rng.normal(size=3), None, frame), st),       # nor rates, unknown cov
            (Imu(st, np.zeros(4), np.zeros(3), np.full((3, 3), np.nan), None, np.zeros(3), None, frame), st),
            (Imu(st, q * 1.5, np.zeros(3), None, None, None, None, frame), st),      # not unit: kept for the router
        ]
        out[POSE_COV_STAMPED] += [(PoseFix(st, rng.normal(size=3), c, frame_id=frame), st),
                                  (PoseFix(st, rng.normal(size=3), np.zeros((3, 3)), frame_id=frame), st)]
        out[TF_MESSAGE] += [
            ([_tf3(frame, FRAMES[j % len(FRAMES)], rng) for j in range(k)], st),  # 0 .. 7 transforms
        ]
    return out


def _tf3(parent: str, child: str, rng: np.random.Generator) -> Transform3D:
    """A transform as the readers give it: its whole rotation (here any 3-D one) and its yaw."""
    from fgloc.geometry import quaternion_to_yaw

    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    xy = rng.normal(size=2)
    return Transform3D(parent, child, np.array([xy[0], xy[1], quaternion_to_yaw(*q)]), float(rng.normal()), q)


@pytest.fixture(scope="module")
def samples() -> dict[str, list[tuple[object, float]]]:
    return _samples(np.random.default_rng(3))


@pytest.mark.parametrize("type_name", list(ENCODE))
def test_encoders_byte_identical_to_generic(type_name, samples):
    enc, to_ros = ENCODE[type_name]
    msgs = samples[type_name]
    fast = [enc(m, st) for m, st in msgs]
    assert fast == _generic_bytes(type_name, [to_ros(m, st) for m, st in msgs])  # type: ignore[operator]


@pytest.mark.parametrize("type_name", list(ENCODE))
def test_decoders_identical_to_generic_on_fgloc_bytes(type_name, samples):
    enc, _ = ENCODE[type_name]
    datas = [enc(m, st) for m, st in samples[type_name]]  # type: ignore[operator]
    assert check_all(type_name, datas) == len(datas)  # all standard little-endian: none declined


# ---------------------------------------------------------------------------------------------
# big-endian, other representations, garbage: declined (None), never misread
def _big_endian(type_name: str, ros_msgs: list[Any]) -> list[bytes]:
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    if type_name not in ts.types:
        from rosbags.typesys import get_types_from_msg

        ts.register(get_types_from_msg(full_text(type_name), type_name))
    out = []
    for le in ros_msgs:
        msg = ts.deserialize_cdr(le, type_name)
        out.append(bytes(ts.serialize_cdr(msg, type_name, little_endian=False)))
    return out


@pytest.mark.parametrize("type_name", list(ENCODE))
def test_big_endian_is_declined_and_read_by_the_generic_codec(type_name, samples, tmp_path):
    enc, _ = ENCODE[type_name]
    le = [enc(m, st) for m, st in samples[type_name]]  # type: ignore[operator]
    be = _big_endian(type_name, le)
    assert all(b[:2] == b"\x00\x00" for b in be)
    assert FAST[type_name](be) == [None] * len(be)
    dec = _generic_decoder(type_name)
    for a, b in zip(le, be, strict=True):  # the generic codec reads both to the same values
        assert_identical(_generic(type_name, a, dec), _generic(type_name, b, dec))
    # and the reader uses it: a log of big-endian messages reads as the little-endian one
    from mcap.writer import Writer

    for name, datas in (("le", le), ("be", be)):
        with (tmp_path / f"{name}.mcap").open("wb") as f:
            w = Writer(f)
            w.start(profile="ros2", library="test")
            sid = w.register_schema(type_name, "ros2msg", full_text(type_name).encode())
            cid = w.register_channel("/t", "cdr", sid)
            for i, d in enumerate(datas):
                w.add_message(cid, i, d, i)
            w.finish()
    got = [[r.msg for r in open_log(tmp_path / f"{n}.mcap").records({"/t"})] for n in ("le", "be")]
    assert len(got[0]) == len(got[1]) == len(le)
    for a, b in zip(*got, strict=True):
        if type_name == POSE_COV_STAMPED:
            a.source = b.source = ""  # type: ignore[union-attr]
        assert_identical(a, b)


@pytest.mark.parametrize("type_name", list(ENCODE))
def test_garbage_is_declined_not_misread(type_name, samples):
    enc, _ = ENCODE[type_name]
    data = enc(*samples[type_name][-1])  # type: ignore[operator]
    s = 16 if type_name == TF_MESSAGE else 12  # the first string length
    bad = [b"", b"\x00\x01", b"\x00\x01\x00\x00", data[: len(data) // 2], b"\x00\x03" + data[2:],
           data[:s] + b"\xff\xff\xff\x7f" + data[s + 4:]]  # a frame id length far past the end
    assert FAST[type_name](bad) == [None] * len(bad)


@pytest.mark.parametrize("type_name", list(ENCODE))
def test_damaged_bytes_never_decode_differently(type_name, samples):
    """Any byte changed anywhere: the fixed layout declines, or gives what the generic codec gives."""
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as hs

    enc, _ = ENCODE[type_name]
    datas = [enc(m, st) for m, st in samples[type_name][:12]]  # type: ignore[operator]
    dec = _generic_decoder(type_name)

    @settings(max_examples=150, deadline=None, suppress_health_check=list(HealthCheck), derandomize=not FUZZ_RANDOM)
    @given(hs.integers(0, len(datas) - 1), hs.integers(0, 10**6), hs.integers(0, 255), hs.booleans())
    def check(k: int, pos: int, value: int, cut: bool) -> None:
        d = bytearray(datas[k])
        pos %= max(len(d), 1)
        d[pos] = value
        data = bytes(d[:pos] if cut else d)
        (fast,) = FAST[type_name]([data])
        if fast is None:
            return
        try:
            ref = _generic(type_name, data, dec)
        except Exception:  # noqa: BLE001 - the generic codec fails: the fast one must have declined
            pytest.fail(f"fixed layout read bytes the generic codec rejects (byte {pos} = {value}, cut {cut})")
        assert_identical(fast, ref)

    check()


# ---------------------------------------------------------------------------------------------
# every message of real and foreign logs
def _by_channel(path: Path) -> dict[tuple[str, str, str], list[bytes]]:
    out: dict[tuple[str, str, str], list[bytes]] = {}
    src = open_log(path)
    for rec in src.records(src.topic_types()):
        ch = rec.channel
        assert rec.data is not None and ch is not None
        out.setdefault((ch.topic, ch.type, ch.schema_data.decode()), []).append(rec.data)
    return out


@pytest.fixture(scope="module")
def foreign_logs(tmp_path_factory) -> list[Path]:
    from fgloc.io.convert import import_log
    from fgloc.sim import simulate_paper, write_sim

    d = tmp_path_factory.mktemp("fastcdr")
    sim = simulate_paper(seed=0, route=conf.ROUTE)
    logs = []
    for name, v in (("clean", {}), ("everything", conf.VARIANTS["everything"]),
                    ("lz4", conf.VARIANTS["lz4_small_chunks_intensities"]),
                    ("upside_down", conf.VARIANTS["upside_down_laser_on_tf"]),
                    ("rosbags_mcap", {"writer": "rosbags", "mount": "tf", "scan": "360", "imu": "no_orientation"}),
                    ("rosbags_db3", {"writer": "db3", "mount": "chain", "ground_truth": True})):
        p = d / (f"{name}.mcap" if "writer" not in v else name)
        conf.write_foreign(p, sim, **v)
        logs.append(p)
    write_sim(sim, d / "sim")
    logs += sorted((d / "sim").glob("*.mcap"))
    here = Path(__file__).resolve().parents[2] / "data" / "radish"
    for clf in sorted(here.glob("*.clf.bz2")):
        logs.append(import_log(clf, d / (clf.name + ".mcap"), progress=False).dst)
    return logs


def test_every_message_of_foreign_and_bundled_logs(foreign_logs):
    seen: dict[str, int] = {}
    for path in foreign_logs:
        for (topic, type_name, schema), datas in _by_channel(path).items():
            if type_name not in FAST:
                continue
            taken = check_all(type_name, datas, schema)
            assert taken == len(datas), f"{path.name} {topic}: {len(datas) - taken} declined"
            seen[type_name] = seen.get(type_name, 0) + taken
    assert set(seen) >= {LASER_SCAN, ODOMETRY, IMU, TF_MESSAGE}
    assert seen[LASER_SCAN] > 3000 and seen[ODOMETRY] > 5000 and seen[IMU] > 2000


# ---------------------------------------------------------------------------------------------
# foreign bytes of every type: rosbags' own CDR serializer (little-endian)
@pytest.mark.parametrize("type_name", list(ENCODE))
def test_decoders_identical_to_generic_on_rosbags_bytes(type_name, samples):
    """The samples (empty arrays, frame ids of 0..7 bytes and multi-byte UTF-8, no pose / no
    orientation / unknown covariances, 0..7 transforms) serialized by rosbags, not by fgloc:
    every one taken by the fixed layout and read as the generic codec reads it."""
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    enc, _ = ENCODE[type_name]
    datas = []
    for m, st in samples[type_name]:
        msg = ts.deserialize_cdr(enc(m, st), type_name)  # type: ignore[operator]
        datas.append(bytes(ts.serialize_cdr(msg, type_name, little_endian=True)))
    assert check_all(type_name, datas) == len(datas)


# ---------------------------------------------------------------------------------------------
# the reader: fixed layouts batched per chunk and channel == the generic codec message by message
def _records(path: Path, generic: bool, monkeypatch) -> tuple[list, Any]:
    import fgloc.io.mcap_reader as mr

    with monkeypatch.context() as mp:
        if generic:  # no channel gets a fixed-layout decoder: every message through mcap_ros2
            mp.setattr(mr, "is_standard", lambda *a: False)
        src = open_log(path)
        recs = [(r.topic, r.log_time_ns, r.msg) for r in src.records(src.topic_types())]
        mount = src.laser_mount() if src.has("/scan") else None
    return recs, mount


def test_reader_fast_path_equals_the_generic_reader(foreign_logs, monkeypatch):
    """Every MCAP log (fgloc's, mcap_ros2's and rosbags' foreign ones, the bundled Radish
    excerpts): the same records in the same order, field-identical, and the same laser mount."""
    n = 0
    for path in foreign_logs:  # (the rosbag2 SQLite folder has no fixed layouts: the same both ways)
        fast, mount_fast = _records(path, False, monkeypatch)
        slow, mount_slow = _records(path, True, monkeypatch)
        assert len(fast) == len(slow) > 0, path.name
        for a, b in zip(fast, slow, strict=True):
            assert a[:2] == b[:2], path.name
            assert_identical(a[2], b[2], f"{path.name} {a[0]} {a[1]}")
        assert_identical(mount_fast, mount_slow, path.name)
        n += len(fast)
    assert n > 15_000


def _write_log(path: Path, type_name: str, datas: list[bytes], schema_text: str | None = None) -> None:
    from mcap.writer import Writer

    with path.open("wb") as f:
        w = Writer(f)
        w.start(profile="ros2", library="test")
        sid = w.register_schema(type_name, "ros2msg", (schema_text or full_text(type_name)).encode())
        cid = w.register_channel("/t", "cdr", sid)
        for i, d in enumerate(datas):
            w.add_message(cid, i, d, i)
        w.finish()


@pytest.mark.parametrize("type_name", list(ENCODE))
def test_big_endian_messages_among_little_endian_ones(type_name, samples, tmp_path):
    """One channel, one chunk, every other message big-endian: the batch decoder declines those
    and the generic codec reads them in place (order and values as the all-little-endian log)."""
    enc, _ = ENCODE[type_name]
    le = [enc(m, st) for m, st in samples[type_name]]  # type: ignore[operator]
    be = _big_endian(type_name, le)
    mixed = [b if i % 2 else a for i, (a, b) in enumerate(zip(le, be, strict=True))]
    assert FAST[type_name](mixed)[1::2] == [None] * len(mixed[1::2])
    _write_log(tmp_path / "le.mcap", type_name, le)
    _write_log(tmp_path / "mixed.mcap", type_name, mixed)
    got = [[r.msg for r in open_log(tmp_path / f"{n}.mcap").records({"/t"})] for n in ("le", "mixed")]
    assert len(got[0]) == len(got[1]) == len(le)
    for a, b in zip(*got, strict=True):
        assert_identical(a, b)


def test_a_schema_with_another_layout_is_not_read_by_the_fixed_layout(samples, tmp_path):
    """An Odometry whose schema gives std_msgs/Header a ROS 1 ``seq`` field (another byte
    layout under the standard type name): read by the generic codec with that schema, right,
    where the fixed layout would misread every field after the header."""
    from mcap_ros2.writer import Writer

    text = full_text(ODOMETRY)
    head = "MSG: std_msgs/Header\n"
    assert head in text
    ros1_header = text.replace(head, head + "uint32 seq\n", 1)
    msgs = [m for m, _ in samples[ODOMETRY]]
    path = tmp_path / "seq.mcap"
    with path.open("wb") as f:
        w = Writer(f)
        schema = w.register_msgdef(ODOMETRY, ros1_header)
        for i, (m, st) in enumerate(samples[ODOMETRY]):
            d = odom_to_ros(m, st)  # type: ignore[arg-type]
            d["header"]["seq"] = 7 + i
            w.write_message("/t", schema, d, log_time=i)
        w.finish()
    got = [r.msg for r in open_log(path).records({"/t"})]
    assert len(got) == len(msgs)
    for a, (m, st) in zip(got, samples[ODOMETRY], strict=True):
        assert isinstance(a, Odometry)
        assert a.stamp == st and a.frame_id == m.frame_id and a.child_frame_id == m.child_frame_id
        assert np.array_equal(a.twist, m.twist)
    # the fixed layout on those bytes would not give the same message
    from mcap.reader import make_reader

    with path.open("rb") as f:
        raw = [msg.data for _, _, msg in make_reader(f).iter_messages()]
    fast = fastcdr.decode_odometries(raw)
    assert any(x is None or x.child_frame_id != m.child_frame_id or not np.array_equal(x.twist, m.twist)
               for x, (m, _) in zip(fast, samples[ODOMETRY], strict=True))


# ---------------------------------------------------------------------------------------------
# fgloc's own yaw-only IMU messages and planar transforms (serial link, simulator)
def test_compass_and_planar_tf_encoders_byte_identical_and_read_back(samples):
    """A :class:`CompassHeading` is written as an Imu with its yaw and z rate, a planar
    :class:`StaticTransform` with its yaw's quaternion: byte-identical to the generic encoder, and
    read back as a whole Imu whose :meth:`~fgloc.types.Imu.heading` is the message written."""
    st = 1_700_000_000.25
    comp = [CompassHeading(st, 0.7, -0.2, 1e-4, 1e-6, "imu"), CompassHeading(st, None, 0.3, frame_id="imu"),
            CompassHeading(st, 1.0, None, frame_id="x"),
            CompassHeading(st, -math.pi, 0.0, float("nan"), float("nan"), "")]
    fast = [fastcdr.encode_compass(m, st) for m in comp]
    assert fast == _generic_bytes(IMU, [compass_to_ros(m, st) for m in comp])
    assert check_all(IMU, fast) == len(fast)
    for m, back in zip(comp, fastcdr.decode_imus(fast), strict=True):
        assert isinstance(back, Imu)
        h = back.heading()
        assert h.yaw_rad == pytest.approx(m.yaw_rad, abs=1e-15) if m.yaw_rad is not None else h.yaw_rad is None
        assert h.yaw_rate_radps == m.yaw_rate_radps
        assert _same_float(h.yaw_var, m.yaw_var) and _same_float(h.yaw_rate_var, m.yaw_rate_var)
    planar = [[StaticTransform("base_link", "laser", np.array([0.1, -0.2, 2.5]), 0.3)]]
    data = [fastcdr.encode_tf(m, st) for m in planar]
    assert data == _generic_bytes(TF_MESSAGE, [tf_to_ros(m, st) for m in planar])
    (got,) = fastcdr.decode_tf_messages(data)
    assert got is not None and isinstance(got[0][0], Transform3D)
    assert got[0][0].pose == pytest.approx([0.1, -0.2, 2.5])
    assert got[0][0].rotation_xyzw == pytest.approx([0, 0, math.sin(1.25), math.cos(1.25)])


def test_imu_read_back_whole_with_rep145_absent_fields(samples):
    """Every field of a written Imu comes back; absent fields (covariance[0] = -1) as None."""
    msgs = samples[IMU]
    back = fastcdr.decode_imus([fastcdr.encode_imu(m, st) for m, st in msgs])
    for (m, _), b in zip(msgs, back, strict=True):
        assert isinstance(m, Imu) and isinstance(b, Imu)
        for f in ("orientation_xyzw", "angular_velocity_radps", "linear_acceleration_mps2", "orientation_cov",
                  "angular_velocity_cov", "linear_acceleration_cov"):
            a, c = getattr(m, f), getattr(b, f)
            assert (a is None) == (c is None), f
            if a is not None:
                assert np.array_equal(a, c, equal_nan=True), f
