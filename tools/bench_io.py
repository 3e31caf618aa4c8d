"""Benchmark of fgloc.io: decoders (fixed-layout vs generic), log reading, run.mcap writing
(raw copy vs re-encode), CARMEN import, memory while reading.

Usage: python tools/bench_io.py [--minutes 2] [--repeats 5] [--shared ../shared/data]
Prints one table of medians over the repeats (min-max in brackets); no assertions (tests check
behaviour, this measures speed).  The generated log is shaped like the paper's robot: 25 Hz
1081-beam scans, 50 Hz odometry, compass and /tf (two transforms).
"""

from __future__ import annotations

import argparse
import io
import os
import statistics
import tempfile
import time
import tracemalloc
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from fgloc.io import fastcdr, open_log
from fgloc.io.convert import import_log
from fgloc.io.mcap_writer import LogWriter
from fgloc.io.msgdefs import full_text
from fgloc.io.ros import FROM_ROS, compass_to_ros, imu_to_ros, odom_to_ros, scan_to_ros, tf_to_ros
from fgloc.io.topics import IMU, LASER_SCAN, ODOMETRY, TF_MESSAGE
from fgloc.types import CompassHeading, Imu, LaserScan, Odometry, StaticTransform

REPO = Path(__file__).resolve().parents[1]


def write_big(path: Path, minutes: float) -> int:
    """A log shaped like the paper's robot: 25 Hz 270 deg scans (1081 beams), 50 Hz odom, compass, /tf."""
    rng = np.random.default_rng(0)
    n = 0
    with LogWriter(path) as w:
        w.write("/tf_static", [StaticTransform("base_link", "laser", np.array([0.2, 0.0, 0.0]))])
        t_end = 60.0 * minutes
        for k in range(int(t_end * 50)):
            t = 1000.0 + k * 0.02
            w.write("/odom", Odometry(t, np.array([0.8, 0.0, 0.01]), np.eye(3) * 1e-4,
                                      np.array([0.016 * k, 0.0, 0.0002 * k]), np.eye(3) * 1e-3))
            w.write("/imu", CompassHeading(t + 0.001, yaw_rad=0.01 * k, yaw_rate_radps=0.01, yaw_var=1e-4))
            w.write("/tf", [StaticTransform("odom", "base_link", np.array([0.016 * k, 0.0, 0.0002 * k])),
                            StaticTransform("map", "odom", np.array([0.1, 0.2, 0.01]))], stamp=t + 0.002)
            n += 3
            if k % 2 == 0:
                r = rng.uniform(0.5, 50.0, 1081).astype(np.float32)
                r[::50] = np.inf
                w.write("/scan", LaserScan(t + 0.005, -2.356194, 0.004363323, 0.5, 50.0, r))
                n += 1
    return n + 1


def timed(fn: Callable[[], Any], repeats: int) -> tuple[float, float, float, Any, float]:
    """(median, min, max) wall seconds of ``fn`` over ``repeats`` runs, its last result, and the
    median CPU seconds of this process (less sensitive to the machine's load than the wall time)."""
    ts, cs, out = [], [], None
    for _ in range(repeats):
        c0, t0 = time.process_time(), time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t0)
        cs.append(time.process_time() - c0)
    return statistics.median(ts), min(ts), max(ts), out, statistics.median(cs)


def rate(n: int, t: tuple[float, float, float, Any, float], unit: str = "msg/s") -> str:
    med, lo, hi, _, cpu = t
    return f"{n / med:>10,.0f} {unit}  [{n / hi:,.0f}-{n / lo:,.0f}]  CPU {n / max(cpu, 1e-9):,.0f}"


def generic_decoder(type_name: str) -> Callable[[bytes], Any]:
    from mcap.records import Schema
    from mcap_ros2.decoder import DecoderFactory

    schema = Schema(id=1, name=type_name, encoding="ros2msg", data=full_text(type_name).encode())
    dec = DecoderFactory().decoder_for("cdr", schema)
    assert dec is not None
    return dec  # type: ignore[no-any-return]


