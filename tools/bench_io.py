"""Benchmark of fgloc.io: CARMEN import, MCAP write/read throughput, peak memory while reading.

Usage: /work/venv/bin/python tools/bench_io.py [--minutes 10] [--shared ../shared/data]
Prints a table; no assertions (tests check behaviour, this measures speed).
"""

from __future__ import annotations

import argparse
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

from fgloc.io.convert import import_log
from fgloc.io.log import LogReader, LogWriter
from fgloc.types import CompassHeading, LaserScan, Odometry, StaticTransform

REPO = Path(__file__).resolve().parents[1]


def write_big(path: Path, minutes: float) -> int:
    """A log shaped like the paper's robot: 25 Hz 270 deg scans (1081 beams), 50 Hz odom and compass."""
    rng = np.random.default_rng(0)
    n = 0
    with LogWriter(path) as w:
        w.write("/tf_static", [StaticTransform("base_link", "laser", np.array([0.2, 0.0, 0.0]))])
        t_end = 60.0 * minutes
        for k in range(int(t_end * 50)):
            t = 1000.0 + k * 0.02
            w.write("/odom", Odometry(t, np.array([0.8, 0.0, 0.01]), np.eye(3) * 1e-4))
            w.write("/imu", CompassHeading(t + 0.001, yaw_rad=0.01 * k, yaw_rate_radps=0.01, yaw_var=1e-4))
            n += 2
            if k % 2 == 0:
                r = rng.uniform(0.5, 50.0, 1081).astype(np.float32)
                r[::50] = np.inf
                w.write("/scan", LaserScan(t + 0.005, -2.356194, 0.004363323, 0.5, 50.0, r))
                n += 1
    return n + 1


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--shared", type=Path, default=REPO.parent / "shared" / "data")
    a = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as d:
        for name in ("aces.clf.bz2", "intel.clf.bz2"):
            src = a.shared / "radish" / name
            if not src.exists():
                continue
            res = import_log(src, Path(d) / (name + ".mcap"), progress=False)
            rows.append((f"import {name}", f"{res.seconds:.2f} s",
                         f"scans {res.counts.get('/scan', 0)}, odom {res.counts.get('/odom', 0)}"))
        big = Path(d) / "big.mcap"
        t0 = time.perf_counter()
        n = write_big(big, a.minutes)
        tw = time.perf_counter() - t0
        size = big.stat().st_size
        rows.append((f"write {a.minutes:g}-min log", f"{tw:.1f} s",
                     f"{n} msgs, {n / tw:.0f} msg/s, {size / 1e6:.1f} MB"))
        t0 = time.perf_counter()
        r = LogReader(big)
        m = sum(1 for _ in r.messages())
        tr = time.perf_counter() - t0
        rows.append(("read (LogReader.messages)", f"{tr:.1f} s", f"{m} msgs, {m / tr:.0f} msg/s"))
        tracemalloc.start()  # separate run: tracing slows allocation down
        r = LogReader(big)
        m = sum(1 for _ in r.messages())
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        rows.append(("peak memory while reading", "", f"Python heap peak {peak / 1e6:.1f} MB for a "
                     f"{size / 1e6:.1f} MB file ({peak / size:.2f} x)"))
        cut = Path(d) / "cut.mcap"  # a recorder killed at 90 %: no index, streamed
        with big.open("rb") as f, cut.open("wb") as g:
            g.write(f.read(int(size * 0.9)))
        tracemalloc.start()
        t0 = time.perf_counter()
        rc = LogReader(cut)
        mc = sum(1 for _ in rc.messages())
        tc = time.perf_counter() - t0
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        rows.append(("read truncated at 90 % (traced)", f"{tc:.1f} s",
                     f"{mc} msgs, heap peak {peak / 1e6:.1f} MB; {rc.truncated}"))
        t0 = time.perf_counter()
        ns = sum(1 for _ in r.messages({"/scan"}))
        ts = time.perf_counter() - t0
        rows.append(("read /scan only", f"{ts:.1f} s", f"{ns} scans, {ns / ts:.0f} scans/s"))
    w0 = max(len(r[0]) for r in rows)
    for name, t, info in rows:
        print(f"{name:<{w0}}  {t:>8}  {info}")


if __name__ == "__main__":
    main()
