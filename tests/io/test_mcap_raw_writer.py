"""``LogWriter.raw_writer``: a topic's writer with its channel looked up once writes the same file
as ``write_raw`` message by message (the view's channels in run.mcap go through it)."""

from __future__ import annotations

import numpy as np
from mcap.reader import make_reader

from fgloc.io.mcap_writer import LogWriter
from fgloc.types import PoseFix


def _write(path, fast: bool) -> None:
    rng = np.random.default_rng(2)
    topics = [("/fgloc/pose", "foxglove.PoseInFrame", b"schema-a", "protobuf", "protobuf"),
              ("/fgloc/fix", "fgloc.Fix", b'{"type": "object"}', "jsonschema", "json"),
              ("/fgloc/fix/accepted", "foxglove.PoseInFrame", b"schema-a", "protobuf", "protobuf")]
    with LogWriter(path) as w:
        writers = {}
        for k in range(3000):
            topic, name, schema, senc, menc = topics[int(rng.integers(0, 3))]
            data = rng.bytes(int(rng.integers(0, 400)))
            t_ns = 1_000_000_000 + 40_000_000 * k
            if k % 7 == 0:  # interleaved with ordinary messages
                w.write("/fused_pose", PoseFix(t_ns * 1e-9, np.zeros(3), np.eye(3)), log_time_ns=t_ns)
            if fast:
                if topic not in writers:
                    writers[topic] = w.raw_writer(topic, name, schema, senc, menc)
                writers[topic](data, t_ns)
            else:
                w.write_raw(topic, name, schema, data, t_ns, schema_encoding=senc, message_encoding=menc)


def test_raw_writer_writes_what_write_raw_writes(tmp_path):
    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    _write(a, fast=False)
    _write(b, fast=True)
    assert a.read_bytes() == b.read_bytes()
    with b.open("rb") as f:
        got = [(c.topic, s.name, m.log_time, len(m.data)) for s, c, m in make_reader(f).iter_messages()]
    assert len(got) == 3000 + 429 and {t for t, *_ in got} == {"/fgloc/pose", "/fgloc/fix", "/fgloc/fix/accepted",
                                                               "/fused_pose"}