def generic_write(path_or_buf: Any, msgs: list[tuple[str, object]]) -> None:
    """The old run.mcap path: mcap_ros2's generic encoder on dicts (no fast scan encoder)."""
    from mcap_ros2.writer import Writer

    to = {LaserScan: (LASER_SCAN, scan_to_ros), Odometry: (ODOMETRY, odom_to_ros),
          CompassHeading: (IMU, compass_to_ros), Imu: (IMU, imu_to_ros)}
    w = Writer(path_or_buf)
    schemas: dict[str, Any] = {}
    for topic, m in msgs:
        if isinstance(m, list):
            name, conv, st = TF_MESSAGE, tf_to_ros, 0.0
        else:
            (name, conv), st = to[type(m)], m.stamp  # type: ignore[attr-defined]
        if name not in schemas:
            schemas[name] = w.register_msgdef(name, full_text(name))
        w.write_message(topic, schemas[name], conv(m, st), log_time=int(st * 1e9))  # type: ignore[arg-type]
    w.finish()


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--minutes", type=float, default=2.0)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--shared", type=Path, default=REPO.parent / "shared" / "data")
    a = ap.parse_args()
    R = a.repeats
    rows: list[tuple[str, str]] = []
    with tempfile.TemporaryDirectory() as d:
        big = Path(d) / "big.mcap"
        t0 = time.perf_counter()
        n = write_big(big, a.minutes)
        size = big.stat().st_size
        rows.append((f"generated {a.minutes:g}-min log",
                     f"{n} msgs, {size / 1e6:.1f} MB in {time.perf_counter() - t0:.1f} s"))
        src = open_log(big)
        recs: dict[str, list[Any]] = {}
        for rec in src.records():
            recs.setdefault(rec.topic, []).append(rec)
        # -- decoders on the raw bytes of each topic
        for topic, type_name, fast in (("/odom", ODOMETRY, fastcdr.decode_odometries),
                                       ("/imu", IMU, fastcdr.decode_imus),
                                       ("/tf", TF_MESSAGE, fastcdr.decode_tf_messages),
                                       ("/scan", LASER_SCAN, fastcdr.decode_laser_scans)):
            datas = [r.data for r in recs[topic]]
            dec, conv = generic_decoder(type_name), FROM_ROS[type_name]
            unit = "scans/s" if topic == "/scan" else "msg/s"
            tf_ = timed(lambda datas=datas, fast=fast: fast(datas), R)
            tg = timed(lambda datas=datas, dec=dec, conv=conv, topic=topic: [conv(dec(x), topic) for x in datas],
                       max(1, R // 2))
            rows.append((f"decode {type_name}: fixed-layout (batch)", rate(len(datas), tf_, unit)))
            rows.append((f"decode {type_name}: generic mcap_ros2 + conversion",
                         rate(len(datas), tg, unit) + f"  (fixed-layout {tg[0] / tf_[0]:.1f}x faster)"))
        # -- the reader, whole log and one topic
        t = timed(lambda: sum(1 for _ in open_log(big).messages()), R)
        rows.append(("read log: open_log(...).messages(), all topics",
                     rate(n, t) + f"  ({size / 1e6 / t[0]:.0f} MB/s)"))
        for topic, unit in (("/scan", "scans/s"), ("/odom", "msg/s"), ("/imu", "msg/s")):
            k = len(recs[topic])
            t = timed(lambda topic=topic: sum(1 for _ in open_log(big).messages({topic})), R)
            rows.append((f"read {topic} only (every chunk decompressed)", rate(k, t, unit)))
        # -- writing run.mcap: raw copy vs re-encode vs the old generic encoder
        allrecs = list(open_log(big).records())
        msgs = [(r.topic, r.msg) for r in allrecs]
        out = Path(d) / "out.mcap"

        def copy_raw() -> None:
            with LogWriter(out) as w:
                for r in allrecs:
                    w.copy(r)

        def reencode() -> None:
            with LogWriter(out) as w:
                for topic, m in msgs:
                    w.write(topic, m)

        tc = timed(copy_raw, R)
        te = timed(reencode, max(1, R // 2))
        tg = timed(lambda: generic_write(io.BytesIO(), msgs), 1)
        rows.append(("write run.mcap: raw copy (LogWriter.copy)", rate(n, tc)))
        rows.append(("write run.mcap: re-encode (LogWriter.write, fixed-layout)",
                     rate(n, te) + f"  (raw copy {te[0] / tc[0]:.1f}x faster)"))
        rows.append(("write run.mcap: generic mcap_ros2 encoder (before)",
                     rate(n, tg) + f"  (raw copy {tg[0] / tc[0]:.1f}x faster)"))
        # -- memory and a cut file
        tracemalloc.start()
        m = sum(1 for _ in open_log(big).messages())
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        rows.append(("peak Python heap while reading", f"{peak / 1e6:.1f} MB for a {size / 1e6:.1f} MB file, {m} msgs"))
        cut = Path(d) / "cut.mcap"
        with big.open("rb") as f, cut.open("wb") as g:
            g.write(f.read(int(size * 0.9)))
        t = timed(lambda: sum(1 for _ in open_log(cut).messages()), max(1, R // 2))
        rows.append(("read truncated at 90 % (linear walk)", rate(t[3], t) + f"  ({t[3]} msgs)"))
        # -- CARMEN
        for name in ("aces.clf.bz2", "intel.clf.bz2"):
            p = a.shared / "radish" / name
            if not p.exists():
                continue
            t = timed(lambda p=p: sum(1 for _ in open_log(p).messages()), 1)
            rows.append((f"read CARMEN {name} (open_log, 2 passes)", rate(t[3], t) + f"  ({t[3]} msgs)"))
            res = import_log(p, Path(d) / (name + ".mcap"), progress=False)
            rows.append((f"import {name}", f"{res.seconds:.2f} s, scans {res.counts.get('/scan', 0)}, "
                         f"odom {res.counts.get('/odom', 0)}"))
    w0 = max(len(r[0]) for r in rows)
    print(f"fgloc.io benchmark: medians over {R} repeats [slowest-fastest], wall time; CPU: the median over the "
          f"CPU time of this process; load average {', '.join(f'{x:.1f}' for x in os.getloadavg())}")
    for name, info in rows:
        print(f"{name:<{w0}}  {info}")


if __name__ == "__main__":
    main()
