"""fgloc.memory: glibc's allocator calls in one place, each a no-op off glibc."""

from __future__ import annotations

import pytest

from fgloc import memory

pytestmark = pytest.mark.skipif(not memory.available(), reason="the C library is not glibc")


def test_mallinfo_sees_an_allocation_and_trim_returns_it():
    before = memory.mallinfo()
    if before is None:
        pytest.skip("glibc older than 2.33 (no mallinfo2)")
    block = bytearray(64 << 20)  # above glibc's mmap threshold: a chunk of its own
    during = memory.mallinfo()
    assert during is not None and during.mmapped_b - before.mmapped_b >= 64 << 20
    del block
    after = memory.mallinfo()
    assert after is not None and after.mmapped_b - before.mmapped_b < 1 << 20
    small = [bytes(1000) + bytes([i % 256]) for i in range(10_000)]  # 10 MB of blocks from malloc's heap
    grown = memory.mallinfo()
    assert grown is not None and grown.in_use_b - after.in_use_b >= 9 << 20
    del small
    assert memory.trim()
    n = memory.arenas()
    assert n is not None and n >= 1


def test_the_mmap_threshold_moves_blocks_between_heap_and_mmap():
    if memory.mallinfo() is None:
        pytest.skip("glibc older than 2.33 (no mallinfo2)")
    try:
        assert memory.set_mmap_threshold(1 << 20)
        m0 = memory.mallinfo()
        a = bytearray(2 << 20)  # over the threshold: mmapped
        m1 = memory.mallinfo()
        assert m0 is not None and m1 is not None and m1.mmapped_b - m0.mmapped_b >= 2 << 20
        del a
        assert memory.set_mmap_threshold(32 << 20)
        m2 = memory.mallinfo()
        b = bytearray(2 << 20)  # under it now: from the heap
        m3 = memory.mallinfo()
        assert m2 is not None and m3 is not None and m3.mmapped_b - m2.mmapped_b < 1 << 20
        assert m3.in_use_b - m2.in_use_b >= 2 << 20
        del b
    finally:
        memory.set_mmap_threshold(128 << 10)  # glibc's default (the dynamic threshold stays off in this process)
        assert memory.set_trim_threshold(128 << 10)
