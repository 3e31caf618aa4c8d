"""Benchmark ``fgloc batch``: N simulated logs, sequential vs the local process pool vs Ray.

    python tools/bench_batch.py [--logs 14] [--jobs 2] [--repeat 2] [--route paper|line] [--cli]
                                [--engines sequential,local,ray,cli] [--workdir DIR]

Logs: by default the paper's run (the 78 m rectangle around the hall, 113 s, the length of a
real robot's run), one per seed 0..N-1 (the noise, compass offset and distortion differ);
``--route line --route-m M`` drives M metres along the hall's first side instead (short logs,
M <= 25). The logs are simulated in parallel before the timing starts.

Rows (each repeated ``--repeat`` times, in rotating order; medians and ranges printed):

* ``sequential``: every log one after the other in this process (``fgloc batch`` with the
  in-process engine: no process start, imports and numba caches paid once) - the baseline;
* ``fgloc run`` x N (with ``--cli``): one ``fgloc run`` process per log, a shell loop;
* ``local pool -j J``: ``--engine local`` (J spawned workers, their start included);
* ``ray -j J``: ``--engine ray`` on a private local Ray instance with J CPUs, as ``fgloc batch``
  runs it: the instance starts in the background while the driver prepares the jobs, and
  its start and stop are included; the next row is the same runs without the time the driver
  waited for the start and the stop.

Speed-up (wall): the sequential run's wall time over the engine's, paired within each repeat.
Speed-up (CPU time): the sequential run's CPU time over (the engine's job CPU time / workers +
the time the driver waited for Ray's start and stop): the speed-up with the cores to itself.
"CPU s, all processes" is the CPU time of the driver and every process under it (pool
workers; Ray's daemons and workers), sampled every 0.5 s: what the engine costs the machine
in all, load or not. "Cores busy" is the jobs' CPU time over the wall time.

Per-log overhead: wall x workers minus the time spent inside the jobs, divided by the
number of logs (what the engine adds around each log: dispatch, pickling, result transfer,
idle workers at the end; for Ray without its start and stop), and the round trip of an
empty job (200 of them) per engine. "Worker processes": how many processes ran the jobs (one
per CPU: each imports fgloc once). Every engine's trajectories are compared byte for byte
with the sequential run's. The load average (``uptime``'s first figure) is printed before and
after each measurement.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

START_POSE = [2.5, 3.0, 0.0]   # the paper route's first corner, heading east (both routes start there)


def simulate_one(seed: int, folder: str, route: str, route_m: float) -> str:
    """One simulated log (in a worker process): ``folder/runNN.mcap`` (+ the map beside it)."""
    from fgloc.sim import simulate_paper, write_sim

    root = Path(folder)
    dst = root / f"run{seed:02d}.mcap"
    if not dst.exists():
        kw = {} if route == "paper" else {"route": [START_POSE[:2], [START_POSE[0] + route_m, START_POSE[1]]]}
        sim = simulate_paper(seed=seed, **kw)
        d = write_sim(sim, root / "sim" / f"{seed:02d}")
        shutil.copy(d / "log.mcap", root / f".run{seed:02d}.tmp")
        os.replace(root / f".run{seed:02d}.tmp", dst)
        if seed == 0:
            shutil.copy(d / "map.yaml", root / "map.yaml")
            shutil.copy(d / "map.pgm", root / "map.pgm")
        shutil.rmtree(d, ignore_errors=True)
    return str(dst)


def make_logs(folder: Path, n: int, route: str, route_m: float, jobs: int) -> tuple[list[Path], Path]:
    """``n`` simulated runs (seeds 0..n-1), in ``jobs`` processes; logs of another route are not reused."""
    tag = folder / "route.txt"
    want = f"{route} {route_m if route == 'line' else ''}".strip()
    if tag.exists() and tag.read_text().strip() != want:
        shutil.rmtree(folder)
    folder.mkdir(parents=True, exist_ok=True)
    tag.write_text(want + "\n")
    with ProcessPoolExecutor(max(1, jobs)) as pool:
        logs = [Path(p) for p in pool.map(simulate_one, range(n), [str(folder)] * n, [route] * n, [route_m] * n)]
    return logs, folder / "map.yaml"


class CpuMeter:
    """CPU time (user + system) of this process and of every process under it, sampled every
    ``period_s`` (a process's last fraction of a period before it ends is not seen)."""

    def __init__(self, period_s: float = 0.5) -> None:
        import psutil

        self.psutil = psutil
        self.me = psutil.Process()
        self.period_s = period_s
        self.seen: dict[tuple[int, float], float] = {}
        self.base: dict[tuple[int, float], float] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True)

    def _sample(self) -> dict[tuple[int, float], float]:
        out = {}
        for p in self.me.children(recursive=True):
            try:
                with p.oneshot():
                    t = p.cpu_times()
                    out[(p.pid, p.create_time())] = t.user + t.system
            except (self.psutil.NoSuchProcess, self.psutil.AccessDenied, self.psutil.ZombieProcess):
                pass
        return out

    def _loop(self) -> None:
        while not self._stop.wait(self.period_s):
            self.seen.update(self._sample())

    def __enter__(self) -> CpuMeter:
        self.base = self._sample()
        self.t0 = time.process_time()
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()
        self.seen.update(self._sample())
        self.driver_s = time.process_time() - self.t0
        self.children_s = sum(v - self.base.get(k, 0.0) for k, v in self.seen.items())
        self.total_s = self.driver_s + self.children_s


