"""The watchdog of a private Ray instance: its processes end when the fgloc process that started it ends.

Ray ties its GCS server and raylet to the driver (Linux's parent-death signal), but not the agents
the raylet starts: after ``kill -9`` of a batch they lived on for 60-120 s.  This process is
started (in a session of its own, so a terminal's Ctrl-C does not reach it) before the instance,
with a pipe on its standard input whose other end only the driver holds.  While the pipe is open
it notes, every :data:`POLL_S`, the driver's descendants (pid and start time: a pid used again
later is not the same process); every process of the instance also carries
``FGLOC_RAY_INSTANCE=<tag>`` in its environment (set by the driver around ``ray.init``, inherited
by everything Ray starts; a process that rewrites its title, as Ray's agents do, may lose it from
``/proc``, hence the tree).  When the pipe closes (the driver shut Ray down, or died however it
died), every noted process still running, every descendant of one and every tagged process is
killed, again until none has been seen for a moment.  Linux (``/proc``) only; elsewhere it exits
at once.

Run as a script (``python -I raywatch.py DRIVER_PID TAG``): it imports nothing of fgloc.
"""

from __future__ import annotations

import os
import select
import signal
import sys
import time

ENV = "FGLOC_RAY_INSTANCE"
POLL_S = 0.2       # the driver's descendants noted this often
QUIET_S = 0.3      # no process of the instance seen for this long: done
GIVE_UP_S = 10.0   # at most this long killing


def _stat(pid: int) -> tuple[int, int] | None:
    """``(ppid, start time in clock ticks)`` of a process, None when it is gone or a zombie (dead,
    waiting for its parent: a container's init may take seconds)."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            raw = f.read()
    except OSError:
        return None
    fields = raw[raw.rfind(b")") + 2 :].split()  # after the command name, which may hold spaces
    if fields[0] in (b"Z", b"X"):
        return None
    return int(fields[1]), int(fields[19])


def _table() -> dict[int, tuple[int, int]]:
    out = {}
    for name in os.listdir("/proc"):
        if name.isdigit() and (st := _stat(int(name))) is not None:
            out[int(name)] = st
    return out


def descendants(roots: set[int], table: dict[int, tuple[int, int]]) -> set[int]:
    """Every process below ``roots`` in ``table`` (pid -> (ppid, start))."""
    children: dict[int, list[int]] = {}
    for pid, (ppid, _) in table.items():
        children.setdefault(ppid, []).append(pid)
    out: set[int] = set()
    todo = list(roots)
    while todo:
        for c in children.get(todo.pop(), []):
            if c not in out:
                out.add(c)
                todo.append(c)
    return out


def tagged(tag: bytes) -> set[int]:
    """The processes (of this user: others' environments are not readable) whose environment, as
    ``/proc`` shows it, holds ``tag`` (``ENV=value``)."""
    me = os.getpid()
    out = set()
    for name in os.listdir("/proc"):
        if not name.isdigit() or int(name) == me:
            continue
        try:
            with open(f"/proc/{name}/environ", "rb") as f:
                env = f.read()
        except OSError:
            continue
        if tag in env.split(b"\0"):
            out.add(int(name))
    return out


def kill_instance(noted: dict[int, int], tag: bytes) -> int:
    """Kill the noted processes (``pid -> start time``) still running as themselves, their descendants
    and the tagged ones, until none is seen for :data:`QUIET_S`; returns how many were killed."""
    me = os.getpid()
    killed: set[int] = set()
    quiet_since: float | None = None
    deadline = time.monotonic() + GIVE_UP_S
    while time.monotonic() < deadline:
        table = _table()
        alive = {p for p, start in noted.items() if p in table and table[p][1] == start}
        pids = (alive | descendants(alive, table) | tagged(tag)) - {me}
        for pid in pids:
            try:
                os.kill(pid, signal.SIGKILL)
                killed.add(pid)
            except OSError:
                pass
        now = time.monotonic()
        if pids:
            quiet_since = None
        elif quiet_since is None:
            quiet_since = now
        elif now - quiet_since >= QUIET_S:
            break
        time.sleep(0.05)
    return len(killed)


def _stop(*_: object) -> None:
    raise InterruptedError


def main(argv: list[str]) -> int:
    if len(argv) != 3 or not os.path.isdir("/proc"):
        return 0
    driver, tag = int(argv[1]), f"{ENV}={argv[2]}".encode()
    for s in (signal.SIGINT, signal.SIGHUP, signal.SIGPIPE):
        signal.signal(s, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _stop)  # a stop request: clean up now
    me = os.getpid()
    noted: dict[int, int] = {}
    stdin = sys.stdin.buffer.raw if hasattr(sys.stdin.buffer, "raw") else sys.stdin.buffer
    try:
        while True:
            table = _table()
            for pid in descendants({driver}, table) - {me}:
                noted.setdefault(pid, table[pid][1])
            ready, _, _ = select.select([stdin], [], [], POLL_S)
            if ready and not os.read(stdin.fileno(), 4096):
                break  # EOF: the driver closed the pipe or is gone
    except (OSError, InterruptedError, ValueError):
        pass
    kill_instance(noted, tag)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
