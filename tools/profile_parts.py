#!/usr/bin/env python
"""Where a run's time goes, by part: the main thread's time, each call's charged to one part.

In this process, on a log with its map (``fgloc bench speed``'s ``WORKDIR/office-120s``: ``log.mcap`` +
``map.yaml``): ``run`` times :func:`fgloc.app.run.run_log` with the defaults (the whole command
after its imports: reading, localizing, run.mcap, the view's channels, the outputs), ``pipeline``
``Session(Localizer).run`` on the decoded messages (smoother + native, ``frontend_every`` 2, as
``fgloc bench speed``'s in-memory row).  One warm-up run (numba's kernels loaded), then
``--repeats`` runs.

The parts are entry points wrapped at their classes' public methods; a call's time (wall,
``time.perf_counter_ns``; ``--cpu``: thread CPU) goes to the innermost wrapped part it is in
(exclusive); the total per run is the main thread's CPU either way:

* back-end: every public method of the smoother's classes (the localizer's calls: odometry,
  compass / gyro readings, keyframes, predictions, covariances), the Python around GTSAM;
* smoother solve: ``IncrementalFixedLagSmoother.update`` (iSAM2's update, C++), less
* custom factors: the Python callbacks of ``gtsam.CustomFactor`` made during the run;
* front-end: ``match`` of the front-end (preprocessing, the compiled matcher);
* gate: the public methods of the jump gate, recovery, relocalization and map-agreement classes;
* monitor / status: those of the monitor, pose status, coverage, divergence and statistics classes;
* sources: the source handlers (``handle`` / ``__call__``) and the odometry tracker's ``step`` (the
  localizer's code between them and the back-end counts here);
* view channels (``run``): the view hook's ``on_message`` / ``on_scan`` / ``close``;
* run.mcap (``run``): the log writer's ``copy`` / ``write`` (the inputs copied, ``/fused_pose``);
* the rest: the loop, reading and decoding the log (a generator: its time is its consumer's), the
  outputs.

Each entry into a part costs two clock reads (wall ~0.2 us, thread CPU ~2 us: a system call; a call
from inside the same part none); the back-end, the sources and the monitor are entered tens of
thousands of times per run: compare the total with ``--plain`` (no wrapping) for the overhead.
Wall time counts what the machine's load takes from the thread, in proportion to where it is;
load-independent counts need callgrind.

    python tools/profile_parts.py WORKDIR/office-120s [--mode run|pipeline] [--repeats 3] [--cpu] [--plain]
                                  [--backend-methods]
"""

from __future__ import annotations

import argparse
import functools
import importlib
import inspect
import pkgutil
import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any


class PartClock:
    """Exclusive time per part: a call's time goes to the innermost wrapped call it is in."""

    def __init__(self, clock: Callable[[], int] = time.perf_counter_ns) -> None:
        self.clock = clock
        self.ns: Counter[str] = Counter()
        self.calls: Counter[str] = Counter()
        self.stack: list[list[Any]] = [["the rest", clock()]]

    def reset(self) -> None:
        self.ns.clear()
        self.calls.clear()
        self.stack = [["the rest", self.clock()]]

    def close(self) -> None:
        top = self.stack[-1]
        now = self.clock()
        self.ns[top[0]] += now - top[1]
        top[1] = now

    def wrap(self, fn: Callable[..., Any], part: str) -> Callable[..., Any]:
        ns, calls, clock = self.ns, self.calls, self.clock  # cleared in place by reset(); the stack is replaced

        @functools.wraps(fn)
        def timed(*a: Any, **k: Any) -> Any:
            st = self.stack
            top = st[-1]
            if top[0] == part:  # inside the same part: no clock read
                return fn(*a, **k)
            now = clock()
            ns[top[0]] += now - top[1]
            frame = [part, now]
            st.append(frame)
            calls[part] += 1  # entries into the part (calls from inside it are not counted)
            try:
                return fn(*a, **k)
            finally:
                now = clock()
                ns[part] += now - frame[1]
                st.pop()
                st[-1][1] = now

        timed.profile_parts_wrapped = True  # type: ignore[attr-defined]
        return timed

    def wrap_class(self, cls: type, part: str, names: set[str] | None = None) -> None:
        """Wrap ``cls``'s own plain methods: ``names``, or every public one."""
        for n, v in list(vars(cls).items()):
            if names is not None and n not in names:
                continue
            if names is None and n.startswith("_"):
                continue
            if inspect.isfunction(v) and not getattr(v, "profile_parts_wrapped", False):
                setattr(cls, n, self.wrap(v, part))

    def wrap_module(self, name: str, part: str, names: set[str] | None = None) -> None:
        """Wrap the public methods (or ``names``) of every class defined in module ``name``."""
        m = importlib.import_module(name)
        for v in list(vars(m).values()):
            if inspect.isclass(v) and v.__module__ == name:
                self.wrap_class(v, part, names)


BACKEND = "back-end (Python around GTSAM)"
SOLVE = "smoother solve (iSAM2 update)"
CUSTOM = "custom factors (Python callbacks)"
FRONTEND = "front-end (match)"
GATE = "gate / recovery / relocalization / agreement"
MONITOR = "monitor / status / coverage / divergence / stats"
SOURCES = "sources, odometry tracker (with the localizer between them)"
VIEW = "view channels"
MCAP = "run.mcap: inputs copied, /fused_pose"


