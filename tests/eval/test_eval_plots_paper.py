"""Plots are written as PNG files; the paper comparison table shows the paper beside our rows."""

from __future__ import annotations

import re

import numpy as np

from fgloc.eval import paper
from fgloc.eval.metrics import evaluate
from fgloc.eval.plots import plot_all
from fgloc.maps import OccupancyMap
from fgloc.types import Trajectory

from .helpers import rectangle

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _noisy(gt: Trajectory, sigma: float, seed: int) -> Trajectory:
    rng = np.random.default_rng(seed)
    p = gt.poses.copy()
    p[:, :2] += rng.normal(0.0, sigma, (len(p), 2))
    p[:, 2] += rng.normal(0.0, sigma, len(p))
    return Trajectory(gt.stamps, p)


def test_plot_all_writes_pngs_with_map_fixes_and_two_estimates(tmp_path):
    gt = rectangle(width=6.0, height=4.0, rate=20.0)
    grid = np.zeros((140, 180), dtype=np.int16)
    grid[:3, :] = grid[-3:, :] = grid[:, :3] = grid[:, -3:] = 100
    grid[40:100, 40:140] = -1
    occ = OccupancyMap(grid, 0.05, np.array([-1.5, -1.5, 0.0]))
    ests = {"ekf": _noisy(gt, 0.02, 0), "smoother": _noisy(gt, 0.005, 1)}
    fixes = Trajectory(gt.stamps[::5], ests["ekf"].poses[::5])
    files = plot_all(ests, gt, tmp_path / "out", fixes=fixes, occ_map=occ, prefix="run_")
    names = sorted(p.name for p in files)
    assert names == sorted(f"run_{n}.png" for n in
                           ["path", "heading", "x_error", "y_error", "heading_error", "track_error", "overview"])
    for p in files:
        data = p.read_bytes()
        assert data[:8] == PNG_MAGIC and len(data) > 5000


def test_plot_all_single_trajectory(tmp_path):
    gt = rectangle(width=6.0, height=4.0, rate=20.0)
    files = plot_all(_noisy(gt, 0.01, 2), gt, tmp_path, label="ekf")
    assert len(files) == 7 and all(p.stat().st_size > 5000 for p in files)


def test_comparison_table_and_text():
    gt = rectangle(width=6.0, height=4.0, rate=20.0)
    rows = {
        "ekf": [evaluate(_noisy(gt, 0.02, s), gt) for s in range(3)],
        "smoother": [evaluate(_noisy(gt, 0.005, s), gt) for s in range(3)],
    }
    text = paper.comparison_text(rows)
    assert "0.0203" in text and "0.6939" in text and "3.3" in text
    lines = text.splitlines()
    assert len(lines) == 2 + len(paper.PAPER_ROWS) + len(paper.EXTRA_ROWS)
    pos = next(line for line in lines if line.startswith("| position RMSE"))
    ekf = [m.position_rmse_m for m in rows["ekf"]]
    assert f"{np.mean(ekf):.4f} ± {np.std(ekf):.4f}" in pos
    table = paper.comparison_table(rows)
    assert len(table.columns) == 3 + 2
    assert table.row_count == len(paper.PAPER_ROWS) + len(paper.EXTRA_ROWS)
    assert len(paper.comparison_text(rows, extra=False).splitlines()) == 2 + len(paper.PAPER_ROWS)
    # every line a Markdown row of the same width: the '|' of "max |x error|" is escaped
    cells = {len(re.split(r"(?<!\\)\|", line)) for line in lines}
    assert cells == {len(paper.comparison_cells(rows, True)[0]) + 2}
    assert any("max \\|x error\\|" in line for line in lines)
    # one seed: no +-
    assert "±" not in paper.comparison_text({"ekf": rows["ekf"][:1]})
