"""``StreamWriter(background=True)``: the chunks compressed and written by a worker thread make the
same file, byte for byte, as written in line, and a write error of the worker reaches the caller."""

from __future__ import annotations

import io

import numpy as np
import pytest
from mcap.reader import make_reader

from fgloc.io.mcap_format import StreamWriter


def _write(f, background: bool, compression: str, n: int = 4000) -> None:
    rng = np.random.default_rng(5)
    w = StreamWriter(f, chunk_size=16 * 1024, compression=compression, background=background)
    sid = w.add_schema("fgloc.Test", "jsonschema", b'{"type": "object"}')
    channels = [w.add_channel(f"/t{i}", "json", sid) for i in range(3)]
    for k in range(n):
        if k == n // 2:  # a channel registered mid-file, while chunks are in flight
            channels.append(w.add_channel("/late", "json", sid))
        cid = channels[int(rng.integers(0, len(channels)))]
        t_ns = 1_000_000_000 + 10_000_000 * k - int(rng.integers(0, 30_000_000))  # slightly out of order
        w.add_message(cid, t_ns, rng.bytes(int(rng.integers(0, 300))), t_ns, k)
    w.finish()


@pytest.mark.parametrize("compression", ["zstd", "lz4", ""])
def test_background_chunks_write_the_same_bytes(compression: str) -> None:
    inline, background = io.BytesIO(), io.BytesIO()
    _write(inline, False, compression)
    _write(background, True, compression)
    assert background.getvalue() == inline.getvalue()
    background.seek(0)
    reader = make_reader(background, validate_crcs=True)
    summary = reader.get_summary()
    assert summary is not None and len(summary.chunk_indexes) > 20  # many chunks went through the worker
    assert sum(1 for _ in reader.iter_messages()) == 4000


class _FullDisk(io.BytesIO):
    def __init__(self, room: int) -> None:
        super().__init__()
        self.room = room

    def write(self, b) -> int:  # type: ignore[override]
        if self.tell() + len(b) > self.room:
            raise OSError(28, "No space left on device")
        return super().write(b)


def test_a_write_error_of_the_worker_is_raised_to_the_caller() -> None:
    with pytest.raises(OSError, match="No space left"):
        _write(_FullDisk(room=50_000), True, "zstd")
