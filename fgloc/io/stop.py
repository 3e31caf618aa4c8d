"""Stopping a command on SIGINT or SIGTERM: cleanly at the first signal, at once at the second.

The CLI calls :func:`handling` around every command (a service manager's SIGTERM is handled as
a Ctrl-C; a signal the parent set to be ignored stays ignored):

* the **first** signal requests a stop.  Work that declared itself :func:`cooperative` (its
  loops call :func:`checkpoint`: ``fgloc run`` per message, ``fgloc map`` per scan, ``fgloc
  live`` its stop event) stops at the next check by raising :class:`Interrupted`, so numba or
  GTSAM code is never left in the middle of a call; other work is interrupted at once
  (Python's own Ctrl-C behaviour).  Either way the command's staged outputs are discarded, its
  previous outputs stay as they were (:mod:`fgloc.io.outputs`), and the CLI exits 130 with one
  line ``fgloc: interrupted (SIGINT)``;
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
        self.cooperative = 0
        self.critical = 0
        self.exit_pending = False
        self.stop_pending = False  # a first signal held by a critical section (raised when it ends)
        self.raised = False  # an Interrupted was raised (the CLI prints the line)
        self.on_stop: list[Callable[[], None]] = []
        self.hurry: list[Callable[[], None]] = []
        self.hard_exit: dict[int, Callable[[], None]] = {}
        self.notes: list[str] = []


_state = _State()
_lock = threading.Lock()


def requested() -> int | None:
    """The signal number of a requested stop, or None."""
    return _state.signum


def interrupted() -> int | None:
    """The signal whose stop ended the command (an :class:`Interrupted` was raised), or None."""
    return _state.signum if _state.raised else None


def checkpoint() -> None:
    """Raise :class:`Interrupted` when a stop was requested (outside a :func:`critical` section)."""
    if _state.signum is not None and not _state.critical:
        _state.raised = True
        raise Interrupted(_state.signum)


def note(line: str) -> None:
    """A clause for the interrupted line (e.g. which outputs were left as they were)."""
    with _lock:
        if line not in _state.notes:
            _state.notes.append(line)


def notes() -> list[str]:
    return list(_state.notes)


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


def _on_signal(signum: int, frame: object) -> None:
    st = _state
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
        st.raised = True
        raise Interrupted(signum)
    if st.hurry and st.count == 2:
        for fn in list(st.hurry):
            fn()
        return
    if st.critical:
        st.exit_pending = True
        return
    _hard_exit()


@contextmanager
def handling() -> Iterator[None]:
    """Install the handlers (main thread only) for the duration of one command; restores the
    previous ones and forgets the command's stop afterwards."""
    global _state
    old: dict[signal.Signals, object] = {}
    if threading.current_thread() is threading.main_thread():
        for s in SIGNALS:
            prev = signal.getsignal(s)
            if prev is signal.SIG_IGN:  # e.g. a background job of a shell, or nohup: stays ignored
                continue
            old[s] = prev
            signal.signal(s, _on_signal)
    try:
        yield
    finally:
        for sig, h in old.items():
            signal.signal(sig, h)  # type: ignore[arg-type]
        _state = _State()


@contextmanager
def cooperative(on_stop: Callable[[], None] | None = None,
                on_hurry: Callable[[], None] | None = None) -> Iterator[None]:
    """Within: a first signal only requests the stop (the work calls :func:`checkpoint`, or
    watches ``on_stop``, called from the handler); ``on_hurry``: called at the second signal
    instead of exiting (the third exits)."""
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
        if st.stop_pending and st.signum is not None:
            st.stop_pending = False
            st.raised = True
            raise Interrupted(st.signum)
