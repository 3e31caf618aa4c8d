#!/usr/bin/env python
"""Record the calls a localization run makes on its back-end, and replay them on a fresh back-end.

A change inside the back-end that leaves its behaviour alone leaves the calls it is given alone too
(the front-end sees the same predictions): the recorded calls, replayed on the changed back-end,
measure the back-end's own cost without the front-end's, the log's decoding or the start-up, and
``--check`` shows the behaviour unchanged (the online trajectory, its covariances and the back-end's
counters as recorded).

    python tools/replay_backend.py record LOG_DIR CALLS.pkl [--backend smoother] [--frontend native]
    python tools/replay_backend.py replay CALLS.pkl [--check] [--callgrind-lib LIB]

``LOG_DIR`` holds ``log.mcap`` and ``map.yaml`` (as ``fgloc bench speed`` writes them); the run is the
in-memory pipeline of ``fgloc bench speed`` (no sinks, global localization, ``frontend_every``
``--every``).  Compare two source trees by replaying the same ``CALLS.pkl`` with
``PYTHONPATH=TREE``.

Instructions of the replay alone (load-independent): under ``valgrind --tool=callgrind
--instr-atstart=no --collect-atstart=no``, ``--callgrind-lib`` names a shared library whose
``cg_start`` / ``cg_stop`` switch the collection on around the replay; build it from

    #include <valgrind/callgrind.h>
    void cg_start(void) { CALLGRIND_ZERO_STATS; CALLGRIND_START_INSTRUMENTATION; CALLGRIND_TOGGLE_COLLECT; }
    void cg_stop(void) { CALLGRIND_TOGGLE_COLLECT; CALLGRIND_DUMP_STATS_AT("replay"); CALLGRIND_STOP_INSTRUMENTATION; }

with ``gcc -O2 -shared -fPIC -o cgctl.so cgctl.c`` (and ``PYTHONHASHSEED=0``); the replay's count
is the dump's ``summary:`` line.
"""

from __future__ import annotations

import argparse
import copy
import ctypes
import gc
import hashlib
import pickle
import sys
import time
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np


class _Recorder:
    """Stands for the back-end: every method call (arguments deep-copied) and attribute set is kept
    in ``calls`` before it is passed on; attribute reads are passed on."""

    def __init__(self, target: Any, calls: list) -> None:
        object.__setattr__(self, "target", target)
        object.__setattr__(self, "calls", calls)

    def __getattr__(self, name: str) -> Any:
        a = getattr(self.target, name)
        if not (callable(a) and hasattr(a, "__self__")):
            return a

        def call(*args: Any, **kw: Any) -> Any:
            self.calls.append((name, copy.deepcopy(args), copy.deepcopy(kw)))
            return a(*args, **kw)
        return call

    def __setattr__(self, name: str, value: Any) -> None:
        self.calls.append(("__setattr__", (name, copy.deepcopy(value)), {}))
        setattr(self.target, name, value)


def _config(every: int) -> Any:
    from fgloc.config import load_config
    return load_config(None, {"pipeline": {"frontend_every": every}})


def _online(be: Any) -> dict[str, np.ndarray]:
    tr = be.online_trajectory()
    return {"stamps": np.asarray(tr.stamps), "poses": np.asarray(tr.poses), "covs": np.asarray(tr.covs)}


def record(log_dir: Path, out: Path, backend: str, frontend: str, every: int) -> None:
    from fgloc.io import open_log
    from fgloc.localization import Localizer, Session
    from fgloc.maps import OccupancyMap

    src = open_log(log_dir / "log.mcap")
    mount = src.laser_mount()
    msgs = list(src.messages([t for t in ("/scan", "/odom", "/imu", "/tf_static") if src.has(t)]))
    loc = Localizer(OccupancyMap.load(log_dir / "map.yaml"), mount, backend=backend, frontend=frontend,
                    config=_config(every))
    calls: list = []
    be = loc.backend
    loc.backend = _Recorder(be, calls)  # type: ignore[assignment]
    Session(loc).run(msgs)
    with open(out, "wb") as f:
        pickle.dump({"backend": backend, "every": every, "calls": calls, "online": _online(be),
                     "stats": dict(be.stats)}, f)
    print(f"{len(calls)} calls: " + ", ".join(f"{n} {c}" for n, c in Counter(c[0] for c in calls).most_common(8)))


def replay(path: Path, check: bool, callgrind_lib: str | None) -> int:
    from fgloc.backends import make_backend

    with open(path, "rb") as f:
        rec = pickle.load(f)  # noqa: S301 (a file this tool wrote)
    be = make_backend(rec["backend"], _config(rec["every"]))
    cg = ctypes.CDLL(callgrind_lib) if callgrind_lib else None
    gc.collect()
    if cg is not None:
        cg.cg_start()
    c0 = time.process_time()
    for name, args, kw in rec["calls"]:
        if name == "__setattr__":
            setattr(be, args[0], args[1])
        else:
            getattr(be, name)(*args, **kw)
    cpu = time.process_time() - c0
    if cg is not None:
        cg.cg_stop()
    online = _online(be)
    h = hashlib.md5()
    for k in ("stamps", "poses", "covs"):
        h.update(np.ascontiguousarray(online[k]).tobytes())
    print(f"{len(rec['calls'])} calls replayed in {cpu:.3f} s CPU; online trajectory md5 {h.hexdigest()}")
    if not check:
        return 0
    same = all(np.array_equal(online[k], rec["online"][k]) for k in ("stamps", "poses", "covs"))
    same_stats = dict(be.stats) == rec["stats"]
    print(f"online trajectory as recorded: {same}; back-end counters as recorded: {same_stats}")
    return 0 if same and same_stats else 1


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("record", help="run the in-memory pipeline on a log, keep its back-end's calls")
    r.add_argument("log_dir", type=Path)
    r.add_argument("out", type=Path)
    r.add_argument("--backend", default="smoother")
    r.add_argument("--frontend", default="native")
    r.add_argument("--every", type=int, default=2, help="pipeline.frontend_every (default 2, as bench speed)")
    p = sub.add_parser("replay", help="replay recorded calls on a fresh back-end of this source tree")
    p.add_argument("calls", type=Path)
    p.add_argument("--check", action="store_true", help="exit 1 unless the outputs are as recorded")
    p.add_argument("--callgrind-lib", help="shared library with cg_start / cg_stop (see the docstring)")
    a = ap.parse_args(argv)
    if a.cmd == "record":
        record(a.log_dir, a.out, a.backend, a.frontend, a.every)
        return 0
    return replay(a.calls, a.check, a.callgrind_lib)


if __name__ == "__main__":
    sys.exit(main())
