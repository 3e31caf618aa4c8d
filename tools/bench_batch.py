"""Benchmark ``fgloc batch``: N simulated logs, sequential vs the local process pool vs Ray.

    python tools/bench_batch.py [--logs 20] [--jobs 2] [--repeat 3] [--route-m 25] [--no-cli]

Rows (each repeated ``--repeat`` times, in rotating order; medians and ranges printed):

* ``sequential``: every log one after the other in this process (``fgloc batch`` with the
  in-process engine: no process start, imports and numba caches paid once) - the baseline;
* ``fgloc run`` x N: one ``fgloc run`` process per log, what a shell loop does today;
* ``local pool -j J``: ``--engine local`` (J spawned workers, startup included);
* ``ray -j J``: ``--engine ray`` on a private local Ray instance with J CPUs, startup and
  shutdown included; also without them (``ray, after init``).

Speed-up (wall): the sequential run's wall time over the engine's, paired within each repeat.
Speed-up (CPU time): the sequential run's CPU time over (the engine's job CPU time / workers +
Ray's startup and shutdown), i.e. the speed-up with the cores to itself; "cores busy" is the
jobs' CPU time over the wall time (2.0 = both cores all the time).

Per-log overhead: wall x workers minus the time spent inside the jobs, divided by the
number of logs (what the engine adds around each log: dispatch, pickling, result transfer,
idle workers at the end), and the round trip of an empty job (200 of them) per engine.
Every engine's trajectories are compared byte for byte with the sequential run's.
The load average of the machine is printed before and after each measurement (the load
column: its mean); on a shared machine wall times and speed-ups only mean something at a low
load, the CPU seconds per log (worker CPU time inside the jobs) much less depend on it.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def make_logs(folder: Path, n: int, route_m: float) -> tuple[list[Path], Path]:
    """``n`` simulated runs (seeds 0..n-1) along the paper hall's first side, ``route_m`` long."""
    from tqdm import tqdm

    from fgloc.sim import simulate_paper, write_sim

    folder.mkdir(parents=True, exist_ok=True)
    logs = []
    for seed in tqdm(range(n), desc="simulating logs", unit="log", leave=False):
        dst = folder / f"run{seed:02d}.mcap"
        if not dst.exists():
            sim = simulate_paper(seed=seed, route=[[2.5, 3.0], [2.5 + route_m, 3.0]])
            d = write_sim(sim, folder / "sim" / f"{seed:02d}")
            shutil.copy(d / "log.mcap", dst)
            if not (folder / "map.yaml").exists():
                shutil.copy(d / "map.yaml", folder / "map.yaml")
                shutil.copy(d / "map.pgm", folder / "map.pgm")
        logs.append(dst)
    return logs, folder / "map.yaml"


def noop_job(job, blobs):
    """An empty job: what an engine costs around a log, without the log."""
    from fgloc.batch import JobResult

    return JobResult(job.name, True, row={}, wall_s=0.0)


def run_engine(name: str, engine, logs: list[Path], map_yaml: Path, out: Path) -> dict:
    from fgloc.batch import run_batch
    from fgloc.batch.inputs import run_jobs

    shutil.rmtree(out, ignore_errors=True)
    jobs = run_jobs(logs, out, map_yaml, [2.5, 3.0, 0.0])
    load0 = os.getloadavg()[0]
    t0 = time.perf_counter()
    init_s = 0.0
    if name.startswith("ray"):
        engine.connect()
        init_s = time.perf_counter() - t0
    rep = run_batch(jobs, out, engine, progress=False)
    if name.startswith("ray"):
        t_sd = time.perf_counter()
        engine.shutdown()
        init_s += time.perf_counter() - t_sd
    wall = time.perf_counter() - t0
    assert rep.failed == 0 and rep.ran == len(jobs), [r.error for r in rep.rows if r.error]
    inside = sum(r.wall_s for r in rep.results.values())
    cpu = sum(getattr(r, "cpu_s", 0.0) for r in rep.results.values())
    return {"wall": wall, "init": init_s, "inside": inside, "cpu": cpu, "load": (load0, os.getloadavg()[0])}


