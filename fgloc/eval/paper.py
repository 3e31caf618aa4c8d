"""The paper's reported results (section 5) and a table that puts ours beside them.

The numbers are those of ``../shared/paper/PAPER.md`` (Nguyen Anh Tu et al., EKF
fusing encoders, compass and AMCL on a mecanum robot, 78 m rectangle at 0.8 m/s).
"along-track" is reported there as "oscillates around 0.02 m" and cross-track as
"around 0.0016 m"; we compare them with our mean absolute along/cross-track errors.

:func:`comparison_table` (rich) and :func:`comparison_text` (plain text) both take
``{backend name: [Metrics per seed]}`` and show mean +- std over the seeds.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from fgloc.eval.metrics import Metrics

PAPER_POSITION_RMSE_M = 0.0203
PAPER_HEADING_RMSE_DEG = 0.6939
PAPER_MAX_X_ERROR_M = 0.03
PAPER_MAX_Y_ERROR_M = 0.028
PAPER_ALONG_TRACK_M = 0.02  # "oscillates around 0.02 m"
PAPER_CROSS_TRACK_M = 0.0016  # "around 0.0016 m"
PAPER_MAX_HEADING_ERROR_DEG = 3.3  # at the rectangle's corners
PAPER_ROUTE_LENGTH_M = 78.0
PAPER_SPEED_MPS = 0.8
PAPER_OUTPUT_RATE_HZ = 17.0


@dataclass(frozen=True)
class Row:
    """One line of the comparison: a :class:`Metrics` field, its label, unit and the paper's value."""

    key: str
    label: str
    unit: str
    paper: float | None
    digits: int


#: The rows of the paper's results, in the paper's order, then our extra statistics.
PAPER_ROWS: tuple[Row, ...] = (
    Row("position_rmse_m", "position RMSE (eq. 11)", "m", PAPER_POSITION_RMSE_M, 4),
    Row("heading_rmse_deg", "heading RMSE (eq. 12)", "deg", PAPER_HEADING_RMSE_DEG, 4),
    Row("max_abs_x_m", "max |x error|", "m", PAPER_MAX_X_ERROR_M, 4),
    Row("max_abs_y_m", "max |y error|", "m", PAPER_MAX_Y_ERROR_M, 4),
    Row("along_mean_abs_m", "along-track error (mean |.|)", "m", PAPER_ALONG_TRACK_M, 4),
    Row("cross_mean_abs_m", "cross-track error (mean |.|)", "m", PAPER_CROSS_TRACK_M, 4),
    Row("max_abs_heading_deg", "max |heading error|", "deg", PAPER_MAX_HEADING_ERROR_DEG, 3),
)

EXTRA_ROWS: tuple[Row, ...] = (
    Row("position_p95_m", "position error p95", "m", None, 4),
    Row("heading_p95_deg", "heading error p95", "deg", None, 3),
    Row("ape_max_m", "APE max", "m", None, 4),
    Row("rpe_dist_trans_rmse_m", "RPE per 1 m, translation RMSE", "m", None, 4),
    Row("rpe_dist_rot_rmse_deg", "RPE per 1 m, rotation RMSE", "deg", None, 3),
)


def _stats(values: Sequence[float]) -> tuple[float, float, int]:
    v = np.asarray([x for x in values if x is not None and np.isfinite(x)], dtype=float)
    if len(v) == 0:
        return float("nan"), float("nan"), 0
    return float(np.mean(v)), float(np.std(v)), len(v)


def format_cell(values: Sequence[float], digits: int) -> str:
    """``mean +- std`` (std population, over seeds); just the value for one seed; ``-`` for none."""
    mean, std, n = _stats(values)
    if n == 0:
        return "-"
    if n == 1:
        return f"{mean:.{digits}f}"
    return f"{mean:.{digits}f} ± {std:.{digits}f}"


def _rows(extra: bool) -> tuple[Row, ...]:
    return PAPER_ROWS + (EXTRA_ROWS if extra else ())


