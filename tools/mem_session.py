"""``fgloc live --ros2``'s localization session alone, offline and as fast as it goes: where its memory grows.

The paper run simulated ``LOOPS`` times round, its messages fed to the session ``fgloc live`` builds (the
smoother, the native matcher, a sink that wants the fused pose, the localizer's history kept 60 s back), no
DDS, no threads; every 30 s of log: RSS, glibc malloc's bytes in use and free (``mallinfo2``), Python's
blocks and (``--trace``, from 2 min of log on) what tracemalloc holds, with every 3 min the source lines
whose live memory grew most since the first snapshot.

    python tools/mem_session.py --loops 6 --trace
"""

from __future__ import annotations

import argparse
import gc
import sys
import tempfile
import tracemalloc
from pathlib import Path

import numpy as np


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--loops", type=int, default=6)
    ap.add_argument("--trace", action="store_true", help="tracemalloc from 2 min of log on, snapshots every 3 min")
    ap.add_argument("--frames", type=int, default=1,
                    help="with --trace: frames kept per allocation; > 1 groups the growth by whole traceback")
    ap.add_argument("--top", type=int, default=8, help="with --trace: the growing lines (tracebacks) printed")
    a = ap.parse_args()
    from fgloc import memory
    from fgloc.io import open_log
    from fgloc.localization import build_session
    from fgloc.localization.session import BaseSink
    from fgloc.maps import load_map
    from fgloc.sim import run_scenario, write_sim

    d = Path(tempfile.mkdtemp(prefix="mem_session_"))
    write_sim(run_scenario({"name": "mem", "loops": a.loops}, seed=0), d)
    r = open_log(d / "log.mcap")

    class Fused(BaseSink):
        wants_fused = True

    s = build_session(load_map(d / "map.yaml"), r.laser_mount(), initial_pose=np.array([2.5, 3.0, 0.0]),
                      sinks=[Fused()])
    s.loc.keep_history(60.0)
    gc.freeze()
    t0: float | None = None
    due = 0.0
    snap0 = None
    for topic, m in r.messages(["/scan", "/odom", "/imu", "/tf_static"]):
        st = getattr(m, "stamp", None)
        if st is not None:
            t0 = st if t0 is None else t0
            if st - t0 >= due:
                if a.trace and due >= 120 and not tracemalloc.is_tracing():
                    tracemalloc.start(max(1, a.frames))
                mi = memory.mallinfo()
                used_mb, free_mb = (mi.in_use_b / 2**20, mi.free_b / 2**20) if mi else (float("nan"),) * 2
                with open("/proc/self/statm") as f:
                    rss = int(f.read().split()[1]) * 4096 / 2**20
                traced = tracemalloc.get_traced_memory()[0] / 2**20 if tracemalloc.is_tracing() else 0.0
                print(f"{due / 60:5.1f} min of log: RSS {rss:7.1f} MB, malloc in use {used_mb:7.2f} MB, "
                      f"free {free_mb:6.2f} MB, traced {traced:6.2f} MB, Python blocks "
                      f"{sys.getallocatedblocks() / 1e3:7.1f} k", flush=True)
                if tracemalloc.is_tracing() and due % 180 == 0:
                    snap = tracemalloc.take_snapshot()
                    if snap0 is None:
                        snap0 = snap
                    else:
                        key = "traceback" if a.frames > 1 else "lineno"
                        for g in snap.compare_to(snap0, key)[:a.top]:
                            frames = list(reversed(list(g.traceback)))  # the allocating line first
                            print(f"    {g.size_diff / 1e3:+8.1f} kB {g.count_diff:+7d} blocks  {frames[0]}")
                            for fr in frames[1:]:
                                print(f"        {fr}")
                due += 30.0
        s.feed(topic, m)
    return 0


if __name__ == "__main__":
    sys.exit(main())
