"""fgloc.memory: glibc's allocator calls in one place, each a no-op off glibc."""

from __future__ import annotations

import subprocess
import sys

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


#: run in a fresh interpreter: in a long-lived test worker glibc serves a 2 MB request from the
#: heap's free chunks whatever the threshold (it only mmaps what the heap cannot give), and the
#: thresholds set here are the process's for good
_THRESHOLD_PROBE = """
from fgloc import memory
assert memory.set_mmap_threshold(1 << 20)
m0 = memory.mallinfo()
a = bytearray(2 << 20)
m1 = memory.mallinfo()
del a
assert memory.set_mmap_threshold(32 << 20)
m2 = memory.mallinfo()
b = bytearray(2 << 20)
m3 = memory.mallinfo()
print(m1.mmapped_b - m0.mmapped_b, m3.mmapped_b - m2.mmapped_b, m3.in_use_b - m2.in_use_b)
"""


def test_the_mmap_threshold_moves_blocks_between_heap_and_mmap():
    if memory.mallinfo() is None:
        pytest.skip("glibc older than 2.33 (no mallinfo2)")
    out = subprocess.run([sys.executable, "-c", _THRESHOLD_PROBE], capture_output=True, text=True,
                         timeout=60, check=True).stdout
    mmapped_over, mmapped_under, heap_under = (int(v) for v in out.split())
    assert mmapped_over >= 2 << 20  # over the threshold: a mapping of its own
    assert mmapped_under < 1 << 20 and heap_under >= 2 << 20  # under it now: from the heap
