"""GTSAM keys of the smoother's variables: ``x<i>`` keyframe poses, ``o<j>`` compass-to-map offsets,
the calibration chains' characters (:mod:`.calibration`) and the inert ballast ``z<j>`` (:mod:`.window`)."""

from __future__ import annotations


def symbol(c: str, i: int) -> int:
    """``gtsam.symbol(c, i)`` in Python (GTSAM's layout: the character in the top 8 bits of the 64-bit
    key, the index below; no call into GTSAM per key)."""
    return (ord(c) << 56) | int(i)


def X(i: int) -> int:
    return symbol("x", i)


def O(j: int) -> int:  # noqa: E743
    return symbol("o", j)


BALLAST = "z"  # the inert variables that keep iSAM2's re-elimination incremental (_with_ballast)
