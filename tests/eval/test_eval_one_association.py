"""``fgloc eval`` pairs each estimate with the reference once: the metrics, the notes, --align-start's
move and end error and --nees all use that one association."""

from __future__ import annotations

import contextlib
import io
import json
import math

import numpy as np
import pytest

import fgloc.eval.metrics as metrics
from fgloc.cli import main


def _write(path, t, poses) -> None:
    with open(path, "w") as f:
        for s, (x, y, yaw) in zip(t, poses, strict=True):
            f.write(f"{s:.6f} {x:.6f} {y:.6f} 0 0 0 {math.sin(yaw / 2):.9f} {math.cos(yaw / 2):.9f}\n")


@pytest.mark.parametrize("extra", [[], ["--align-start"], ["--align"]])
def test_each_estimate_is_associated_once(tmp_path, monkeypatch, extra):
    t = np.linspace(0.0, 20.0, 201)
    ref = np.c_[np.cos(t / 4), np.sin(t / 4), t / 4 + math.pi / 2]
    (tmp_path / "a").mkdir()
    _write(tmp_path / "ref.tum", t, ref)
    _write(tmp_path / "a" / "est.tum", t, ref + [0.05, -0.02, 0.0])  # one offset each
    _write(tmp_path / "est2.tum", t, ref + [0.15, -0.02, 0.0])
    calls = []
    real = metrics.associate
    monkeypatch.setattr(metrics, "associate", lambda *a, **k: calls.append(1) or real(*a, **k))
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        assert main(["eval", str(tmp_path / "a" / "est.tum"), str(tmp_path / "est2.tum"), str(tmp_path / "ref.tum"),
                     *extra, "--json"]) == 0
    assert len(calls) == 2
    docs = json.loads(out.getvalue())
    rmse = [d["metrics"]["position_rmse_m"] for d in docs]
    if extra:  # the offsets are taken out
        assert rmse == pytest.approx([0.0, 0.0], abs=1e-5)
    else:
        assert rmse == pytest.approx([math.hypot(0.05, 0.02), math.hypot(0.15, 0.02)], abs=1e-5)
