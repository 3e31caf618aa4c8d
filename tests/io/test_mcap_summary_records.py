"""The summary's chunk indexes and statistics read with ``struct`` (fgloc.io.mcap_format) equal what
the ``mcap`` package's own record classes read, on files of fgloc's writer and of ``mcap``'s."""

from __future__ import annotations

import io
import struct

import numpy as np
from mcap.data_stream import ReadDataStream
from mcap.records import ChunkIndex, Statistics
from mcap.writer import CompressionType, Writer

from fgloc.io.mcap_format import OP_CHUNK_INDEX, OP_STATISTICS, parse_chunk_index, parse_statistics, read_summary
from fgloc.io.mcap_writer import LogWriter
from fgloc.types import CompassHeading, LaserScan, Odometry


def _summary_bodies(data: bytes) -> list[tuple[int, bytes]]:
    """(opcode, body) of the chunk index and statistics records of an MCAP's summary section."""
    start = struct.unpack_from("<Q", data, len(data) - 8 - 20)[0]
    out, pos = [], start
    while pos < len(data) - 8 - 29:
        op, length = struct.unpack_from("<BQ", data, pos)
        if op in (OP_CHUNK_INDEX, OP_STATISTICS):
            out.append((op, data[pos + 9:pos + 9 + length]))
        pos += 9 + length
    return out


def _fgloc_file(path) -> bytes:
    rng = np.random.default_rng(1)
    with LogWriter(path, chunk_size=4096) as w:
        for i in range(300):
            t = 10.0 + 0.04 * i
            w.write("/scan", LaserScan(t, -1.0, 0.01, 0.1, 20.0, rng.uniform(1, 9, 100).astype(np.float32)))
            w.write("/odom", Odometry(t + 0.01, np.array([0.3, 0.0, 0.02])))
            if i % 3 == 0:
                w.write("/imu", CompassHeading(t + 0.02, yaw_rad=0.01 * i))
    return path.read_bytes()


def _mcap_file() -> bytes:
    f = io.BytesIO()
    w = Writer(f, chunk_size=2048, compression=CompressionType.LZ4)
    w.start()
    sid = w.register_schema("s", "jsonschema", b"{}")
    chans = [w.register_channel(f"/c{i}", "json", sid) for i in range(4)]
    rng = np.random.default_rng(2)
    for k in range(600):
        w.add_message(chans[int(rng.integers(0, 4))], 1000 + 7 * k, rng.bytes(int(rng.integers(1, 90))), 1000 + 7 * k)
    w.finish()
    return f.getvalue()


def test_chunk_indexes_and_statistics_read_as_mcap_reads_them(tmp_path) -> None:
    for data in (_fgloc_file(tmp_path / "f.mcap"), _mcap_file()):
        bodies = _summary_bodies(data)
        assert sum(op == OP_CHUNK_INDEX for op, _ in bodies) > 10
        for op, body in bodies:
            theirs = (ChunkIndex if op == OP_CHUNK_INDEX else Statistics).read(ReadDataStream(io.BytesIO(body)))
            if op == OP_CHUNK_INDEX:
                ref = parse_chunk_index(body)
                assert (ref.start_ns, ref.end_ns, ref.offset, ref.length) == (
                    theirs.message_start_time, theirs.message_end_time, theirs.chunk_start_offset, theirs.chunk_length)
                assert ref.channels == (frozenset(theirs.message_index_offsets) or None)
            else:
                assert parse_statistics(body) == (theirs.message_count, theirs.message_start_time,
                                                  theirs.message_end_time, theirs.channel_message_counts)
        s = read_summary(io.BytesIO(data), len(data))
        assert s is not None and len(s.chunks) == sum(op == OP_CHUNK_INDEX for op, _ in bodies)


def test_a_cut_record_is_an_error_not_a_wrong_value() -> None:
    op, body = next(b for b in _summary_bodies(_mcap_file()) if b[0] == OP_CHUNK_INDEX)
    for cut in (10, 36, len(body) - 3):
        try:
            parse_chunk_index(body[:cut])
        except (struct.error, ValueError):
            continue
        raise AssertionError(f"a chunk index cut at {cut} bytes was read")
