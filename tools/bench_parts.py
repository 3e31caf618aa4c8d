#!/usr/bin/env python
"""CPU time per call of the per-message pieces of ``fgloc run`` around the back-end and the matcher.

On a log written by ``fgloc bench speed`` (``WORKDIR/office-120s``: ``log.mcap`` + ``map.yaml``) or
any log with its map, in this process, CPU time (``time.process_time``) per call, best of
``--repeats`` passes over all the log's scans:

* ``preprocess``: the front-ends' shared scan preprocessing (valid beams -> de-skewed points in
  ``base_link``), with the odometry motion between scans as the localizer hands it;
* ``check_guess``: the guess check before each match (at the ground-truth poses when the log has
  them, else at the map's free cells);

and with ``--runs N`` the whole ``fgloc run`` (:func:`fgloc.app.run.run_log`, defaults) in this
process N times, its phases in thread CPU time (``fgloc.app.run.PHASE_CLOCK``), medians: setup
(after the imports), reading the log, writing run.mcap (inputs and ``/fused_pose``), the view's
channels, localizing (the rest of the loop: back-end, front-end, localizer, session), the outputs
(TUM files, config, evaluation); ``--every1`` with ``pipeline.frontend_every: 1``.  The phases are
the main thread's; ``process`` is the whole ``run_log`` call in process CPU time, run.mcap's chunk
writer thread (compression, file writes) included.

Compare two source trees with ``PYTHONPATH=TREE python tools/bench_parts.py ...`` alternately
(the machine's load drifts).

    python tools/bench_parts.py WORKDIR/office-120s [--repeats 5] [--runs 3 [--every1]]
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np


def best_us(fn: Callable[[], int], repeats: int) -> float:
    """Best CPU microseconds per call over ``repeats`` passes (``fn`` returns its call count)."""
    best = float("inf")
    for _ in range(repeats):
        c0 = time.process_time()
        n = fn()
        best = min(best, (time.process_time() - c0) / max(n, 1))
    return 1e6 * best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("folder", type=Path, help="a folder with log.mcap and map.yaml (fgloc bench speed's)")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--runs", type=int, default=0, help="also run_log N times: its phases in thread CPU time")
    ap.add_argument("--every1", action="store_true", help="--runs with pipeline.frontend_every: 1")
    args = ap.parse_args()

    from fgloc.frontends.base import ScanPreprocessor, check_guess
    from fgloc.geometry import between
    from fgloc.io import open_log
    from fgloc.maps import OccupancyMap
    from fgloc.types import LaserScan, Odometry

    src = open_log(args.folder / "log.mcap")
    occ = OccupancyMap.load(args.folder / "map.yaml")
    mount = src.laser_mount()
    scans: list[LaserScan] = []
    deltas: list[np.ndarray | None] = []
    odom_pose: np.ndarray | None = None
    at_last_scan: np.ndarray | None = None
    for _topic, msg in src.messages([t for t in ("/scan", "/odom") if src.has(t)]):
        if isinstance(msg, Odometry) and msg.pose is not None:
            odom_pose = np.asarray(msg.pose, dtype=float)
        elif isinstance(msg, LaserScan):
            scans.append(msg)
            deltas.append(None if at_last_scan is None or odom_pose is None else between(at_last_scan, odom_pose))
            at_last_scan = odom_pose
    gt = src.ground_truth()
    if gt is not None and len(gt):
        guesses = list(gt.poses[:: max(1, len(gt) // max(len(scans), 1))][: len(scans)])
    else:
        free = occ.free_cell_centers()
        pick = np.random.default_rng(0).integers(0, len(free), max(len(scans), 1))
        guesses = [np.array([free[i, 0], free[i, 1], 0.1]) for i in pick]

    def preprocess() -> int:
        pre = ScanPreprocessor(mount)
        for scan, delta in zip(scans, deltas, strict=True):
            pre(scan, delta)
        return len(scans)

    def guess() -> int:
        for g in guesses:
            check_guess(occ, g)
        return len(guesses)

    print(f"{args.folder}: {len(scans)} scans, {len(guesses)} guesses; CPU us per call, best of {args.repeats}")
    for name, fn in (("preprocess", preprocess), ("check_guess", guess)):
        print(f"  {name:12s} {best_us(fn, args.repeats):8.1f}")
    if args.runs > 0:
        run_phases(args.folder, args.runs, args.every1)


def run_phases(folder: Path, runs: int, every1: bool) -> None:
    """``run_log`` on ``folder``'s log ``runs`` times; the median thread CPU seconds of each phase."""
    import statistics
    import tempfile
    import types

    import fgloc.app.run as app_run
    from fgloc.config import load_config

    config = load_config(None, {"pipeline": {"frontend_every": 1}}) if every1 else None
    if hasattr(app_run, "PHASE_CLOCK"):
        app_run.PHASE_CLOCK = time.thread_time
    else:  # an older tree (before PHASE_CLOCK): its timers read time.perf_counter
        app_run.time = types.SimpleNamespace(perf_counter=time.thread_time)  # type: ignore[assignment]
    keys = ("setup_s", "read_s", "write_s", "view_s", "localize_s", "outputs_s", "total_s")
    got: dict[str, list[float]] = {k: [] for k in (*keys, "process_s")}
    with tempfile.TemporaryDirectory() as out:
        for _ in range(runs):
            c0 = time.process_time()
            res = app_run.run_log(app_run.RunRequest(log=folder / "log.mcap", outdir=Path(out), force=True,
                                                     map_yaml=folder / "map.yaml", config=config))
            got["process_s"].append(time.process_time() - c0)
            for k in keys:
                got[k].append(res.timings[k])
    print(f"run_log{' (frontend_every 1)' if every1 else ''}: thread CPU s, median of {runs} "
          f"[min-max]")
    for k in (*keys, "process_s"):
        v = got[k]
        print(f"  {k[:-2]:12s} {statistics.median(v):7.3f} [{min(v):.3f}-{max(v):.3f}]")


if __name__ == "__main__":
    main()