def run_cli(logs: list[Path], map_yaml: Path, out: Path) -> dict:
    shutil.rmtree(out, ignore_errors=True)
    exe = Path(sys.executable).parent / "fgloc"
    load0 = os.getloadavg()[0]
    t0 = time.perf_counter()
    for log in logs:
        subprocess.run([str(exe), "run", str(log.resolve()), "--map", str(map_yaml.resolve()), "--initial-pose",
                        "2.5", "3.0", "0.0", "-o", str(out / log.stem), "-q"], check=True, capture_output=True)
    return {"wall": time.perf_counter() - t0, "init": 0.0, "inside": float("nan"), "cpu": float("nan"),
            "load": (load0, os.getloadavg()[0])}


def noop_roundtrip(engine_name: str, jobs: int, n: int = 200) -> float:
    """Milliseconds per empty job through an engine (startup excluded: one warm-up batch first)."""
    from fgloc.batch import Job, make_engine

    eng = make_engine(engine_name, jobs)
    if engine_name == "ray":
        eng.connect()
    try:
        work = [Job("run", f"n{i}", "/nonexistent") for i in range(n)]
        if engine_name == "local":  # the pool starts per run: time a run of n minus a run of 1
            t0 = time.perf_counter()
            list(eng.run(noop_job, work[:1]))
            one = time.perf_counter() - t0
            t0 = time.perf_counter()
            list(eng.run(noop_job, work))
            return 1e3 * (time.perf_counter() - t0 - one) / (n - 1)
        list(eng.run(noop_job, work[:jobs * 2]))  # warm the workers
        t0 = time.perf_counter()
        list(eng.run(noop_job, work))
        return 1e3 * (time.perf_counter() - t0) / n
    finally:
        if engine_name == "ray":
            eng.shutdown()


def same_outputs(a: Path, b: Path, logs: list[Path], flat_b: bool = False) -> bool:
    for log in logs:
        for f in ("trajectory.tum", "online.tum", "fixes.tum"):
            if (a / log.stem / f).read_bytes() != (b / log.stem / f).read_bytes():
                return False
    return True


