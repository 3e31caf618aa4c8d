"""A reference published on updates only (AMCL's /amcl_pose: after each 0.2 m or 0.5 rad of motion,
0.5-1 s apart) left most of an estimate's poses unpaired under --max-gap 0.5 s, with only the count in
the table to say so.  ``fgloc eval`` now notes it and the --max-gap that pairs them."""

from __future__ import annotations

import numpy as np

from fgloc.eval.checks import gap_note
from fgloc.testing.cli import run_cli as _eval


def _tum(path, stamps, xs) -> None:
    with open(path, "w") as f:
        for t, x in zip(stamps, xs, strict=True):
            f.write(f"{t:.6f} {x:.6f} 0 0 0 0 0 1\n")



def test_a_sparse_reference_is_noted_with_the_gap_that_pairs(tmp_path):
    est_t = np.arange(0.0, 30.0, 0.1)
    ref_t = np.arange(0.0, 30.01, 0.8)  # an update every 0.8 s
    _tum(tmp_path / "est.tum", est_t, 0.5 * est_t)
    _tum(tmp_path / "amcl.tum", ref_t, 0.5 * ref_t + 0.02)
    rc, out, err = _eval("eval", tmp_path / "est.tum", tmp_path / "amcl.tum")
    assert rc == 0, err
    note = [ln for ln in err.splitlines() if ln.startswith("note: ")]
    assert len(note) == 1, err
    assert "fall in gaps of the reference longer than --max-gap 0.5 s (its median spacing 0.80 s" in note[0]
    assert note[0].endswith("--max-gap 1 pairs 297, interpolating across its gaps")
    rc, out, err = _eval("eval", tmp_path / "est.tum", tmp_path / "amcl.tum", "--max-gap", "1")
    assert rc == 0 and "note:" not in err
    assert "297" in out  # every pose inside the reference's span associated


def test_a_dense_reference_or_exact_stamps_give_no_note():
    t = np.arange(0.0, 10.0, 0.1)
    assert gap_note("e", t, np.arange(0.0, 10.0, 0.05), 0.5) is None
    sparse = t[::8]  # 0.8 s apart, but every estimated pose stamped as a reference pose (AMCL stamps its scan's)
    assert gap_note("e", sparse, sparse, 0.5) is None
    note = gap_note("e", t, sparse, 0.5)
    assert note is not None and note.startswith("84 of 100 poses of e fall in gaps")
    assert note.endswith("pairs 97, interpolating across its gaps")
