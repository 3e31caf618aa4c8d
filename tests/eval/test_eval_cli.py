"""``fgloc eval`` through ``fgloc.cli.main``: table, JSON, plots, bad input, relations wiring."""

from __future__ import annotations

import json

import numpy as np
import pytest

from fgloc.cli import main
from fgloc.eval.metrics import Metrics
from fgloc.io.tum import write_tum
from fgloc.types import Trajectory

from .helpers import rectangle


@pytest.fixture()
def files(tmp_path):
    gt = rectangle(width=6.0, height=4.0)
    p = gt.poses.copy()
    p[:, 0] += 0.03
    p[:, 1] -= 0.04
    write_tum(tmp_path / "gt.tum", gt)
    write_tum(tmp_path / "est.tum", Trajectory(gt.stamps, p))
    p2 = gt.poses.copy()
    p2[:, 2] += np.radians(1.0)
    write_tum(tmp_path / "smoother.tum", Trajectory(gt.stamps, p2))
    return tmp_path


def test_eval_table(files, capsys):
    assert main(["eval", str(files / "est.tum"), str(files / "gt.tum")]) == 0
    out = capsys.readouterr().out
    assert "position RMSE" in out
    assert "0.0500" in out  # hypot(0.03, 0.04)
    assert "0.0300" in out and "0.0400" in out  # max |x|, max |y|


def test_eval_table_identical_and_paper_column(files, capsys):
    assert main(["eval", str(files / "gt.tum"), str(files / "gt.tum"), "--paper"]) == 0
    out = capsys.readouterr().out
    assert "0.0203" in out and "0.6939" in out  # the paper's column
    assert "0.0000" in out


def test_eval_json_has_documented_keys(files, capsys):
    assert main(["eval", str(files / "est.tum"), str(files / "gt.tum"), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert set(doc) >= {"label", "estimate", "reference", "metrics"}
    assert list(doc["metrics"]) == Metrics.keys()
    assert doc["metrics"]["position_rmse_m"] == pytest.approx(0.05, abs=1e-9)
    assert doc["metrics"]["heading_rmse_deg"] == pytest.approx(0.0, abs=1e-9)


def test_eval_several_estimates_and_plots(files, capsys, tmp_path):
    outdir = tmp_path / "plots"
    rc = main(["eval", str(files / "est.tum"), str(files / "smoother.tum"), str(files / "gt.tum"),
               "--json", "--plots", str(outdir)])
    assert rc == 0
    docs = json.loads(capsys.readouterr().out)
    assert [d["label"] for d in docs] == ["est", "smoother"]
    assert docs[1]["metrics"]["heading_rmse_deg"] == pytest.approx(1.0, abs=1e-9)
    pngs = sorted(outdir.glob("*.png"))
    assert len(pngs) == 7
    assert all(p.stat().st_size > 5000 for p in pngs)


@pytest.mark.parametrize(
    "content, match",
    [
        (None, "not found"),
        ("1 2 3\n", "expected 8 numbers"),
        ("0 0 0 0 0 0 0 1\nabc d e f g h i j\n", "not a number"),
    ],
)
def test_eval_bad_file_is_one_line_error(files, capsys, content, match):
    bad = files / "bad.tum"
    if content is not None:
        bad.write_text(content)
    assert main(["eval", str(bad), str(files / "gt.tum")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("fgloc: error:") and "\n" not in err
    assert "bad.tum" in err and match in err


def test_eval_no_overlap_is_one_line_error(files, capsys):
    gt = rectangle(width=6.0, height=4.0)
    write_tum(files / "late.tum", Trajectory(gt.stamps + 1000.0, gt.poses))
    assert main(["eval", str(files / "late.tum"), str(files / "gt.tum")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "late.tum" in err and "do not overlap" in err


def test_eval_time_offset(files, capsys):
    gt = rectangle(width=6.0, height=4.0)
    write_tum(files / "late.tum", Trajectory(gt.stamps + 1000.0, gt.poses))
    assert main(["eval", str(files / "late.tum"), str(files / "gt.tum"), "--t-offset", "-1000", "--json"]) == 0
    m = json.loads(capsys.readouterr().out)["metrics"]
    assert m["position_rmse_m"] == pytest.approx(0.0, abs=1e-6)
    assert m["n"] >= len(gt) - 1


def test_eval_too_few_poses(files, capsys):
    write_tum(files / "one.tum", Trajectory([1.0], [[0.0, 0.0, 0.0]]))
    assert main(["eval", str(files / "one.tum"), str(files / "gt.tum")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "one.tum" in err and "at least 2" in err


def test_eval_needs_two_files(files, capsys):
    assert main(["eval", str(files / "gt.tum")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "needs an estimate and a reference" in err and "GT.tum" in err


def test_eval_reference_relations(files, capsys):
    pytest.importorskip("fgloc.eval.relations")
    rc = main(["eval", "--reference", str(files / "gt.tum"), str(files / "gt.tum"), "--json"])
    assert rc == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["n"] > 0
    assert doc["trans_mean"] == pytest.approx(0.0, abs=1e-9)
    assert doc["rot_mean_deg"] == pytest.approx(0.0, abs=1e-9)
    rc = main(["eval", "--reference", str(files / "gt.tum"), str(files / "smoother.tum")])
    assert rc == 0
    assert "translation error" in capsys.readouterr().out


def test_eval_relations_file(files, capsys):
    rel = pytest.importorskip("fgloc.eval.relations")
    from fgloc.io.tum import read_tum

    gt = read_tum(files / "gt.tum")
    rels = rel.relations_from_reference(gt, loop_closures=False)
    rel.write_relations(files / "rel.txt", rels)
    rc = main(["eval", "--relations", str(files / "rel.txt"), str(files / "est.tum"), "--json"])
    assert rc == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["n"] == len(rels)
    assert doc["trans_mean"] == pytest.approx(0.0, abs=1e-9)  # a constant offset has no relation error
    assert main(["eval", "--relations", str(files / "missing.txt"), str(files / "est.tum")]) == 2
    assert "missing.txt" in capsys.readouterr().err


def test_eval_reference_relation_spacing(files, capsys):
    pytest.importorskip("fgloc.eval.relations")
    args = ["eval", "--reference", str(files / "gt.tum"), str(files / "gt.tum"), "--json"]
    assert main(args) == 0
    n_default = json.loads(capsys.readouterr().out)["n"]
    assert main(args + ["--min-dt", "5", "--max-dt", "6"]) == 0
    n_wide = json.loads(capsys.readouterr().out)["n"]
    assert 0 < n_wide < n_default  # poses in the last 5 s find no partner
    assert main(args + ["--min-dt", "1e6", "--max-dt", "2e6"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "no relations" in err
