"""The ``fgloc`` process's exit: without the interpreter's teardown (fgloc.app.startup.exit_process),
but with everything a normal exit does that anyone can see: the exit code, the output flushed, the
``atexit`` handlers run, a live non-daemon thread waited for.  In-process callers get the code back."""

from __future__ import annotations

import subprocess
import sys

import fgloc

PROLOGUE = (
    "import atexit, sys, threading, time\n"
    "atexit.register(lambda: print('HANDLER RAN', flush=False))\n"
)
ENTRY = "from fgloc.cli import main\nsys.exit(main())\n"


def _fgloc(code: str, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, timeout=300)


def test_a_command_exits_with_its_output_and_the_exit_handlers() -> None:
    out = _fgloc(PROLOGUE + ENTRY, "version")
    assert out.returncode == 0, out.stderr
    assert out.stdout.splitlines() == [fgloc.__version__, "HANDLER RAN"]


def test_a_user_error_exits_2_with_its_line(tmp_path) -> None:
    out = _fgloc(PROLOGUE + ENTRY, "run", str(tmp_path / "missing.mcap"), "-o", str(tmp_path / "out"))
    assert out.returncode == 2
    assert out.stderr.startswith("fgloc: error: ") and len(out.stderr.strip().splitlines()) == 1
    assert out.stdout.splitlines() == ["HANDLER RAN"]


def test_a_live_thread_is_waited_for_as_by_a_normal_exit() -> None:
    thread = ("def late():\n"
              "    time.sleep(0.3)\n"
              "    print('THREAD DONE', flush=True)\n"
              "threading.Thread(target=late).start()\n")
    out = _fgloc(PROLOGUE + thread + ENTRY, "version")
    assert out.returncode == 0, out.stderr
    assert sorted(out.stdout.splitlines()) == sorted([fgloc.__version__, "THREAD DONE", "HANDLER RAN"])


def test_an_in_process_caller_gets_the_code_back(capsys) -> None:
    from fgloc.cli import main

    assert main(["version"]) == 0
    assert capsys.readouterr().out.strip() == fgloc.__version__