def comparison_cells(
    rows: Mapping[str, Sequence[Metrics]], extra: bool = True, paper_column: bool = True
) -> tuple[list[str], list[list[str]]]:
    """Header and body cells of the comparison (shared by the rich and text formatters).
    ``paper_column``: the paper's reported values beside ours (the paper's experiment only: on
    any other log they are not a reference)."""
    header = ["metric", "unit", *(["paper (EKF)"] if paper_column else [])] + [
        f"{name} (n={len(ms)})" if len(ms) > 1 else name for name, ms in rows.items()
    ]
    body: list[list[str]] = []
    for r in _rows(extra):
        paper = "-" if r.paper is None else f"{r.paper:g}"
        cells = [r.label, r.unit, *([paper] if paper_column else [])]
        for ms in rows.values():
            cells.append(format_cell([float(getattr(m, r.key)) for m in ms], r.digits))
        body.append(cells)
    return header, body


def comparison_table(
    rows: Mapping[str, Sequence[Metrics]], title: str | None = None, extra: bool = True
):
    """A ``rich.table.Table``: one line per metric, the paper's column, then each back-end.

    ``rows`` maps a back-end name (e.g. ``"ekf"``, ``"smoother"``) to its metrics, one
    per seed; cells are mean +- std over the seeds.  ``extra`` adds the p95 / APE / RPE
    lines (the paper has no value for them).
    """
    from rich.table import Table

    header, body = comparison_cells(rows, extra)
    table = Table(title=title or "Localization error: the paper vs fgloc (mean ± std over seeds)")
    for i, h in enumerate(header):
        table.add_column(h, justify="left" if i < 2 else "right", no_wrap=i >= 2)
    for i, cells in enumerate(body):
        table.add_row(*cells, end_section=extra and i == len(PAPER_ROWS) - 1)
    return table


def justified(table: Sequence[Sequence[str]]) -> list[list[str]]:
    """A table's cells padded to their column's width: the first two columns (metric, unit) left
    aligned, the values right aligned (for :func:`comparison_text` and ``fgloc run``'s summary)."""
    widths = [max(len(row[i]) for row in table) for i in range(len(table[0]))]
    return [[c.ljust(w) if i < 2 else c.rjust(w) for i, (c, w) in enumerate(zip(row, widths, strict=True))]
            for row in table]


def comparison_text(
    rows: Mapping[str, Sequence[Metrics]], title: str | None = None, extra: bool = True
) -> str:
    """The same comparison as aligned plain text (Markdown-table compatible)."""
    header, body = comparison_cells(rows, extra)
    # a '|' inside a cell ("max |x error|") would end the cell in Markdown: escape it
    header = [c.replace("|", "\\|") for c in header]
    body = [[c.replace("|", "\\|") for c in cells] for cells in body]
    padded = justified([header, *body])
    widths = [len(c) for c in padded[0]]
    sep = "|" + "|".join(
        "-" * (w + 2) if i < 2 else "-" * (w + 1) + ":" for i, w in enumerate(widths)
    ) + "|"
    out = ["| " + " | ".join(cells) + " |" for cells in padded]
    out.insert(1, sep)
    if title:
        out.insert(0, title)
    return "\n".join(out)


def show_comparison(rows: Mapping[str, Sequence[Metrics]], title: str | None = None, extra: bool = True,
                    tty: bool | None = None) -> None:
    """Print the comparison: a drawn table on a terminal (:func:`comparison_table`), Markdown
    (:func:`comparison_text`) into a pipe or a file, where it is pasted into documents."""
    import sys

    if tty is None:
        tty = sys.stdout.isatty()
    if tty:
        from rich.console import Console

        Console().print(comparison_table(rows, title=title, extra=extra))
    else:
        print(comparison_text(rows, title=title, extra=extra))


def styled_claim(line: str) -> str:
    """A target line for rich: a missed target in bold red, a met one in green."""
    return line.replace("MISSED", "[bold red]MISSED[/bold red]").replace(": met)", ": [green]met[/green])")
