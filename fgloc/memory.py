"""The C allocator, where the process runs on glibc: hand its free pages back, fix its mmap threshold, read
its counters.  Everything here is a no-op (False / None) where there is no glibc (musl, macOS, Windows) or
the glibc lacks the call (``mallinfo2`` came with glibc 2.33).

* :func:`trim`: ``malloc_trim(0)``, every arena's free pages back to the system;
* :func:`set_mmap_threshold`: ``mallopt(M_MMAP_THRESHOLD)``, blocks from that size up from mmap (returned to
  the system when freed; glibc's dynamic threshold would otherwise move them into the heap after a free);
* :func:`mallinfo`: ``mallinfo2``, the bytes in use, free inside the arenas, in mmapped chunks;
* :func:`arenas`: the number of malloc arenas (``malloc_info``).
"""

from __future__ import annotations

import ctypes
import ctypes.util
from dataclasses import dataclass
from typing import Any

M_TRIM_THRESHOLD = -1  # mallopt's parameters (malloc.h)
M_MMAP_THRESHOLD = -3

_MALLINFO2_FIELDS = ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks", "fordblks",
                     "keepcost")


class _Mallinfo2(ctypes.Structure):
    _fields_ = [(n, ctypes.c_size_t) for n in _MALLINFO2_FIELDS]


@dataclass(frozen=True)
class Mallinfo:
    """glibc malloc's counters (``mallinfo2``), in bytes."""

    in_use_b: int   # allocated and not freed (uordblks)
    free_b: int     # free inside the arenas, not handed back (fordblks)
    mmapped_b: int  # in chunks of their own from mmap (hblkhd)
    arena_b: int    # the main arena's heap from sbrk (arena)


_LIBC: Any = None


def _libc() -> Any:
    """The C library if it is glibc (it has ``malloc_trim``), else False; loaded once."""
    global _LIBC
    if _LIBC is None:
        try:
            lib = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        except OSError:
            lib = None
        if lib is not None and hasattr(lib, "malloc_trim"):
            if hasattr(lib, "mallinfo2"):
                lib.mallinfo2.restype = _Mallinfo2
            if hasattr(lib, "open_memstream"):
                lib.open_memstream.restype = ctypes.c_void_p
                lib.open_memstream.argtypes = [ctypes.c_void_p, ctypes.c_void_p]
                lib.malloc_info.argtypes = [ctypes.c_int, ctypes.c_void_p]
                lib.fclose.argtypes = [ctypes.c_void_p]
                lib.free.argtypes = [ctypes.c_void_p]
            _LIBC = lib
        else:
            _LIBC = False
    return _LIBC


def available() -> bool:
    """True where the process's C library is glibc (the calls here do something)."""
    return bool(_libc())


def trim() -> bool:
    """Every arena's free pages back to the system (``malloc_trim(0)``); False without glibc."""
    lib = _libc()
    if not lib:
        return False
    lib.malloc_trim(0)
    return True


def _mallopt(param: int, value: int) -> bool:
    """``mallopt(param, value)``: False without glibc or if glibc refused the value."""
    lib = _libc()
    if not lib or not hasattr(lib, "mallopt"):
        return False
    return bool(lib.mallopt(param, int(value)))


def set_mmap_threshold(nbytes: int) -> bool:
    """Blocks of ``nbytes`` and more from mmap from now on (``mallopt(M_MMAP_THRESHOLD)``; it also stops
    glibc's dynamic threshold); False without glibc or if glibc refused the value."""
    return _mallopt(M_MMAP_THRESHOLD, nbytes)


def set_trim_threshold(nbytes: int) -> bool:
    """Free space of ``nbytes`` and more at the top of the heap goes back to the system at once
    (``mallopt(M_TRIM_THRESHOLD)``; glibc raises it with its dynamic mmap threshold); False without glibc."""
    return _mallopt(M_TRIM_THRESHOLD, nbytes)


def mallinfo() -> Mallinfo | None:
    """glibc malloc's counters now; None without glibc 2.33+."""
    lib = _libc()
    if not lib or not hasattr(lib, "mallinfo2"):
        return None
    mi = lib.mallinfo2()
    return Mallinfo(in_use_b=int(mi.uordblks), free_b=int(mi.fordblks), mmapped_b=int(mi.hblkhd),
                    arena_b=int(mi.arena))


def arenas() -> int | None:
    """How many malloc arenas the process has (from ``malloc_info``'s XML); None without glibc."""
    lib = _libc()
    if not lib or not hasattr(lib, "open_memstream"):
        return None
    buf, size = ctypes.c_void_p(), ctypes.c_size_t()
    fp = lib.open_memstream(ctypes.byref(buf), ctypes.byref(size))
    if not fp:
        return None
    lib.malloc_info(0, fp)
    lib.fclose(fp)
    text = ctypes.string_at(buf.value, size.value).decode() if buf.value else ""
    lib.free(buf)
    return text.count("<heap nr=")
