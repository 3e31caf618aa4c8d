"""Stopping a command on SIGINT or SIGTERM: cleanly at the first signal, at once at the second.

The CLI calls :func:`handling` around every command (a service manager's SIGTERM is handled as
a Ctrl-C; a signal the parent set to be ignored stays ignored):

* the **first** signal requests a stop; the signal handler itself never raises in the middle
  of the work (a Ctrl-C that landed inside an import, numba's dispatcher or a GTSAM call gave
  ``ImportError: initialization failed``, a numba ``SystemError`` or a segfault).  The work
  stops at its next :func:`checkpoint` (``fgloc run`` checks per message, ``fgloc map`` per
  scan, ``simulate`` per scan, ``demo`` per message) by raising :class:`Interrupted`; work
  without one is interrupted :data:`GRACE_S` later (a timer signal raises there).  Inside
  :func:`immediate` (the batch driver waiting for its workers) it is interrupted at once;
  inside :func:`cooperative` (``fgloc live``: its stop event) never: the work finishes itself.
  Either way the command's staged outputs are discarded, its output folder stays as it was
  (:mod:`fgloc.io.outputs`), and the CLI exits 130 with one line ``fgloc: interrupted (SIGINT)``;
* the **second** signal exits with 130 at once, after the hooks registered with
  :func:`at_hard_exit` (removing staging folders, killing worker processes); a command that
  registered a hurry hook (:func:`cooperative` ``on_hurry``: ``fgloc live`` skips its final
  smoothing and closes its recording) gets it called instead, and exits at the third;
* inside :func:`critical` (publishing outputs: a few renames) nothing interrupts: a signal
  takes effect when the section ends, so what was complete is never cut.

A handler runs between two Python bytecodes: work stuck in one long C call (a GTSAM batch
optimization) sees even the second signal only when that call returns.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager

#: the exit status of an interrupted command (128 + SIGINT, as a shell reports Ctrl-C)
EXIT_INTERRUPTED = 130

#: seconds between a first signal and interrupting work that has not reached a checkpoint
GRACE_S = 1.0

SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Interrupted(KeyboardInterrupt):
    """A stop requested by a signal, raised where the work can stop cleanly."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal_name(signum))
        self.signum = signum


def signal_name(signum: int) -> str:
    try:
        return signal.Signals(signum).name
    except ValueError:
        return f"signal {signum}"


class _State:
    def __init__(self) -> None:
        self.signum: int | None = None  # the first signal received
        self.count = 0
        self.cooperative = 0  # the work stops itself (no raise)
        self.immediate = 0  # raise at the first signal
        self.critical = 0
        self.exit_pending = False
        self.stop_pending = False  # a stop held by a critical section (raised when it ends)
        self.raised = False  # an Interrupted was raised
        self.on_stop: list[Callable[[], None]] = []
        self.hurry: list[Callable[[], None]] = []
        self.hard_exit: dict[int, Callable[[], None]] = {}
        self.notes: list[str] = []
        self.alarm = False  # the grace timer is ours
        self.closed = False  # the command is over (the process is exiting): signals are ignored


_state = _State()
_lock = threading.Lock()


def requested() -> int | None:
    """The signal number of a requested stop, or None."""
    return _state.signum


def checkpoint() -> None:
    """Raise :class:`Interrupted` when a stop was requested (outside a :func:`critical` section)."""
    st = _state
    if st.signum is not None and not st.critical:
        st.raised = True
        raise Interrupted(st.signum)


def note(line: str) -> None:
    """A clause for the interrupted line (e.g. which outputs were left as they were)."""
    with _lock:
        if line not in _state.notes:
            _state.notes.append(line)


def interrupted_line() -> str:
    """``fgloc: interrupted (SIGINT): ...`` for the CLI."""
    name = signal_name(_state.signum) if _state.signum is not None else "SIGINT"
    tail = "; ".join(_state.notes)
    return f"fgloc: interrupted ({name})" + (f": {tail}" if tail else "")


def at_hard_exit(fn: Callable[[], None]) -> Callable[[], None]:
    """Run ``fn`` (quick, never raising) before an exit at the second signal; returns the
    function that unregisters it."""
    key = id(fn)
    with _lock:
        _state.hard_exit[key] = fn

    def remove() -> None:
        with _lock:
            _state.hard_exit.pop(key, None)

    return remove


def _hard_exit() -> None:
    with _lock:
        hooks = list(_state.hard_exit.values())
    for fn in hooks:
        try:
            fn()
        except BaseException:  # noqa: BLE001, S110 - exiting anyway: every hook gets its turn
            pass
    try:
        sys.stderr.write(interrupted_line() + " (second signal: stopped at once)\n")
        sys.stderr.flush()
    except (OSError, ValueError):
        pass
    os._exit(EXIT_INTERRUPTED)


def _raise_now() -> None:
    st = _state
    st.raised = True
    raise Interrupted(st.signum if st.signum is not None else signal.SIGINT)