def instrument(clock: PartClock, by_method: bool = False) -> None:
    """Wrap the parts (``by_method``: the back-end per public method, each its own part)."""
    import gtsam

    from fgloc.backends.smoother.sliding_window import SlidingWindowSmoother
    from fgloc.frontends.base import FrontendBase
    from fgloc.io.mcap_writer import LogWriter
    from fgloc.localization import sources
    from fgloc.localization.odometry import OdometryTracker
    from fgloc.view.hook import ViewHook

    smoother = gtsam.IncrementalFixedLagSmoother
    smoother.update = clock.wrap(smoother.update, SOLVE)
    plain_factor = gtsam.CustomFactor

    class TimedCustomFactor(plain_factor):  # type: ignore[misc, valid-type]
        def __init__(self, noise: Any, keys: Any, error: Callable[..., Any]) -> None:
            super().__init__(noise, keys, clock.wrap(error, CUSTOM))

    gtsam.CustomFactor = TimedCustomFactor
    for cls in SlidingWindowSmoother.__mro__:
        if cls.__module__.startswith("fgloc.backends"):
            if by_method:
                for n in vars(cls):
                    if not n.startswith("_"):
                        clock.wrap_class(cls, f"{BACKEND}: {n}", {n})
            else:
                clock.wrap_class(cls, BACKEND)
    clock.wrap_class(FrontendBase, FRONTEND, {"match"})
    for name in ("gate", "gate_records", "recovery", "relocalization", "agreement"):
        clock.wrap_module(f"fgloc.localization.{name}", GATE)
    for name in ("monitor", "status", "coverage", "divergence", "stats", "odometry_coverage"):
        clock.wrap_module(f"fgloc.localization.{name}", MONITOR)
    for mi in pkgutil.iter_modules(sources.__path__):
        clock.wrap_module(f"fgloc.localization.sources.{mi.name}", SOURCES, {"__call__", "handle"})
    clock.wrap_class(OdometryTracker, SOURCES, {"step"})
    clock.wrap_class(ViewHook, VIEW, {"on_message", "on_scan", "close"})
    clock.wrap_class(LogWriter, MCAP, {"copy", "write"})


def runner(folder: Path, mode: str, out: Path) -> Callable[[], None]:
    if mode == "run":
        from fgloc.app.run import RunRequest, run_log

        def run() -> None:
            run_log(RunRequest(log=folder / "log.mcap", map_yaml=folder / "map.yaml", outdir=out, force=True))

        return run
    from fgloc.config import load_config
    from fgloc.io import open_log
    from fgloc.localization import Localizer, Session
    from fgloc.maps import OccupancyMap

    src = open_log(folder / "log.mcap")
    mount = src.laser_mount()
    want = [t for t in ("/scan", "/odom", "/imu", "/tf_static") if src.has(t)]
    msgs = list(src.messages(want))
    occ = OccupancyMap.load(folder / "map.yaml")
    cfg = load_config(None, {"pipeline": {"frontend_every": 2}})

    def pipeline() -> None:
        loc = Localizer(occ, mount, backend="smoother", frontend="native", config=cfg)
        Session(loc).run(msgs)

    return pipeline


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("folder", type=Path, help="a folder with log.mcap and map.yaml (fgloc bench speed's)")
    ap.add_argument("--mode", choices=("run", "pipeline"), default="run")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--plain", action="store_true", help="no wrapping: the totals alone (the overhead)")
    ap.add_argument("--backend-methods", action="store_true", help="the back-end split by its public methods")
    ap.add_argument("--cpu", action="store_true",
                    help="split thread CPU (a system call per clock read, ~2 us) instead of wall time (~0.2 us)")
    ap.add_argument("--out", type=Path, default=None, help="run's output folder (default: a temporary one)")
    args = ap.parse_args()

    import tempfile

    clock = PartClock(time.thread_time_ns if args.cpu else time.perf_counter_ns)
    if not args.plain:
        instrument(clock, args.backend_methods)
    with tempfile.TemporaryDirectory() as tmp:
        run = runner(args.folder, args.mode, args.out or Path(tmp) / "out")
        run()  # warm-up: numba's kernels loaded, the file cache filled
        totals: list[float] = []
        per_part: Counter[str] = Counter()
        for _ in range(args.repeats):
            clock.reset()
            t0 = time.thread_time()
            run()
            totals.append(time.thread_time() - t0)
            clock.close()
            per_part.update(clock.ns)
    totals.sort()
    print(f"{args.mode} {args.folder.name}: main thread CPU per run {totals[len(totals) // 2]:.3f} s "
          f"(median; {', '.join(f'{t:.3f}' for t in totals)}){' without wrapping' if args.plain else ''}")
    if args.plain:
        return
    whole = sum(per_part.values())
    what = "thread CPU" if args.cpu else "wall time"
    print(f"| part | share of the main thread's {what} | s per run | entries per run |")
    print("|---|--:|--:|--:|")
    for part, ns in per_part.most_common():
        print(f"| {part} | {100.0 * ns / whole:.1f} % | {ns / 1e9 / args.repeats:.3f} | "
              f"{clock.calls[part]} |")


if __name__ == "__main__":
    main()
