"""A command process's start-up: no cyclic garbage collection while it imports and sets up.

Importing numpy, scipy, numba and gtsam and building the map and the localizer creates hundreds
of thousands of objects that live as long as the process.  CPython's cyclic collector walks them
again in every collection of the older generations while they pile up, and in every full
collection afterwards (``fgloc run`` on a 2 s log: 0.17 s of its 1.9 s of CPU went to the
collector).  A command that is the whole process calls :func:`pause_gc` first and
:func:`setup_done` when its set-up is over (``fgloc run``: before the first message): what is
alive then is moved to the permanent generation (:func:`gc.freeze`), so later collections skip
it, and collection resumes.  In a library caller (tests, batch workers) nothing was paused and
:func:`setup_done` does nothing: the process's collector is never touched behind its back.

At the end, :func:`exit_process` leaves without the interpreter's teardown (freeing every module,
numba's and gtsam's objects one by one: 0.04 s of CPU after every ``fgloc run``), once the exit
handlers have run and the output is flushed.
"""

from __future__ import annotations

import atexit
import gc
import os
import sys
import threading

_paused = False


def pause_gc() -> None:
    """Stop cyclic collection until :func:`setup_done` (no-op if it is already off)."""
    global _paused
    if gc.isenabled():
        gc.disable()
        _paused = True


def setup_done() -> None:
    """After a :func:`pause_gc`: freeze the objects alive now and collect again; else nothing."""
    global _paused
    if _paused:
        _paused = False
        gc.freeze()
        gc.enable()


def resume_gc() -> None:
    """After a :func:`pause_gc` whose set-up never finished (an error): collect again, freeze nothing.
    A no-op after :func:`setup_done`, so a caller runs it in a ``finally``."""
    global _paused
    if _paused:
        _paused = False
        gc.enable()


def exit_process(code: int) -> None:
    """End the process now with ``code``: the ``atexit`` handlers run (logging's flush, a caller's
    own), stdout and stderr are flushed, then ``os._exit`` skips the interpreter's teardown, whose
    only work left is freeing memory the OS frees anyway.  Returns (the caller exits as usual)
    when a thread other than daemons is alive (the normal exit joins it) or the output cannot be
    flushed (a closed pipe: the normal exit reports it)."""
    if any(t is not threading.main_thread() and not t.daemon for t in threading.enumerate()):
        return
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    except (OSError, ValueError):
        return
    atexit._run_exitfuncs()
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    finally:
        os._exit(code)