def fmt_range(v: list[float], digits: int = 1) -> str:
    if len(v) == 1:
        return f"{v[0]:.{digits}f}"
    return f"{statistics.median(v):.{digits}f} ({min(v):.{digits}f}-{max(v):.{digits}f})"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--logs", type=int, default=20)
    ap.add_argument("--jobs", "-j", type=int, default=2)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--route-m", type=float, default=25.0, help="length of each simulated run (m, 0.8 m/s)")
    ap.add_argument("--no-cli", action="store_true", help="skip the one-process-per-log row")
    ap.add_argument("--no-ray", action="store_true")
    ap.add_argument("--workdir", type=Path, default=None, help="keep logs here (default: a temp folder)")
    args = ap.parse_args()

    from rich.console import Console
    from rich.table import Table

    from fgloc.batch import InlineEngine, LocalEngine, RayEngine

    con = Console()
    if not con.is_terminal:
        con = Console(width=220)  # the table whole in a saved log
    work = args.workdir or Path(tempfile.mkdtemp(prefix="fgloc-bench-batch-"))
    logs, map_yaml = make_logs(work / "logs", args.logs, args.route_m)
    from fgloc.io import open_log

    log_s = sum(open_log(p).summary()["duration"] for p in logs)
    con.print(f"{len(logs)} logs, {log_s:.0f} s of log time in all; {os.cpu_count()} CPUs; "
              f"load average {os.getloadavg()[0]:.2f} at the start")
    configs: list[tuple[str, object]] = [("sequential", None), ("local", None)]
    if not args.no_ray:
        configs.append(("ray", None))
    if not args.no_cli:
        configs.append(("cli", None))
    results: dict[str, list[dict]] = {c: [] for c, _ in configs}
    order = [c for c, _ in configs]
    same_reps = 0  # repeats in which every engine wrote the sequential run's trajectories
    for rep in range(args.repeat):
        for name in order[rep % len(order):] + order[: rep % len(order)]:
            out = work / "out" / name
            if name == "sequential":
                r = run_engine(name, InlineEngine(), logs, map_yaml, out)
            elif name == "local":
                r = run_engine(name, LocalEngine(args.jobs), logs, map_yaml, out)
            elif name == "ray":
                r = run_engine("ray", RayEngine(args.jobs), logs, map_yaml, out)
            else:
                r = run_cli(logs, map_yaml, out)
            results[name].append(r)
            con.print(f"  repeat {rep + 1} {name:10s} {r['wall']:7.1f} s  (load {r['load'][0]:.2f} -> "
                      f"{r['load'][1]:.2f})")
        same_reps += all(same_outputs(work / "out" / "sequential", work / "out" / name, logs)
                         for name in order if name != "sequential")
    noop = {"local": [noop_roundtrip("local", args.jobs)]}
    if not args.no_ray:
        noop["ray"] = [noop_roundtrip("ray", args.jobs)]

    seq = results["sequential"]
    seq_cpu = statistics.median(r["cpu"] for r in seq)
    t = Table(title=f"fgloc batch: {len(logs)} logs x {log_s / len(logs):.0f} s, -j {args.jobs}, "
                    f"{args.repeat} repeat(s): median (min-max)")
    cols = ("engine", "wall s", "speed-up (wall)", "startup s", "overhead per log s", "empty job ms",
            "CPU s per log", "cores busy", "speed-up (CPU time)", "load")
    for c in cols:
        t.add_column(c, justify="left" if c == "engine" else "right")
    labels = {"sequential": "sequential (one process)", "local": f"local pool -j {args.jobs}",
              "ray": f"ray, local instance, {args.jobs} CPUs", "cli": f"fgloc run x {len(logs)} (a process each)"}
    md = ["| " + " | ".join(cols) + " |", "|---" + "|--:" * (len(cols) - 1) + "|"]
    for name in order:
        rs = results[name]
        walls = [r["wall"] for r in rs]
        # paired with the sequential run of the same repeat (minutes apart, not an hour: the load drifts)
        speed = [s["wall"] / r["wall"] for s, r in zip(seq, rs, strict=True)]
        workers = 1 if name in ("sequential", "cli") else args.jobs
        over = [(r["wall"] - r["init"]) * workers / len(logs) - r["inside"] / len(logs) for r in rs]
        has_cpu = name != "cli"
        # what the engine would take with its cores to itself: its jobs' CPU time spread over the workers,
        # plus Ray's startup and shutdown; the sequential run's CPU time divided by that
        cpu_speed = [seq_cpu / (r["cpu"] / workers + r["init"]) for r in rs] if has_cpu else []
        cells = [labels[name], fmt_range(walls), fmt_range(speed, 2),
                 fmt_range([r["init"] for r in rs], 1) if name == "ray" else "-",
                 fmt_range(over, 2) if has_cpu else "-",
                 fmt_range(noop[name], 2) if name in noop else "-",
                 fmt_range([r["cpu"] / len(logs) for r in rs], 2) if has_cpu else "-",
                 fmt_range([r["cpu"] / r["wall"] for r in rs], 2) if has_cpu else "-",
                 fmt_range(cpu_speed, 2) if has_cpu else "-",
                 fmt_range([0.5 * (r["load"][0] + r["load"][1]) for r in rs], 1)]
        t.add_row(*cells)
        md.append("| " + " | ".join(cells) + " |")
        if name == "ray":
            w2 = [r["wall"] - r["init"] for r in rs]
            cells = ["ray, after init/shutdown", fmt_range(w2),
                     fmt_range([s["wall"] / w for s, w in zip(seq, w2, strict=True)], 2)] + ["-"] * (len(cols) - 3)
            t.add_row(*cells)
            md.append("| " + " | ".join(cells) + " |")
    con.print(t)
    print("\n".join(md))
    con.print(f"trajectories identical to the sequential run for every engine in {same_reps} of {args.repeat} "
              f"repeat(s) (a repeat where they differ ran while the source tree changed); "
              f"load average {os.getloadavg()[0]:.2f} at the end")
    if args.workdir is None:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
