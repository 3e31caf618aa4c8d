"""The global search's candidates come best first, as a full sort of every score would give them."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

import fgloc.backends.global_search as gs
from fgloc.geometry import transform_points

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "frontends"))
from synth import MOUNT, make_map, make_scan  # noqa: E402


def _full_sort(scores: np.ndarray) -> list[int]:
    """Highest score first, ties from the highest index down: a stable ascending sort read backwards."""
    return np.argsort(scores, kind="stable")[::-1].tolist()


@pytest.mark.parametrize("n, levels", [(10, 3), (5000, 7), (5000, 0), (100_000, 50)])
def testbest_first_is_the_full_sort_ties_included(n, levels):
    rng = np.random.default_rng(n + levels)
    # few distinct values (many ties, across the batches' edges) or none repeated
    scores = rng.integers(0, levels, n).astype(float) / max(levels, 1) if levels else rng.random(n)
    assert list(gs.best_first(scores)) == _full_sort(scores)


def test_search_returns_what_the_full_sort_does(monkeypatch):
    room = make_map(resolution=0.1)
    search = gs.GlobalSearch(room)
    for pose in ([8.0, 5.0, 0.3], [3.0, 2.0, -2.0], [13.0, 8.0, 1.5]):
        pts = transform_points(MOUNT.pose, make_scan(room, np.array(pose)).points())
        got = search.search(pts)
        with monkeypatch.context() as m:
            m.setattr(gs, "best_first", lambda s: iter(_full_sort(s)))
            want = search.search(pts)
        assert len(got) == len(want) == search.n_best
        for (p, q), (pw, qw) in zip(got, want, strict=True):
            assert q == qw
            np.testing.assert_array_equal(p, pw)
