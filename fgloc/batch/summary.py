"""The batch summary: one row per log (CSV and a rich table).

Columns: log, status (``ok``, ``done`` = finished by an earlier run and skipped, ``error``,
``lost`` = ran but ``fgloc run`` would exit 3: lost at the end or too long, no pose (with
``--allow-lost`` a lost run with poses is ``ok``/``done`` and its line is in the error column);
``not run`` = interrupted before it ran), duration (s of log time), poses, x real time
(log time / localization wall time, as ``fgloc run`` prints it), lost time (s the localizer
was lost, :attr:`fgloc.app.run.RunResult.lost_s`; map-frame runs only), position and heading RMSE
(when the log has ``/ground_truth``; over the poses the run vouches for, as ``fgloc run``'s table),
the one-line error, and the worker that ran it.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fgloc.batch.jobs import JobResult

#: CSV header (in order)
COLUMNS = ("log", "status", "duration_s", "poses", "x_real_time", "lost_time_s", "rmse_m", "heading_rmse_deg",
           "mode", "wall_s", "host", "error")


@dataclass
class SummaryRow:
    log: str
    status: str
    duration_s: float | None = None
    poses: int | None = None
    x_real_time: float | None = None
    lost_time_s: float | None = None
    rmse_m: float | None = None
    heading_rmse_deg: float | None = None
    mode: str | None = None
    wall_s: float | None = None
    host: str = ""
    error: str | None = None

    @staticmethod
    def from_result(res: JobResult, accept_lost: bool = False) -> SummaryRow:
        if not res.ok:
            return SummaryRow(res.name, "error", wall_s=res.wall_s, host=res.host, error=res.error)
        return SummaryRow._from_row(res.name, "ok", res.row, res.wall_s, res.host, accept_lost)

    @staticmethod
    def from_marker(name: str, doc: dict[str, Any], accept_lost: bool = False) -> SummaryRow:
        return SummaryRow._from_row(name, "done", doc.get("row") or {}, doc.get("wall_s"), doc.get("host", ""),
                                    accept_lost)

    @staticmethod
    def not_run(name: str) -> SummaryRow:
        return SummaryRow(name, "not run")

    @staticmethod
    def _from_row(name: str, status: str, row: dict[str, Any], wall_s: float | None, host: str,
                  accept_lost: bool = False) -> SummaryRow:
        def num(k: str) -> float | None:
            v = row.get(k)
            return None if v is None or (isinstance(v, float) and not math.isfinite(v)) else float(v)

        poses = row.get("poses")
        if row.get("failure") and not (accept_lost and row.get("acceptable")):
            status = "lost"
        return SummaryRow(name, status, num("duration_s"), None if poses is None else int(poses), num("x_real_time"),
                          num("lost_time_s"), num("rmse_m"), num("heading_rmse_deg"), row.get("mode"),
                          wall_s, host, row.get("failure") or row.get("note"))

    def csv_cells(self) -> list[str]:
        def f(v: float | None, fmt: str) -> str:
            return "" if v is None else format(v, fmt)

        return [self.log, self.status, f(self.duration_s, ".3f"), "" if self.poses is None else str(self.poses),
                f(self.x_real_time, ".1f"), f(self.lost_time_s, ".2f"), f(self.rmse_m, ".6f"),
                f(self.heading_rmse_deg, ".5f"), self.mode or "", f(self.wall_s, ".2f"), self.host,
                self.error or ""]


def write_summary_csv(path: Path, rows: list[SummaryRow]) -> Path:
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(COLUMNS)
        for r in rows:
            w.writerow(r.csv_cells())
    return path


def read_summary_csv(path: Path) -> list[dict[str, str]]:
    """The summary CSV as dicts (column -> cell text)."""
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


def summary_table(rows: list[SummaryRow], title: str):
    """A ``rich.table.Table`` of the rows (errors in red, one line each)."""
    from rich.table import Table

    t = Table(title=title)
    log_w = min(28, max([len(r.log) for r in rows] + [3]))
    t.add_column("log", no_wrap=True, min_width=log_w, overflow="ellipsis")
    t.add_column("status", no_wrap=True, min_width=6)
    for c in ("duration s", "poses", "x real time", "lost s", "RMSE m"):
        t.add_column(c, justify="right", no_wrap=True, min_width=5)
    t.add_column("error", overflow="fold")

    def f(v: float | None, fmt: str) -> str:
        return "-" if v is None else format(v, fmt)

    for r in rows:
        style = {"error": "red", "lost": "red", "not run": "yellow", "done": "dim"}.get(r.status)
        t.add_row(r.log, r.status, f(r.duration_s, ".1f"), "-" if r.poses is None else str(r.poses),
                  f(r.x_real_time, ".0f"), f(r.lost_time_s, ".1f"), f(r.rmse_m, ".4f"),
                  _clip(short_error(r.error), 36), style=style)
    return t


def _clip(text: str, n: int) -> str:
    return text if len(text) <= n else text[: n - 1] + "…"


def short_error(error: str | None) -> str:
    """The error without the folders of the file it names (the table has the log's name)."""
    if not error:
        return ""
    head, sep, tail = error.partition(": ")
    if sep and "/" in head and " " not in head:
        return f"{head.rsplit('/', 1)[-1]}: {tail}"
    return error