def _on_signal(signum: int, frame: object) -> None:
    st = _state
    if st.closed:
        return
    st.count += 1
    if st.count == 1:
        st.signum = signum
        for fn in list(st.on_stop):
            fn()
        if st.cooperative:
            return
        if st.critical:
            st.stop_pending = True
            return
        if st.immediate:
            _raise_now()
        if st.alarm:  # the grace: a checkpoint in time stops the work where it is safe to
            signal.setitimer(signal.ITIMER_REAL, GRACE_S)
        return
    if st.hurry and st.count == 2:
        for fn in list(st.hurry):
            fn()
        return
    if st.critical:
        st.exit_pending = True
        return
    _hard_exit()


def _on_alarm(signum: int, frame: object) -> None:
    """The grace is over and no checkpoint raised: interrupt the work here."""
    st = _state
    if st.signum is None or st.raised or st.cooperative or st.closed:
        return
    if st.critical:
        st.stop_pending = True
        return
    _raise_now()


_early: list[int] = []


def _record_early(signum: int, frame: object) -> None:
    if _early:  # a second signal before the command began: nothing to finish
        try:
            sys.stderr.write(f"fgloc: interrupted ({signal_name(signum)})\n")
        except (OSError, ValueError):
            pass
        os._exit(EXIT_INTERRUPTED)
    _early.append(signum)


def install_early() -> None:
    """The ``fgloc`` console script, from its first import on: a signal is only recorded until
    :func:`handling` takes over and acts on it (the work then stops at its first checkpoint;
    Python's own handler raised KeyboardInterrupt inside the imports)."""
    if threading.current_thread() is threading.main_thread():
        for s in SIGNALS:
            if signal.getsignal(s) is not signal.SIG_IGN:
                signal.signal(s, _record_early)


@contextmanager
def handling(restore: bool = True) -> Iterator[None]:
    """Install the handlers (main thread only) for the duration of one command; restores the
    previous ones (``restore``; else, for a process that exits next, they stay and ignore every
    later signal: a Ctrl-C during the exit is no traceback) and forgets the command's stop."""
    global _state
    old: dict[signal.Signals, object] = {}
    if threading.current_thread() is threading.main_thread():
        for s in SIGNALS:
            prev = signal.getsignal(s)
            if prev is signal.SIG_IGN:  # e.g. a background job of a shell, or nohup: stays ignored
                continue
            old[s] = signal.default_int_handler if prev is _record_early and s == signal.SIGINT else \
                signal.SIG_DFL if prev is _record_early else prev
            signal.signal(s, _on_signal)
        if old and signal.getsignal(signal.SIGALRM) in (signal.SIG_DFL, None):
            old[signal.SIGALRM] = signal.getsignal(signal.SIGALRM)
            signal.signal(signal.SIGALRM, _on_alarm)
            _state.alarm = True
    if _early:  # a signal during the start-up: the first of this command
        _on_signal(_early.pop(0), None)
    try:
        yield
    finally:
        if _state.alarm:
            signal.setitimer(signal.ITIMER_REAL, 0)
        if restore:
            for sig, h in old.items():
                signal.signal(sig, h)  # type: ignore[arg-type]
        _state = _State()
        _state.closed = not restore and bool(old)


@contextmanager
def cooperative(on_stop: Callable[[], None] | None = None,
                on_hurry: Callable[[], None] | None = None) -> Iterator[None]:
    """Within: a first signal only calls ``on_stop`` (from the handler) and the work stops
    itself; ``on_hurry``: called at the second signal instead of exiting (the third exits)."""
    st = _state
    st.cooperative += 1
    if on_stop is not None:
        st.on_stop.append(on_stop)
        if st.signum is not None:
            on_stop()
    if on_hurry is not None:
        st.hurry.append(on_hurry)
    try:
        yield
    finally:
        st.cooperative -= 1
        for fn, lst in ((on_stop, st.on_stop), (on_hurry, st.hurry)):
            if fn is not None and fn in lst:
                lst.remove(fn)


@contextmanager
def immediate() -> Iterator[None]:
    """Within: the first signal raises :class:`Interrupted` at once (work that is safe to
    interrupt anywhere and may wait long: the batch driver waiting for its workers)."""
    st = _state
    st.immediate += 1
    try:
        if st.signum is not None and not st.raised:
            _raise_now()
        yield
    finally:
        st.immediate -= 1


@contextmanager
def critical() -> Iterator[None]:
    """A section no signal cuts (publishing outputs): a stop or exit requested meanwhile takes
    effect when it ends (a stop raises :class:`Interrupted` there unless the work is
    cooperative)."""
    st = _state
    st.critical += 1
    try:
        yield
    finally:
        st.critical -= 1
    if st.critical == 0:
        if st.exit_pending:
            _hard_exit()
        if st.stop_pending and st.signum is not None and not st.cooperative:
            st.stop_pending = False
            _raise_now()