def warm_up(work: Path, map_yaml: Path) -> float:
    """One short log through ``fgloc run``'s code in this process before the timing, so that numba's
    on-disk caches exist (a fresh checkout compiles them once) and no row pays for that."""
    from fgloc.batch import InlineEngine, run_batch
    from fgloc.batch.inputs import run_jobs

    t0 = time.perf_counter()
    log = Path(simulate_one(0, str(work / "warm-up"), "line", 4.0))
    rep = run_batch(run_jobs([log], work / "warm-up" / "out", map_yaml, START_POSE), work / "warm-up" / "out",
                    InlineEngine(), progress=False)
    assert rep.ok, [r.error for r in rep.rows]
    return time.perf_counter() - t0


def noop_job(job, blobs):
    """An empty job: what an engine costs around a log, without the log."""
    from fgloc.batch import JobResult

    return JobResult(job.name, True, row={}, wall_s=0.0)


def run_engine(name: str, engine, logs: list[Path], map_yaml: Path, out: Path) -> dict:
    """One batch as ``fgloc batch run`` does it: the engine starts (Ray: in the background), the jobs
    are made and the markers read meanwhile, the jobs run, the engine stops."""
    from fgloc.batch import run_batch
    from fgloc.batch.inputs import run_jobs

    shutil.rmtree(out, ignore_errors=True)
    load0 = os.getloadavg()[0]
    with CpuMeter() as cpu:
        t0 = time.perf_counter()
        if hasattr(engine, "start"):
            engine.start()
        elif name == "ray":  # an engine without a background start (older trees): start it first
            engine.connect()
            engine.timings = {"wait_s": time.perf_counter() - t0, "start_s": time.perf_counter() - t0}
        jobs = run_jobs(logs, out, map_yaml, START_POSE)
        rep = run_batch(jobs, out, engine, progress=False)
        if name == "ray" and not hasattr(engine, "start"):
            t_sd = time.perf_counter()
            engine.shutdown()
            engine.timings["stop_s"] = time.perf_counter() - t_sd
        wall = time.perf_counter() - t0
    assert rep.failed == 0 and rep.ran == len(jobs), [r.error for r in rep.rows if r.error]
    tm = getattr(engine, "timings", {})
    return {"wall": wall, "start": tm.get("start_s", 0.0), "wait": tm.get("wait_s", 0.0), "stop": tm.get("stop_s", 0.0),
            "inside": sum(r.wall_s for r in rep.results.values()),
            "cpu": sum(getattr(r, "cpu_s", 0.0) for r in rep.results.values()),
            "cpu_all": cpu.total_s, "workers": len({r.host for r in rep.results.values()}),
            "load": (load0, os.getloadavg()[0])}


