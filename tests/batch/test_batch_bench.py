"""``fgloc batch bench paper``: the same numbers and table as ``fgloc bench paper``."""

from __future__ import annotations

from fgloc.batch import read_summary_csv

from .helpers import fgloc_cli

VARIANT = ("EKF+native", "ekf", "native", "final")


def test_batch_bench_paper_reproduces_bench_paper(tmp_path):
    """One seed, one column (to stay quick): the metrics of every row equal ``bench_paper``'s to the
    last bit, the printed table is the same text, and a second run reuses the finished seed."""
    from fgloc.bench import bench_paper
    from fgloc.eval.paper import comparison_text

    ref = bench_paper(1, None, variants=(VARIANT,), jobs=1, quiet=True)
    out = tmp_path / "bench"
    rc, stdout, err = fgloc_cli("batch", "bench", "paper", "--seeds", "1", "--only", VARIANT[0], "-o", out,
                                "-j", "1", "--no-plots", "-q")
    assert rc == 0, err
    table = comparison_text(ref["rows"], title="paper replica: 1 seed(s), mean ± std over seeds")
    assert table in stdout
    assert (out / "table.md").read_text() == comparison_text(ref["rows"], title="paper replica, 1 seeds") + "\n"
    from fgloc.batch.adapter import load_seed_metrics

    got = load_seed_metrics(out / "seed-000")["metrics"][VARIANT[0]]
    assert got.to_dict() == ref["rows"][VARIANT[0]][0].to_dict()
    row = read_summary_csv(out / "summary.csv")[0]
    assert row["log"] == "seed-000" and row["status"] == "ok"
    assert float(row["rmse_m"]) == round(got.position_rmse_m, 6)
    rc, stdout, _ = fgloc_cli("batch", "bench", "paper", "--seeds", "1", "--only", VARIANT[0], "-o", out, "--no-plots",
                                "-q")
    assert rc == 0 and "0 ran, 1 already done" in stdout and table in stdout
