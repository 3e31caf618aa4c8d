"""``fgloc run``'s progress bar (fgloc.commands.run.progress_bar): tqdm on a terminal, nothing
with --quiet or when stderr is not a terminal (a log file gets no carriage-return lines)."""

from __future__ import annotations

import io

from fgloc.commands.run import progress_bar


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_quiet_and_not_a_terminal_get_no_bar() -> None:
    assert progress_bar(True, Terminal()) is None
    assert progress_bar(False, io.StringIO()) is None  # a pipe or a file: no bar


def test_a_terminal_gets_a_tqdm_bar_that_counts_and_is_erased() -> None:
    out = Terminal()
    factory = progress_bar(False, out)
    assert factory is not None
    bar = factory(1000)
    from tqdm import tqdm

    assert isinstance(bar, tqdm)
    bar.update(640)
    bar.refresh()
    drawn = out.getvalue()
    assert "localizing" in drawn and "640/1000" in drawn and "64%" in drawn
    bar.close()  # leave=False: the line is cleared at the end
    assert out.getvalue().endswith("\r") or out.getvalue().endswith("\x1b[A")
