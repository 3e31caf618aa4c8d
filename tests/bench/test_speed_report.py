"""``fgloc bench speed``'s after / before table: the ratios and verdicts from the samples."""

from __future__ import annotations

from pathlib import Path

import pytest

from fgloc.bench.speed import Row, Sample, SpeedReport, comparison_lines, no_worse, report_lines


def _row(what: str, cpu_s: list[float]) -> Row:
    return Row("office", what, 120.0, 3000, [Sample(wall_s=c, cpu_s=c) for c in cpu_s])


def _report(rows: list[Row], before: Path | None = Path("old")) -> SpeedReport:
    startup = {"fgloc run, 2 s log": [Sample(1.0, 1.20), Sample(1.0, 1.30)]}
    startup_before = {"fgloc run, 2 s log": [Sample(1.0, 1.10), Sample(1.0, 1.25)]}
    return SpeedReport(rows, startup, startup_before, [(1.0, 1.0, 1.0)], 2, before, 10.0)


@pytest.mark.parametrize(("after", "before", "higher", "ratio", "verdict"), [
    ([30.0, 32.0], [24.0, 26.0], True, 31.0 / 25.0, "yes"),
    ([24.0, 26.0], [25.0, 27.0], True, 25.0 / 26.0, "within the ranges"),
    ([20.0, 22.0], [25.0, 27.0], True, 21.0 / 26.0, "no"),
    ([1.0, 1.2], [1.2, 1.4], False, 1.1 / 1.3, "yes"),
    ([1.3, 1.5], [1.2, 1.4], False, 1.4 / 1.3, "within the ranges"),
    ([1.5, 1.7], [1.2, 1.4], False, 1.6 / 1.3, "no"),
])
def test_no_worse_ratio_and_verdict(after, before, higher, ratio, verdict):
    got_ratio, got_verdict = no_worse(after, before, higher_is_better=higher)
    assert got_ratio == pytest.approx(ratio)
    assert got_verdict == verdict


def test_comparison_table_pairs_each_row_with_its_before_twin():
    rows = [_row("fgloc run", [4.0, 6.0]), _row("fgloc run (before)", [5.0, 5.5]),
            _row("in-memory pipeline", [2.0, 2.4]), _row("in-memory pipeline (before)", [2.4, 2.6]),
            _row("reading the log alone", [0.1, 0.1])]
    lines = comparison_lines(_report(rows))
    assert lines[0].startswith("| log | what | after")
    body = lines[2:]
    # x real time = 120 s / CPU s: after 30.0 and 20.0 (median 25.0), before 24.0 and 21.8 (median 22.9):
    # ratio 25.0 / 22.9 = 1.09
    assert body[0] == "| office (120 s) | fgloc run | 25.0 [20.0-30.0] | 22.9 [21.8-24.0] | 1.09 | yes |"
    # 120/2 = 60, 120/2.4 = 50 (median 55) against 50, 46.2 (median 48.1): 1.14
    assert body[1].endswith("| 1.14 | yes |")
    assert len(body) == 3  # the reading row has no twin; the start-up row follows
    # start-up CPU 1.25 s against 1.175 s: 1.06x the time, the ranges overlap
    assert body[2] == "| start-up | fgloc run, 2 s log (s of CPU) | 1.25 [1.20-1.30] | 1.18 [1.10-1.25] | " \
                      "1.06x the time | within the ranges |"


def test_report_has_the_comparison_only_with_a_before_tree():
    rows = [_row("fgloc run", [4.0]), _row("fgloc run (before)", [5.0])]
    assert any("| no worse? |" in ln for ln in report_lines(_report(rows)))
    assert not any("| no worse? |" in ln for ln in report_lines(_report(rows[:1], before=None)))
