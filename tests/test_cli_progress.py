"""``fgloc run``'s progress line (fgloc.commands.run.ProgressLine): drawn on a terminal only, at most
once a period of its clock, erased at the end; no wall-clock dependence (an injected clock)."""

from __future__ import annotations

import io

from fgloc.commands.run import ProgressLine, _progress


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_redrawn_once_a_period_and_erased() -> None:
    out, clock = Terminal(), Clock()
    bar = ProgressLine(1000, stream=out, clock=clock, period_s=0.5)
    bar.update(64)  # before the first period: nothing drawn
    assert out.getvalue() == ""
    clock.t += 0.5
    bar.update(64)
    assert out.getvalue() == "\rlocalizing  12% 128/1000 msg  0.5 s, 256 msg/s"
    clock.t += 0.2
    bar.update(100)  # within the period: counted, not drawn
    assert out.getvalue().count("\r") == 1 and bar.n == 228
    clock.t += 0.3
    bar.update(772)
    assert out.getvalue().endswith("\rlocalizing 100% 1000/1000 msg  1.0 s, 1000 msg/s")
    width = len("localizing 100% 1000/1000 msg  1.0 s, 1000 msg/s")
    bar.close()
    assert out.getvalue().endswith("\r" + " " * width + "\r")
    bar.close()  # once
    assert out.getvalue().count(" " * width) == 1


def test_shorter_lines_cover_longer_ones_and_unknown_totals() -> None:
    out, clock = Terminal(), Clock()
    bar = ProgressLine(None, stream=out, clock=clock, period_s=0.5)
    clock.t += 1.0
    bar.update(12345)
    clock.t += 1.0
    bar.update(1)
    first, second = out.getvalue().split("\r")[1:]
    assert first == "localizing 12345 msg  1.0 s, 12345 msg/s"
    assert second.startswith("localizing 12346 msg  2.0 s, 6173 msg/s") and len(second) == len(first)


def test_nothing_written_when_not_a_terminal() -> None:
    out, clock = io.StringIO(), Clock()
    bar = ProgressLine(10, stream=out, clock=clock)
    for _ in range(10):
        clock.t += 1.0
        bar.update(1)
    bar.close()
    assert out.getvalue() == "" and bar.n == 10


def test_quiet_has_no_progress() -> None:
    assert _progress(True) is None
    assert _progress(False) is ProgressLine