def run_cli(logs: list[Path], map_yaml: Path, out: Path) -> dict:
    shutil.rmtree(out, ignore_errors=True)
    exe = Path(sys.executable).parent / "fgloc"
    load0 = os.getloadavg()[0]
    with CpuMeter() as cpu:
        t0 = time.perf_counter()
        for log in logs:
            subprocess.run([str(exe), "run", str(log.resolve()), "--map", str(map_yaml.resolve()), "--initial-pose",
                            *map(str, START_POSE), "-o", str(out / log.stem), "-q"], check=True, capture_output=True)
        wall = time.perf_counter() - t0
    return {"wall": wall, "start": 0.0, "wait": 0.0, "stop": 0.0, "inside": float("nan"), "cpu": float("nan"),
            "cpu_all": cpu.total_s, "workers": len(logs), "load": (load0, os.getloadavg()[0])}


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


def same_outputs(a: Path, b: Path, logs: list[Path]) -> bool:
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
    ap.add_argument("--logs", type=int, default=14)
    ap.add_argument("--jobs", "-j", type=int, default=2)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--route", choices=("paper", "line"), default="paper",
                    help="paper: the paper's 78 m rectangle (113 s); line: --route-m along the first side")
    ap.add_argument("--route-m", type=float, default=25.0, help="line route length (m, 0.8 m/s; at most 25)")
    ap.add_argument("--cli", action="store_true", help="add the one-process-per-log row (a few more minutes)")
    ap.add_argument("--no-cli", action="store_true", help="without that row (the default; kept for old command lines)")
    ap.add_argument("--no-ray", action="store_true")
    ap.add_argument("--engines", default="", help="rows to time, e.g. sequential,ray (default: all)")
    ap.add_argument("--workdir", type=Path, default=None, help="keep logs here (default: a temp folder)")
    args = ap.parse_args()
    if args.route == "line" and not 0 < args.route_m <= 25.0:
        ap.error("--route-m must be in (0, 25]: a longer straight route runs into the hall's east wall")

    from rich.console import Console
    from rich.table import Table

    from fgloc.batch import InlineEngine, LocalEngine, RayEngine

    t_bench = time.perf_counter()
    con = Console()
    if not con.is_terminal:
        con = Console(width=240)  # the table whole in a saved log
    work = args.workdir or Path(tempfile.mkdtemp(prefix="fgloc-bench-batch-"))
    t_sim = time.perf_counter()
    logs, map_yaml = make_logs(work / "logs", args.logs, args.route, args.route_m, args.jobs)
    t_sim = time.perf_counter() - t_sim
    from fgloc.io import open_log

    log_s = sum(open_log(p).summary()["duration"] for p in logs)
    t_warm = warm_up(work, map_yaml)
    con.print(f"{len(logs)} logs ({args.route} route), {log_s:.0f} s of log time in all, simulated in {t_sim:.0f} s, "
              f"warm-up {t_warm:.0f} s; {os.cpu_count()} CPUs; load average {os.getloadavg()[0]:.2f} at the start")
    with_cli = args.cli and not args.no_cli
    order = ["sequential", "local"] + ([] if args.no_ray else ["ray"]) + (["cli"] if with_cli else [])
    if args.engines:
        order = [e for e in args.engines.split(",") if e]
        if "sequential" not in order or set(order) - {"sequential", "local", "ray", "cli"}:
            ap.error("--engines: a comma-separated subset of sequential,local,ray,cli with sequential")
    results: dict[str, list[dict]] = {c: [] for c in order}
    same_reps = 0  # repeats in which every engine wrote the sequential run's trajectories
    for rep in range(args.repeat):
        for name in order[rep % len(order):] + order[: rep % len(order)]:
            out = work / "out" / name
            if name == "sequential":
                r = run_engine(name, InlineEngine(), logs, map_yaml, out)
            elif name == "local":
                r = run_engine(name, LocalEngine(args.jobs), logs, map_yaml, out)
            elif name == "ray":
                r = run_engine(name, RayEngine(args.jobs), logs, map_yaml, out)
            else:
                r = run_cli(logs, map_yaml, out)
            results[name].append(r)
            extra = f"; Ray start {r['start']:.1f} s (waited {r['wait']:.1f}), stop {r['stop']:.1f} s" \
                if name == "ray" else ""
            con.print(f"  repeat {rep + 1} {name:10s} {r['wall']:7.1f} s wall, {r['cpu_all']:7.1f} s CPU in all "
                      f"(load {r['load'][0]:.2f} -> {r['load'][1]:.2f}){extra}")
        same_reps += all(same_outputs(work / "out" / "sequential", work / "out" / name, logs)
                         for name in order if name != "sequential")
    noop = {name: [noop_roundtrip(name, args.jobs)] for name in order if name in ("local", "ray")}

    seq = results["sequential"]
    seq_cpu = statistics.median(r["cpu"] for r in seq)
    seq_all = statistics.median(r["cpu_all"] for r in seq)
    title = (f"fgloc batch: {len(logs)} logs x {log_s / len(logs):.0f} s ({args.route} route), -j {args.jobs}, "
             f"{args.repeat} repeat(s): median (min-max)")
    t = Table(title=title)
    cols = ("engine", "wall s", "speed-up (wall)", "speed-up (CPU time)", "CPU s, all processes",
            "CPU vs sequential", "Ray start s (driver waited)", "Ray stop s", "overhead per log s", "empty job ms",
            "job CPU s per log", "worker processes", "cores busy", "load")
    for c in cols:
        t.add_column(c, justify="left" if c == "engine" else "right")
    labels = {"sequential": "sequential (one process)", "local": f"local pool -j {args.jobs}",
              "ray": f"Ray -j {args.jobs}, private local instance, start and stop included",
              "cli": f"fgloc run x {len(logs)} (a process each)"}
    md = ["| " + " | ".join(cols) + " |", "|---" + "|--:" * (len(cols) - 1) + "|"]
    for name in order:
        rs = results[name]
        # paired with the sequential run of the same repeat (minutes apart, not an hour: the load drifts)
        speed = [s["wall"] / r["wall"] for s, r in zip(seq, rs, strict=True)]
        workers = 1 if name in ("sequential", "cli") else args.jobs
        fixed = [r["wait"] + r["stop"] for r in rs]
        over = [(r["wall"] - f) * workers / len(logs) - r["inside"] / len(logs) for r, f in zip(rs, fixed, strict=True)]
        has_cpu = name != "cli"
        cpu_speed = [seq_cpu / (r["cpu"] / workers + f) for r, f in zip(rs, fixed, strict=True)] if has_cpu else []
        ray_row = name == "ray"
        cells = [labels[name], fmt_range([r["wall"] for r in rs]), fmt_range(speed, 2),
                 fmt_range(cpu_speed, 2) if has_cpu else "-",
                 fmt_range([r["cpu_all"] for r in rs]), fmt_range([r["cpu_all"] / seq_all for r in rs], 2),
                 (f"{fmt_range([r['start'] for r in rs])} ({fmt_range([r['wait'] for r in rs])})"
                  if ray_row else "-"),
                 fmt_range([r["stop"] for r in rs]) if ray_row else "-",
                 fmt_range(over, 2) if has_cpu else "-",
                 fmt_range(noop[name], 2) if name in noop else "-",
                 fmt_range([r["cpu"] / len(logs) for r in rs], 2) if has_cpu else "-",
                 fmt_range([float(r["workers"]) for r in rs], 0),
                 fmt_range([r["cpu"] / r["wall"] for r in rs], 2) if has_cpu else "-",
                 fmt_range([0.5 * (r["load"][0] + r["load"][1]) for r in rs], 1)]
        t.add_row(*cells)
        md.append("| " + " | ".join(cells) + " |")
        if ray_row:
            w2 = [r["wall"] - f for r, f in zip(rs, fixed, strict=True)]
            cells = ["Ray, less the wait for its start and its stop", fmt_range(w2),
                     fmt_range([s["wall"] / w for s, w in zip(seq, w2, strict=True)], 2),
                     fmt_range([seq_cpu / (r["cpu"] / workers) for r in rs], 2)] + ["-"] * (len(cols) - 4)
            t.add_row(*cells)
            md.append("| " + " | ".join(cells) + " |")
    con.print(t)
    print("\n".join(md))
    con.print(f"trajectories identical to the sequential run for every engine in {same_reps} of {args.repeat} "
              f"repeat(s) (a repeat where they differ ran while the source tree changed); "
              f"load average {os.getloadavg()[0]:.2f} at the end; benchmark took "
              f"{(time.perf_counter() - t_bench) / 60:.1f} min")
    if args.workdir is None:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
