"""``fgloc bench speed``: the whole ``fgloc run`` command timed as a user runs it, beside its parts.

Logs (generated once into a work folder, then reused):

* ``office``: the shipped Willow Garage office scenario (a real map_server map, 0.5 m/s, 25 Hz
  scans, 50 Hz odometry, 20 Hz IMU) driven back and forth along its route, cut at ``office_s``
  (120 s); ``office-<N>min``: the same for ``long_minutes`` (memory over a long log);
* ``paper``: the paper run (:func:`fgloc.sim.simulate_paper`, seed 0, 113 s).

For each log, side by side and interleaved over ``repeats`` (the machine's load drifts):

* ``fgloc run LOG --map MAP -o DIR`` as a child process (the console script), with the defaults
  and with ``pipeline.frontend_every: 1`` (every scan matched): wall and CPU time, peak RSS
  (``wait4``: every thread's CPU, run.mcap's chunk writer thread included), the time line it
  prints (reading, writing, the view's channels: the I/O share, of the main thread's wall time;
  the chunks' compression and file writes overlap it on another core and are not in it),
  the position / heading RMSE of its ``trajectory.tum`` against the log's ground truth;
* the same command from another source tree (``before``: a folder holding an older ``fgloc``
  package, put first on ``PYTHONPATH``), for a before / after table on the same machine state;
* reading the log alone: opening it and decoding every input message ``fgloc run`` reads (a
  child process on either tree: the median of 5 passes after the first, which imports the
  decoders; one pass is a tenth of a second, at the mercy of the scheduler);
* the in-memory pipeline: ``Session(Localizer).run(messages)`` (``run_messages`` on an older
  tree) on the messages already decoded, no sinks, no initial pose (global localization, as
  ``fgloc run``), a child process on either tree, with the defaults and ``frontend_every: 1``
  (what ``tools/bench_pipeline.py`` times per back-end and front-end, from the true start);
* kiss-icp's own odometry (``kiss_icp.kiss_icp.KissICP.register_frame``, its defaults with
  the laser's range) on the same scans as 3-D points.

Start-up: ``python -c "import fgloc.cli"``, ``fgloc --help`` and ``fgloc run`` on the first
2 s of the office log (imports, map, numba from its on-disk cache, writing the outputs).  Every
child starts as an installed fgloc does: from Python's bytecode cache (kept in ``WORKDIR/pycache``,
filled by the warm-up run, as numba's cache is) even where the environment turns the cache off;
``--no-bytecode-cache`` times it as the environment says.  The
"start-up" column of an ``fgloc run`` row is its wall time outside the message loop: before
the first message (interpreter, imports, log summary, map, localizer, numba from its cache)
and after the outputs are written (exit).

Every figure is a median over the repeats with the range; "x real time" is the log's
duration over the wall time (and over the CPU time: on a loaded machine the wall time
says more about the other processes).  Nothing here asserts a speed.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

OFFICE_S = 120.0
TINY_S = 2.0
EVERY1_YAML = "pipeline:\n  frontend_every: 1\n"
TIME_LINE = re.compile(r"time: ([\d.]+) s = setup ([\d.]+) \+ reading ([\d.]+) \+ localizing ([\d.]+) \+ "
                       r"writing ([\d.]+) \+ view channels ([\d.]+)")


@dataclass
class BenchLog:
    """A generated log: ``log.mcap``, ``map.yaml``, ``ground_truth.tum`` in ``folder``."""

    name: str
    folder: Path
    duration_s: float
    scans: int

    @property
    def log(self) -> Path:
        return self.folder / "log.mcap"

    @property
    def map_yaml(self) -> Path:
        return self.folder / "map.yaml"

    @property
    def ground_truth(self) -> Path:
        return self.folder / "ground_truth.tum"


@dataclass
class Proc:
    """One child process: wall and CPU seconds, peak RSS (MB), exit code, output."""

    wall_s: float
    cpu_s: float
    rss_mb: float
    returncode: int
    out: str
    err: str


@dataclass
class Sample:
    """One measurement of one row."""

    wall_s: float
    cpu_s: float | None = None
    rss_mb: float | None = None
    startup_s: float | None = None
    io_s: float | None = None      # reading + writing run.mcap (inputs, /fused_pose, the view's channels)
    view_s: float | None = None    # of which the view's channels
    pos_mm: float | None = None
    yaw_deg: float | None = None
    note: str = ""


@dataclass
class Row:
    log: str
    what: str
    duration_s: float
    scans: int
    samples: list[Sample] = field(default_factory=list)


# ---------------------------------------------------------------------- logs
def _cut(sim: Any, duration_s: float) -> Any:
    """The first ``duration_s`` of a simulated run (the /tf_static message kept)."""
    from fgloc.types import Trajectory

    t0 = float(sim.ground_truth.stamps[0])
    end = t0 + duration_s
    msgs = [(t, m) for i, (t, m) in enumerate(sim.messages)
            if i == 0 or not math.isfinite(float(getattr(m, "stamp", 0.0))) or float(m.stamp) <= end]
    keep = sim.ground_truth.stamps <= end
    gt = Trajectory(sim.ground_truth.stamps[keep], sim.ground_truth.poses[keep])
    return dataclasses.replace(sim, messages=msgs, ground_truth=gt)


def office_scenario(duration_s: float, speed_mps: float = 0.5) -> dict[str, Any]:
    """The shipped ``willow`` scenario with its route driven back and forth long enough for
    ``duration_s`` (the stop-turn-go at each waypoint included; the log is cut afterwards)."""
    from importlib.resources import as_file

    from fgloc.config import scenario_path
    from fgloc.sim.simulate import load_scenario

    with as_file(scenario_path("willow")) as path:
        sc = load_scenario(path)
    route = [list(map(float, p)) for p in sc["route"]]
    length = float(np.sum(np.hypot(*np.diff(np.asarray(route), axis=0).T)))
    one_way_s = length / speed_mps + 2.0 * len(route)  # + ~2 s per stop and turn
    passes = max(1, math.ceil(duration_s / one_way_s) + 1)
    full = list(route)
    for k in range(1, passes):
        leg = route[::-1] if k % 2 else route
        full += leg[1:]
    sc["route"] = full
    sc["speed_mps"] = speed_mps
    return sc


def _write(sim: Any, folder: Path, name: str) -> BenchLog:
    from fgloc.sim import write_sim

    write_sim(sim, folder)
    scans = sum(1 for t, _ in sim.messages if t == "/scan")
    (folder / "bench.txt").write_text(f"{name} {sim.ground_truth.duration!r} {scans}\n")
    return BenchLog(name, folder, float(sim.ground_truth.duration), scans)


def _cached(folder: Path, name: str) -> BenchLog | None:
    info = folder / "bench.txt"
    if not (info.exists() and (folder / "log.mcap").exists() and (folder / "map.yaml").exists()):
        return None
    try:
        n, dur, scans = info.read_text().split()
    except ValueError:
        return None
    return BenchLog(name, folder, float(dur), int(scans)) if n == name else None


def make_logs(workdir: Path, office_s: float = OFFICE_S, paper: bool = True, long_minutes: float | None = None,
              say: Callable[[str], None] = lambda s: None) -> dict[str, BenchLog]:
    """The benchmark's logs in ``workdir`` (generated when missing): ``office``, ``tiny`` (its
    first 2 s, for the start-up time), ``paper`` and ``office-<N>min`` if asked."""
    from fgloc.sim import run_scenario, simulate_paper

    out: dict[str, BenchLog] = {}
    wanted = [("office", office_s), ("tiny", TINY_S)]
    if long_minutes:
        wanted.append((f"office-{long_minutes:g}min", 60.0 * long_minutes))
    office_sim = None
    for name, dur in wanted:
        folder = workdir / f"{name}-{dur:g}s"
        got = _cached(folder, name)
        if got is None:
            if name == "tiny" and office_sim is not None:
                sim = office_sim
            else:
                say(f"simulating the {name} log ({dur:g} s)")
                sim = run_scenario(office_scenario(max(dur, office_s)), seed=0)
                if name == "office":
                    office_sim = sim
            got = _write(_cut(sim, dur), folder, name)
        out[name] = got
    if paper:
        folder = workdir / "paper-seed0"
        got = _cached(folder, "paper")
        if got is None:
            say("simulating the paper run (seed 0)")
            got = _write(simulate_paper(seed=0), folder, "paper")
        out["paper"] = got
    return out


# ---------------------------------------------------------------------- processes
def _hwm_mb(pid: int) -> float | None:
    """The process's peak resident set (``VmHWM``, Linux), MB."""
    try:
        with open(f"/proc/{pid}/status", "rb") as f:
            for line in f:
                if line.startswith(b"VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except (OSError, ValueError, IndexError):
        return None
    return None


def run_process(argv: Sequence[str], env: dict[str, str] | None = None, poll_s: float = 0.02) -> Proc:
    """Run ``argv`` to its end: wall, CPU (user + system, from ``wait4``) and peak RSS.

    The peak RSS is the child's ``VmHWM`` read every ``poll_s`` (Linux): ``wait4``'s
    ``ru_maxrss`` would include this process's own size at the fork (Linux carries it over
    the exec), which is large here (decoded logs).  Elsewhere: ``ru_maxrss``."""
    with tempfile.TemporaryFile() as fo, tempfile.TemporaryFile() as fe:
        t0 = time.perf_counter()
        p = subprocess.Popen(list(argv), stdout=fo, stderr=fe, env=env)
        peak: float | None = None
        while True:
            pid, status, ru = os.wait4(p.pid, os.WNOHANG)
            if pid:
                break
            hwm = _hwm_mb(p.pid)
            if hwm is not None:
                peak = hwm if peak is None else max(peak, hwm)
            time.sleep(poll_s)
        wall = time.perf_counter() - t0
        p.returncode = os.waitstatus_to_exitcode(status)
        fo.seek(0)
        fe.seek(0)
        rss = peak if peak is not None else ru.ru_maxrss / 1024.0
        return Proc(wall, ru.ru_utime + ru.ru_stime, rss, p.returncode,
                    fo.read().decode(errors="replace"), fe.read().decode(errors="replace"))


def fgloc_argv() -> list[str]:
    """The ``fgloc`` console script beside this Python, else ``python -m fgloc.cli``."""
    script = Path(sys.executable).with_name("fgloc")
    return [str(script)] if script.exists() else [sys.executable, "-m", "fgloc.cli"]


#: where the child processes keep Python's bytecode cache (``PYTHONPYCACHEPREFIX``), set by
#: :func:`bench_speed`; None: as this process's environment says
PYCACHE_PREFIX: Path | None = None


def tree_env(tree: Path | None) -> dict[str, str]:
    """The environment with ``tree`` (a folder holding an ``fgloc`` package) first on the path.

    With :data:`PYCACHE_PREFIX`, Python's bytecode cache is written there (the source trees stay
    untouched) and read back, as an installed package has it, even where the environment turns
    it off (``PYTHONDONTWRITEBYTECODE``: every start would compile fgloc's ~90 modules again)."""
    env = dict(os.environ)
    if PYCACHE_PREFIX is not None:
        env.pop("PYTHONDONTWRITEBYTECODE", None)
        env["PYTHONPYCACHEPREFIX"] = str(PYCACHE_PREFIX)
    if tree is not None:
        env["PYTHONPATH"] = str(tree) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    return env


def _accuracy(traj_path: Path, gt_path: Path) -> tuple[float | None, float | None]:
    from fgloc.errors import LogError
    from fgloc.eval.metrics import evaluate
    from fgloc.io.tum import read_tum

    try:
        m = evaluate(read_tum(traj_path), read_tum(gt_path))
    except (LogError, OSError, ValueError):
        return None, None
    return 1000.0 * m.position_rmse_m, m.heading_rmse_deg


_OPTIONAL_FLAGS: dict[Path | None, list[str]] = {}


def _run_flags(tree: Path | None) -> list[str]:
    """``--allow-lost`` and ``--force`` where ``tree``'s ``fgloc run`` has them (an older tree may not)."""
    got = _OPTIONAL_FLAGS.get(tree)
    if got is None:
        env = tree_env(tree)
        env["COLUMNS"] = "300"
        helptext = run_process(fgloc_argv() + ["run", "--help"], env).out
        got = _OPTIONAL_FLAGS[tree] = [f for f in ("--allow-lost", "--force") if f in helptext]
    return got


def time_fgloc_run(blog: BenchLog, outdir: Path, config: Path | None = None, tree: Path | None = None) -> Sample:
    """One ``fgloc run`` of ``blog`` as a child process (``tree``'s fgloc first on the path)."""
    argv = fgloc_argv() + ["run", str(blog.log), "--map", str(blog.map_yaml), "-o", str(outdir), "-q",
                           *_run_flags(tree)]
    if config is not None:
        argv += ["--config", str(config)]
    p = run_process(argv, tree_env(tree))
    s = Sample(p.wall_s, p.cpu_s, p.rss_mb)
    if p.returncode != 0:
        s.note = f"exit {p.returncode}: {p.err.strip().splitlines()[-1] if p.err.strip() else ''}"
        return s
    m = TIME_LINE.search(p.out)
    if m is not None:
        total, setup, read, _loc, write, view = (float(v) for v in m.groups())
        # before the first message (interpreter, imports, log summary, map, localizer with numba
        # from its cache) and after the outputs (exit)
        s.startup_s = p.wall_s - total + setup
        s.io_s = read + write + view
        s.view_s = view
    s.pos_mm, s.yaw_deg = _accuracy(outdir / "trajectory.tum", blog.ground_truth)
    return s


def time_startup(blogs: dict[str, BenchLog], workdir: Path, tree: Path | None = None) -> dict[str, Sample]:
    """``import fgloc.cli``, ``fgloc --help`` and ``fgloc run`` on the 2 s log, as child processes."""
    env = tree_env(tree)
    out = {}
    p = run_process([sys.executable, "-c", "import fgloc.cli"], env)
    out["python -c 'import fgloc.cli'"] = Sample(p.wall_s, p.cpu_s, p.rss_mb, startup_s=p.wall_s)
    p = run_process(fgloc_argv() + ["--help"], env)
    out["fgloc --help"] = Sample(p.wall_s, p.cpu_s, p.rss_mb, startup_s=p.wall_s)
    tiny = blogs["tiny"]
    s = time_fgloc_run(tiny, workdir / "runs" / ("tiny" if tree is None else f"tiny-{tree.name}"), tree=tree)
    s.startup_s = s.wall_s
    out[f"fgloc run, {tiny.duration_s:.0f} s log"] = s
    return out


# ---------------------------------------------------------------------- in-process rows
def _decoded(blog: BenchLog) -> tuple[Any, list[tuple[str, object]]]:
    from fgloc.io import open_log

    src = open_log(blog.log)
    mount = src.laser_mount()
    want = [t for t in ("/scan", "/odom", "/imu", "/tf_static") if src.has(t)]
    return mount, list(src.messages(want))


# The reading and in-memory rows run as a child process so that another source tree (``before``)
# can be timed the same way: this code runs against whichever ``fgloc`` comes first on the path,
# the session-2 API (fgloc.io.open_log, fgloc.localization) or the older one (fgloc.io.log.LogReader,
# fgloc.pipeline).  It prints one JSON line.
CHILD_CODE = r"""
import json, sys, time
mode, log, map_yaml, gt, every = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4], int(sys.argv[5])
READS = 5
try:
    from fgloc.io import open_log
    new = True
except ImportError:
    from fgloc.io.log import LogReader
    new = False
def read():
    src = open_log(log) if new else LogReader(log)
    mount = src.laser_mount()
    want = [t for t in ("/scan", "/odom", "/imu", "/tf_static") if src.has(t)]
    return mount, list(src.messages(want) if new else src.messages(set(want)))
mount, msgs = read()  # the first pass imports the decoders (start-up, timed elsewhere) and warms the file cache
out = {"n": len(msgs)}
if mode == "read":
    walls, cpus = [], []
    for _ in range(READS):
        del msgs
        c0, t0 = time.process_time(), time.perf_counter()
        mount, msgs = read()
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    out.update(wall_s=sorted(walls)[READS // 2], cpu_s=sorted(cpus)[READS // 2])
else:
    from fgloc.eval.metrics import evaluate
    from fgloc.io.tum import read_tum
    from fgloc.maps import OccupancyMap
    occ = OccupancyMap.load(map_yaml)
    if new:
        from fgloc.config import load_config
        from fgloc.localization import Localizer, Session
        cfg = load_config(None, {"pipeline": {"frontend_every": every}})
        loc = Localizer(occ, mount, backend="smoother", frontend="native", config=cfg)
        run = lambda: Session(loc).run(msgs)
    else:
        from fgloc.pipeline import Localizer, load_config, run_messages
        cfg = load_config()
        cfg.setdefault("pipeline", {})["frontend_every"] = every
        loc = Localizer(occ, mount, backend="smoother", frontend="native", config=cfg)
        run = lambda: run_messages(loc, msgs)
    c0, t0 = time.process_time(), time.perf_counter()
    final = run()
    out.update(wall_s=time.perf_counter() - t0, cpu_s=time.process_time() - c0)
    m = evaluate(final, read_tum(gt))
    out.update(pos_mm=1000.0 * m.position_rmse_m, yaw_deg=m.heading_rmse_deg)
print("BENCH " + json.dumps(out))
"""


def time_child(mode: str, blog: BenchLog, every: int = 2, tree: Path | None = None) -> Sample:
    """``mode`` "read" (decoding every input message) or "pipeline" (``Session(Localizer).run`` on
    the decoded messages, no sinks, no initial pose: global localization as ``fgloc run``) in a
    child process on ``tree``'s fgloc (None: this one); the child's own timer, peak RSS of it all."""
    # -P: the current folder not first on the path (the tree is)
    p = run_process([sys.executable, "-P", "-c", CHILD_CODE, mode, str(blog.log), str(blog.map_yaml),
                     str(blog.ground_truth), str(every)], tree_env(tree))
    line = next((ln for ln in p.out.splitlines() if ln.startswith("BENCH ")), None)
    if p.returncode != 0 or line is None:
        err = p.err.strip().splitlines()
        return Sample(p.wall_s, p.cpu_s, p.rss_mb, note=f"exit {p.returncode}: {err[-1] if err else ''}")
    got = json.loads(line[6:])
    s = Sample(float(got["wall_s"]), float(got["cpu_s"]), p.rss_mb, pos_mm=got.get("pos_mm"),
               yaw_deg=got.get("yaw_deg"))
    s.note = f"{got['n']} msgs"
    return s


def time_kiss_odometry(decoded: tuple[Any, list[tuple[str, object]]]) -> Sample:
    """kiss-icp's own odometry (``KissICP.register_frame``) on the scans as 3-D points; its
    defaults with the laser's range (voxel = max range / 100, as its ``load_config``)."""
    from kiss_icp.config import KISSConfig
    from kiss_icp.kiss_icp import KissICP

    from fgloc.types import LaserScan

    _, msgs = decoded
    scans = [m for _, m in msgs if isinstance(m, LaserScan)]
    clouds = []
    for sc in scans:
        r = np.asarray(sc.ranges, dtype=np.float64)
        a = sc.angle_min + sc.angle_increment * np.arange(len(r))
        ok = sc.valid_mask()
        clouds.append(np.column_stack([r[ok] * np.cos(a[ok]), r[ok] * np.sin(a[ok]), np.zeros(int(ok.sum()))]))
    cfg = KISSConfig()
    cfg.data.max_range = float(scans[0].range_max) if scans else 50.0
    cfg.data.min_range = float(scans[0].range_min) if scans else 0.0
    cfg.data.deskew = False
    cfg.mapping.voxel_size = cfg.data.max_range / 100.0
    odo = KissICP(cfg)
    c0, t0 = time.process_time(), time.perf_counter()
    for pts in clouds:
        odo.register_frame(pts, np.zeros(len(pts)))
    return Sample(time.perf_counter() - t0, time.process_time() - c0)


# ---------------------------------------------------------------------- the benchmark
@dataclass
class SpeedReport:
    rows: list[Row]
    startup: dict[str, list[Sample]]
    startup_before: dict[str, list[Sample]]
    load: list[tuple[float, float, float]]
    repeats: int
    before: Path | None
    wall_s: float
    after: Path | None = None
    bytecode_cache: bool = True  # the children started from Python's bytecode cache (else compiled fgloc each time)


def bench_speed(workdir: Path, repeats: int = 3, logs: Sequence[str] = ("office", "paper"), every1: bool = True,
                before: Path | None = None, kiss: bool = True, long_minutes: float | None = None,
                office_s: float = OFFICE_S, say: Callable[[str], None] = lambda s: None,
                after: Path | None = None, bytecode_cache: bool = True) -> SpeedReport:
    """Measure everything in the module docstring; ``say(line)`` reports progress.

    ``after``: a source tree to time as "after" instead of the fgloc this process imports (a
    snapshot of a commit, while the working tree changes under the benchmark).
    ``bytecode_cache``: the children read and write Python's bytecode cache in ``WORKDIR/pycache``
    (filled by the warm-up run, as numba's cache is); False: as the environment says."""
    global PYCACHE_PREFIX
    t_start = time.perf_counter()
    workdir = Path(workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    PYCACHE_PREFIX = (workdir / "pycache").resolve() if bytecode_cache else None
    blogs = make_logs(workdir, office_s=office_s, paper="paper" in logs, long_minutes=long_minutes, say=say)
    every1_yaml = workdir / "every1.yaml"
    every1_yaml.write_text(EVERY1_YAML)
    runs = workdir / "runs"
    load = [os.getloadavg()]
    names = [n for n in logs if n in blogs]
    if long_minutes:
        names.append(f"office-{long_minutes:g}min")
    rows: dict[tuple[str, str], Row] = {}

    def row(name: str, what: str) -> Row:
        b = blogs[name]
        return rows.setdefault((name, what), Row(name, what, b.duration_s, b.scans))

    # warm-up: numba compiles into its on-disk cache once per tree (not charged to any row)
    say("warm-up (numba's on-disk cache)")
    warm = blogs[names[0]] if names else blogs["tiny"]
    time_fgloc_run(warm, runs / "warm", tree=after)
    if before is not None:
        time_fgloc_run(warm, runs / "warm-before", tree=before)
    decoded = {n: _decoded(blogs[n]) for n in names if not n.startswith("office-")} if kiss else {}
    startup: dict[str, list[Sample]] = {}
    startup_before: dict[str, list[Sample]] = {}
    for rep in range(repeats):
        for what, samples in time_startup(blogs, workdir, after).items():
            startup.setdefault(what, []).append(samples)
        if before is not None:
            for what, samples in time_startup(blogs, workdir, before).items():
                startup_before.setdefault(what, []).append(samples)
        for name in names:
            blog = blogs[name]
            long = name.startswith("office-") and name != "office"
            cases: list[tuple[str, Callable[[], Sample]]] = [
                ("fgloc run", partial(time_fgloc_run, blog, runs / f"{name}-default", tree=after)),
            ]
            if before is not None:
                cases.append(("fgloc run (before)",
                              partial(time_fgloc_run, blog, runs / f"{name}-default-before", tree=before)))
            if every1 and not long:
                cases.append(("fgloc run, frontend_every 1",
                              partial(time_fgloc_run, blog, runs / f"{name}-every1", every1_yaml, tree=after)))
                if before is not None:
                    cases.append(("fgloc run, frontend_every 1 (before)",
                                  partial(time_fgloc_run, blog, runs / f"{name}-every1-before", every1_yaml,
                                          tree=before)))
            if not long:
                cases.append(("reading the log alone", partial(time_child, "read", blog, tree=after)))
                if before is not None:
                    cases.append(("reading the log alone (before)", partial(time_child, "read", blog, tree=before)))
                for every, label in ((2, ""), (1, ", frontend_every 1")):
                    if every == 1 and not every1:
                        continue
                    cases.append((f"in-memory pipeline{label}",
                                  partial(time_child, "pipeline", blog, every, tree=after)))
                    if before is not None:
                        cases.append((f"in-memory pipeline{label} (before)",
                                      partial(time_child, "pipeline", blog, every, tree=before)))
                if kiss and _have_kiss():
                    cases.append(("kiss-icp odometry (its own pipeline)", partial(time_kiss_odometry, decoded[name])))
            k = rep % len(cases)  # rotate the order between repeats
            for what, fn in cases[k:] + cases[:k]:
                say(f"repeat {rep + 1}/{repeats}: {name}: {what}")
                row(name, what).samples.append(fn())
        load.append(os.getloadavg())
    order = {w: i for i, w in enumerate((
        "fgloc run", "fgloc run (before)", "fgloc run, frontend_every 1", "fgloc run, frontend_every 1 (before)",
        "in-memory pipeline", "in-memory pipeline (before)", "in-memory pipeline, frontend_every 1",
        "in-memory pipeline, frontend_every 1 (before)", "reading the log alone", "reading the log alone (before)",
        "kiss-icp odometry (its own pipeline)"))}
    ordered = sorted(rows.values(), key=lambda r: (names.index(r.log), order.get(r.what, 99)))
    return SpeedReport(ordered, startup, startup_before, load, repeats, before, time.perf_counter() - t_start, after,
                       bytecode_cache=PYCACHE_PREFIX is not None or not os.environ.get("PYTHONDONTWRITEBYTECODE"))


def _have_kiss() -> bool:
    try:
        import kiss_icp.kiss_icp  # noqa: F401
    except ImportError:
        return False
    return True


# ---------------------------------------------------------------------- the table
def _stat(values: list[float], fmt: str) -> str:
    vals = [v for v in values if v is not None and math.isfinite(v)]
    if not vals:
        return "-"
    med = statistics.median(vals)
    if len(vals) == 1 or min(vals) == max(vals):
        return format(med, fmt)
    return f"{format(med, fmt)} [{format(min(vals), fmt)}-{format(max(vals), fmt)}]"


def no_worse(after: list[float], before: list[float], higher_is_better: bool = True) -> tuple[float, str]:
    """The ratio of the medians (after / before; for a time, ``higher_is_better`` False, the time's
    ratio) and the verdict: "yes" when after's median is at least as good, "within the ranges" when
    it is not but the two ranges overlap (the load's drift is as large), else "no"."""
    a, b = statistics.median(after), statistics.median(before)
    ratio = a / b
    if (ratio >= 1.0) if higher_is_better else (ratio <= 1.0):
        return ratio, "yes"
    overlap = max(after) >= min(before) if higher_is_better else min(after) <= max(before)
    return ratio, "within the ranges" if overlap else "no"


def comparison_lines(rep: SpeedReport) -> list[str]:
    """After against before, row by row (each row timed on both trees, interleaved): CPU x real time
    medians [min-max], their ratio (> 1: after is faster) and whether after is no worse; start-up
    in CPU seconds (the ratio is after's time over before's)."""
    lines = ["| log | what | after (CPU x real time) | before | after / before | no worse? |",
             "|---|---|--:|--:|--:|--|"]
    by_key = {(r.log, r.what): r for r in rep.rows}
    for r in rep.rows:
        twin = by_key.get((r.log, f"{r.what} (before)"))
        if twin is None:
            continue
        a = [r.duration_s / s.cpu_s for s in r.samples if s.cpu_s and not s.note.startswith("exit")]
        b = [twin.duration_s / s.cpu_s for s in twin.samples if s.cpu_s and not s.note.startswith("exit")]
        if not a or not b:
            continue
        ratio, verdict = no_worse(a, b)
        lines.append(f"| {r.log} ({r.duration_s:.0f} s) | {r.what} | {_stat(a, '.1f')} | {_stat(b, '.1f')} | "
                     f"{ratio:.2f} | {verdict} |")
    for what, ss in rep.startup.items():
        a = [s.cpu_s for s in ss if s.cpu_s is not None]
        b = [s.cpu_s for s in rep.startup_before.get(what, []) if s.cpu_s is not None]
        if not a or not b:
            continue
        ratio, verdict = no_worse(a, b, higher_is_better=False)
        lines.append(f"| start-up | {what} (s of CPU) | {_stat(a, '.2f')} | {_stat(b, '.2f')} | "
                     f"{ratio:.2f}x the time | {verdict} |")
    return lines


def report_lines(rep: SpeedReport) -> list[str]:
    """The report as Markdown lines (pasteable into the README)."""
    lines = ["| log | what | x real time (wall) | x real time (CPU) | ms per scan (wall) | ms per scan (CPU) "
             "| start-up (s) | peak RSS (MB) | I/O share (view channels) | position RMSE (mm) | heading RMSE (deg) |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rep.rows:
        ss = r.samples
        bad = [s.note for s in ss if s.note.startswith("exit")]
        if bad:
            lines.append(f"| {r.log} | {r.what} | {bad[0]} | | | | | | | | |")
            continue
        rt_wall = [r.duration_s / s.wall_s for s in ss]
        rt_cpu = [r.duration_s / s.cpu_s for s in ss if s.cpu_s]
        ms = [1000.0 * s.wall_s / max(r.scans, 1) for s in ss]
        ms_cpu = [1000.0 * s.cpu_s / max(r.scans, 1) for s in ss if s.cpu_s]
        io = [100.0 * s.io_s / s.wall_s for s in ss if s.io_s is not None]
        vw = [100.0 * s.view_s / s.wall_s for s in ss if s.view_s is not None]
        lines.append(
            f"| {r.log} ({r.duration_s:.0f} s) | {r.what} | {_stat(rt_wall, '.1f')} | {_stat(rt_cpu, '.1f')} | "
            f"{_stat(ms, '.2f')} | {_stat(ms_cpu, '.2f')} | "
            f"{_stat([s.startup_s for s in ss if s.startup_s is not None], '.2f')} | "
            f"{_stat([s.rss_mb for s in ss if s.rss_mb is not None], '.0f')} | "
            f"{_stat(io, '.1f') + ' % (' + _stat(vw, '.1f') + ' %)' if io else '-'} | "
            f"{_stat([s.pos_mm for s in ss if s.pos_mm is not None], '.3f')} | "
            f"{_stat([s.yaw_deg for s in ss if s.yaw_deg is not None], '.4f')} |")
    lines.append("")
    lines.append("| start-up | wall (s) | CPU (s) | peak RSS (MB) |")
    lines.append("|---|---|---|---|")
    for label, table in (("", rep.startup), (" (before)", rep.startup_before)):
        for what, ss in table.items():
            lines.append(f"| {what}{label} | {_stat([s.wall_s for s in ss], '.2f')} | "
                         f"{_stat([s.cpu_s for s in ss if s.cpu_s is not None], '.2f')} | "
                         f"{_stat([s.rss_mb for s in ss if s.rss_mb is not None], '.0f')} |")
    if rep.before is not None:
        lines.append("")
        lines += comparison_lines(rep)
    loads = ", ".join(f"{a:.1f}" for a, _, _ in rep.load)
    lines.append("")
    lines.append(f"{rep.repeats} repeat(s), medians [min-max]; load average (1 min) before / after each repeat: "
                 f"{loads}; {os.cpu_count()} CPUs; bench {rep.wall_s:.0f} s"
                 + (f"; before = {rep.before}" if rep.before else "") + (f"; after = {rep.after}" if rep.after else "")
                 + ("; Python's bytecode cache on" if rep.bytecode_cache else
                    "; no bytecode cache (PYTHONDONTWRITEBYTECODE: every start compiles fgloc's modules)"))
    return lines
