"""fgloc over DDS, measured: scan arrival -> map->odom published latency, and the live node's memory.

Two processes on this machine over Cyclone DDS on the loopback interface: ``fgloc replay LOG --ros2``
publishes a log, ``fgloc live --ros2`` localizes it; this script samples the live process's resident
memory (psutil) while the replay runs and prints

* the latency from a scan's arrival (taken from DDS) to its map -> odom transform published, p50 / p99
  (``fgloc live``'s own measurement, over every scan fused live; the scans kept from before the start
  are not counted), and the scans fused / skipped as a backlog;
* the resident memory, sampled every ``--sample-s`` wall seconds: after the first ``--settle`` minutes
  of log, then every quarter of the run, its growth from there to the end and the slope of a line fitted
  after settling (MB per minute of log), which is ~0 when memory is flat; ``--png`` plots it;
* over the last ``--last`` minutes of log, the RSS's fitted slope and its 95 % interval: memory is called
  flat when 0 is within it;
* the load average (1 min) at the start and at the end: the machine's share of the latency.

    python tools/bench_ros2.py                         # the paper run (110 s), rate 1
    python tools/bench_ros2.py --loops 6 --rate 2 --png rss.png   # 11 minutes of log, twice real time: memory
    python tools/bench_ros2.py --log BAG --map MAP.yaml --no-initial-pose   # any log (its map on /map)
    python tools/bench_ros2.py --log BAG --map MAP.yaml --no-initial-pose --compare RUN_DIR

``--receive-only``: the second process is not ``fgloc live`` but fgloc's DDS receive path alone
(:class:`fgloc.ros2.transport.CycloneTransport` and :func:`fgloc.ros2.codec.decode` on the sensor
topics, no localizer): its memory is the DDS layer's own.

``--compare RUN_DIR`` (a ``fgloc run`` of the same log, with the same map and start): /amcl_pose is also
read here and compared with RUN_DIR/online.tum at the same stamps (max, median, p99 of the distance).

``--probe``: where the memory is, sampled inside the live process (:class:`MemProbe`) beside its RSS: glibc
malloc's bytes in use and free inside its arenas (``mallinfo2``), its arenas (``malloc_info``), Python's
small-object blocks, with ``--tracemalloc`` the bytes Python's allocators (numpy's buffers included) hold;
each one's growth after settling, so a rise is found in the allocator, in Python, or in neither (outside
malloc).  ``--trim-s S`` calls ``malloc_trim(0)`` every S seconds there (a diagnostic: does the RSS come back?);
``MALLOC_ARENA_MAX=2`` in the environment limits glibc's arenas in both processes.
``--no-dds``: the replay and ``fgloc live --ros2``'s node in this one process, the replay's samples handed to
the node's subscriptions directly (:class:`LoopTransport`, no DDS): the node's memory without Cyclone DDS.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import psutil


def mappings() -> dict[str, list]:
    """The process's memory mappings now (``/proc/self/smaps``): start address (hex) -> [size kB, Rss kB,
    Anonymous kB, permissions, name ("" for an anonymous mapping)]."""
    out: dict[str, list] = {}
    cur: list | None = None
    with open("/proc/self/smaps") as f:
        for line in f:
            head = line.split(None, 5)
            if "-" in head[0] and len(head) >= 5 and not head[0].endswith(":"):
                start, end = (int(x, 16) for x in head[0].split("-"))
                cur = [(end - start) // 1024, 0, 0, head[1], head[5].strip() if len(head) > 5 else ""]
                out[head[0].split("-")[0]] = cur
            elif cur is not None and head[0] == "Rss:":
                cur[1] = int(head[1])
            elif cur is not None and head[0] == "Anonymous:":
                cur[2] = int(head[1])
    return out


class MemProbe:
    """Memory as a process sees it, sampled every ``every_s`` by a thread of its own into ``path`` (one
    JSON line each): RSS (/proc), glibc malloc (``mallinfo2``: bytes in use, free inside the arenas, in
    mmapped chunks; ``malloc_info``: the arenas), Python's small-object blocks, tracked objects, and with
    ``trace`` the bytes tracemalloc sees (Python's allocators and numpy's buffers).  ``trim_s`` > 0:
    ``malloc_trim(0)`` after each sample at least that far apart (a diagnostic)."""

    def __init__(self, path: str, every_s: float = 10.0, trace: bool = False, trim_s: float = 0.0) -> None:
        self.path, self.every_s, self.trace, self.trim_s = path, every_s, trace, trim_s
        self.trimmed = 0
        # the cyclic collector's passes: count, total and longest pause per generation; pauses over 2 ms
        self.gc_n, self.gc_ms, self.gc_max = [0, 0, 0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
        self.gc_long: list[tuple[float, int, float, int]] = []  # (time.time(), generation, ms, collected)
        self._gc_t0 = 0.0

        def on_gc(phase: str, info: dict) -> None:
            if phase == "start":
                self._gc_t0 = time.perf_counter()
                return
            ms = (time.perf_counter() - self._gc_t0) * 1e3
            g = int(info["generation"])
            self.gc_n[g] += 1
            self.gc_ms[g] += ms
            self.gc_max[g] = max(self.gc_max[g], ms)
            if ms > 2.0 and len(self.gc_long) < 5000:
                self.gc_long.append((time.time(), g, round(ms, 2), int(info.get("collected", 0))))

        import gc

        gc.callbacks.append(on_gc)
        self.maps_s = float(os.environ.get("FGLOC_PROBE_MAPS_S", "0"))
        self._next_maps = 0.0
        self.trace_after_s = float(os.environ.get("FGLOC_PROBE_TRACE_AFTER_S", "0"))
        self.snap_every_s = float(os.environ.get("FGLOC_PROBE_SNAP_S", "0"))
        self._snap0: Any = None
        if trace and self.trace_after_s <= 0:
            import tracemalloc

            tracemalloc.start(1)

    def sample(self, t0: float) -> dict:
        import gc
        import threading

        from fgloc import memory

        mi = memory.mallinfo()
        with open("/proc/self/statm") as f:
            rss = int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
        row = {"t": time.monotonic() - t0, "wall": time.time(), "rss": rss,
               "malloc_used": mi.in_use_b if mi else 0, "malloc_free": mi.free_b if mi else 0,
               "malloc_mmap": mi.mmapped_b if mi else 0, "malloc_arena": mi.arena_b if mi else 0,
               "arenas": memory.arenas() or 0,
               "py_blocks": sys.getallocatedblocks(), "objects": len(gc.get_objects()),
               "threads": threading.active_count(), "trimmed": self.trimmed, "gc_n": list(self.gc_n),
               "gc_ms": [round(v, 2) for v in self.gc_ms], "gc_max_ms": [round(v, 2) for v in self.gc_max],
               "gc_long": self.gc_long[-200:], "gc_threshold": gc.get_threshold(), "frozen": gc.get_freeze_count()}
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith(("RssAnon:", "RssFile:", "RssShmem:")):
                    row[line.split(":")[0].lower()] = int(line.split()[1]) * 1024
        if self.maps_s > 0 and row["t"] >= self._next_maps:
            self._next_maps = row["t"] + self.maps_s
            row["maps"] = mappings()
        if self.trace:
            import tracemalloc

            if not tracemalloc.is_tracing() and row["t"] >= self.trace_after_s:
                tracemalloc.start(1)  # from here on: what is traced is what was allocated since and lives
            row["traced"] = tracemalloc.get_traced_memory()[0] if tracemalloc.is_tracing() else 0
            if tracemalloc.is_tracing() and self.snap_every_s > 0 and row["t"] >= getattr(self, "_next_snap", 0.0):
                self._next_snap = row["t"] + self.snap_every_s
                snap = tracemalloc.take_snapshot().filter_traces([tracemalloc.Filter(False, tracemalloc.__file__)])
                if self._snap0 is None:
                    self._snap0 = snap
                else:  # the lines whose live memory grew most since the first snapshot
                    row["grew"] = [(str(d.traceback[0]), d.size_diff, d.count_diff)
                                   for d in snap.compare_to(self._snap0, "lineno")[:15]]
        return row

    def start(self) -> None:
        import threading

        def run() -> None:
            t0 = time.monotonic()
            last_trim = t0
            with open(self.path, "w") as f:
                while True:
                    f.write(json.dumps(self.sample(t0)) + "\n")
                    f.flush()
                    if self.trim_s > 0 and time.monotonic() - last_trim >= self.trim_s:
                        from fgloc import memory

                        memory.trim()
                        self.trimmed += 1
                        last_trim = time.monotonic()
                    time.sleep(self.every_s)

        threading.Thread(target=run, name="memprobe", daemon=True).start()


class LoopTransport:
    """:class:`fgloc.ros2.transport.Transport` without DDS, for ``--no-dds``: a write hands the bytes to this
    process's subscriptions of its topic at once, in the writer's thread (as the receive thread would); a
    transient-local writer's last sample goes to a subscription made later (as DDS's durability)."""

    domain_id = 0

    def __init__(self) -> None:
        self._subs: dict[str, list[tuple[Any, Any]]] = {}
        self._pubs: dict[str, list[Any]] = {}
        self._health: list[Any] = []
        self._latched: dict[str, bytes] = {}
        self._late: list[tuple[str, Any, Any]] = []  # transient-local subscriptions: the last sample at start()

    def publisher(self, topic: str, type_name: str, qos: Any) -> Any:
        from fgloc.ros2.transport import EndpointHealth

        h = EndpointHealth(topic, type_name, "pub", qos)
        subs = self._subs.setdefault(topic, [])
        h.matched = len(subs)
        self._pubs.setdefault(topic, []).append(h)
        self._health.append(h)
        latched = self._latched if qos.durability == "transient_local" else None

        class Writer:
            health = h

            def write(self, data: bytes) -> bool:
                now = time.time()
                for sh, cb in subs:
                    sh.messages += 1
                    sh.last_arrival = now
                    try:
                        cb(data, now)
                    except Exception as e:  # noqa: BLE001 - counted as the DDS transport does
                        sh.callback_errors += 1
                        sh.last_error = f"{type(e).__name__}: {e}"
                h.messages += 1
                if latched is not None:
                    latched[topic] = data
                return True

        return Writer()

    def subscribe(self, topic: str, type_name: str, qos: Any, callback: Any) -> Any:
        from fgloc.ros2.transport import EndpointHealth

        h = EndpointHealth(topic, type_name, "sub", qos)
        self._subs.setdefault(topic, []).append((h, callback))
        for p in self._pubs.get(topic, []):
            p.matched += 1
        self._health.append(h)
        if qos.durability == "transient_local":
            self._late.append((topic, h, callback))
        return h

    def start(self) -> None:
        for topic, h, cb in self._late:
            if topic in self._latched:
                h.messages += 1
                cb(self._latched[topic], time.time())

    def health(self) -> list[Any]:
        return list(self._health)

    def remote_endpoints(self, topic: str, kind: str = "sub") -> int:
        return len(self._subs.get(topic, [])) if kind == "sub" else len(self._pubs.get(topic, []))

    def close(self) -> None:
        pass


def in_process(a: argparse.Namespace, log: Path, map_yaml: Path | None, init: list[str],
               probe_path: Path | None) -> tuple[dict, float]:
    """``--no-dds``: the replay in a thread and ``fgloc live --ros2``'s node in this thread, over a
    :class:`LoopTransport`; returns the node's report and the replay's start (time.time())."""
    import gc
    import threading

    from fgloc.maps import load_map
    from fgloc.ros2.live import live_ros2
    from fgloc.ros2.replay import replay

    if probe_path is not None:
        MemProbe(str(probe_path), a.sample_s, a.tracemalloc, a.trim_s).start()
    tr = LoopTransport()
    stop = threading.Event()
    started = [0.0]
    occ = load_map(map_yaml) if map_yaml is not None else None

    def play() -> None:
        started[0] = time.time()
        replay(log, tr, rate=a.rate, occ_map=occ, wait_for_subscribers_s=60.0, now=a.now)
        time.sleep(3.0)  # the node's backlog
        stop.set()

    threading.Thread(target=play, name="replay", daemon=True).start()
    sys.setswitchinterval(0.0005)  # as fgloc live --ros2
    pose = tuple(float(v) for v in init[1:]) if init else None
    rep = live_ros2(map_yaml=None, backend="smoother", frontend="native", initial_pose=pose,  # type: ignore[arg-type]
                    record=None, publish=None, duration=None, config=a.config, out=None, out_smoothed=None,
                    quiet=True, view=None, domain=None, interface=None, scan_topic=None, on_started=gc.freeze,
                    transport=tr, stop=stop)
    return rep, started[0]


#: ``fgloc live`` with a :class:`MemProbe` in its process: argv = probe file, every_s, trace 0/1, trim_s, fgloc's args
PROBED = """
import signal, sys
signal.signal(signal.SIGINT, signal.default_int_handler)
sys.path.insert(0, %r)
from bench_ros2 import MemProbe
MemProbe(sys.argv[1], float(sys.argv[2]), sys.argv[3] == "1", float(sys.argv[4])).start()
from fgloc.cli import main
sys.argv = ["fgloc", *sys.argv[5:]]
main()
"""


def fgloc(*args: str) -> list[str]:
    return [sys.executable, "-m", "fgloc.cli", *args]


RECEIVER = """
import os, signal, sys, time
signal.signal(signal.SIGINT, signal.default_int_handler)  # a background shell starts children ignoring it
from fgloc.ros2 import codec, qos
from fgloc.ros2.transport import CycloneTransport
tr = CycloneTransport(int(sys.argv[1]), "lo")
n = [0]
for topic, typ in (("/scan", "sensor_msgs/msg/LaserScan"), ("/odom", "nav_msgs/msg/Odometry"),
                   ("/imu", "sensor_msgs/msg/Imu"), ("/tf_static", "tf2_msgs/msg/TFMessage")):
    prof = qos.TF_STATIC_SUB if topic == "/tf_static" else qos.SENSOR_DATA.with_depth(100)
    def on(data, arrival, typ=typ, topic=topic):
        codec.decode_tf(data) if topic == "/tf_static" else codec.decode(typ, data, topic)
        n[0] += 1
    tr.subscribe(topic, typ, prof, on)
tr.start()
try:
    while True:
        time.sleep(1.0)
except KeyboardInterrupt:
    pass
print('{"received": %d}' % n[0], flush=True)
os._exit(0)  # without the interpreter's teardown under Cyclone's threads (as the fgloc command)
"""


def slope_interval(t: np.ndarray, v: np.ndarray) -> tuple[float, float]:
    """The least-squares slope of ``v`` over ``t`` and the half-width of its 95 % interval (two standard
    errors of the fit; samples 10 s apart are not independent, so the interval is a lower bound on the noise)."""
    c, cov = np.polyfit(t, v, 1, cov="unscaled")
    resid = v - np.polyval(c, t)
    s2 = float(resid @ resid) / max(len(t) - 2, 1)
    return float(c[0]), 2.0 * float(np.sqrt(cov[0, 0] * s2))


def print_probe(probe: list[dict], t_wall0: float, rate: float, settle_min: float, trim_s: float) -> None:
    """Each quantity the probe sampled: after settling, at the end, growth and slope per minute of log."""
    t = np.array([(r["wall"] - t_wall0) * rate / 60.0 for r in probe])
    after = t >= settle_min
    if after.sum() < 3:
        return
    rows = [("rss", "RSS", 2**20, "MB"), ("malloc_used", "malloc: in use", 2**20, "MB"),
            ("malloc_free", "malloc: free in its arenas", 2**20, "MB"),
            ("malloc_mmap", "malloc: mmapped chunks", 2**20, "MB"),
            ("malloc_arena", "malloc: arenas' size", 2**20, "MB"), ("rssanon", "RSS: anonymous", 2**20, "MB"),
            ("rssfile", "RSS: files", 2**20, "MB"), ("traced", "tracemalloc", 2**20, "MB"),
            ("py_blocks", "Python blocks", 1e3, "k"), ("objects", "gc-tracked objects", 1e3, "k"),
            ("arenas", "malloc arenas", 1, ""), ("threads", "threads", 1, "")]
    print(f"in the live process, after {settle_min:.1f} min of log -> end ({after.sum()} samples"
          + (f", malloc_trim(0) every {trim_s:g} s" if trim_s > 0 else "") + "):")
    for key, name, unit, u in rows:
        if key not in probe[0]:
            continue
        v = np.array([float(r[key]) for r in probe]) / unit
        first = float(np.interp(settle_min, t, v))
        slope = float(np.polyfit(t[after], v[after], 1)[0])
        print(f"  {name:28s} {first:9.2f} -> {v[-1]:9.2f} {u:2s} ({v[-1] - first:+.2f}; slope {slope:+.3f} {u} "
              "per minute of log)")
    last = probe[-1]
    snaps = [(float((r["wall"] - t_wall0) * rate / 60.0), r["maps"]) for r in probe if r.get("maps")]
    snaps_after = [s for s in snaps if s[0] >= settle_min]
    if len(snaps_after) >= 2:
        (t_a, a), (t_b, b) = snaps_after[0], snaps_after[-1]

        def kind(m: list) -> str:
            return m[4] or f"anonymous {m[3]}"

        d = sorted(((b[k][1] - (a[k][1] if k in a else 0), k) for k in b), reverse=True)
        gone = sum(a[k][1] for k in a if k not in b)
        print(f"  mappings whose RSS grew most from {t_a:.1f} to {t_b:.1f} min of log ({len(a)} -> {len(b)} "
              f"mappings; {gone / 1024:.2f} MB in those unmapped):")
        for dk, k in d[:12]:
            m = b[k]
            print(f"    {dk / 1024:+7.2f} MB  {k} {m[0] / 1024:8.1f} MB mapped, Rss {m[1] / 1024:6.2f} MB  {kind(m)}")
        by: dict[str, float] = {}
        for k in set(a) | set(b):
            m = b.get(k) or a[k]
            name = "[heap]" if m[4] == "[heap]" else ("a file" if m[4].startswith("/") else kind(m))
            by[name] = by.get(name, 0.0) + (b[k][1] if k in b else 0) - (a[k][1] if k in a else 0)
        kinds = sorted(by.items(), key=lambda x: -abs(x[1]))
        print("    by kind: " + ", ".join(f"{n} {v / 1024:+.2f} MB" for n, v in kinds))
    grew = [r for r in probe if r.get("grew")]
    if grew:
        r = grew[-1]
        print(f"  tracemalloc: the lines whose live memory grew most from the first snapshot to "
              f"{(r['wall'] - t_wall0) * rate / 60.0:.1f} min of log:")
        for where, size, count in r["grew"][:12]:
            print(f"    {size / 1e3:+9.1f} kB {count:+7d} blocks  {where}")
    if "gc_n" in last:
        print(f"  cyclic GC (threshold {last['gc_threshold']}, {last['frozen']} objects frozen): passes per generation "
              f"{last['gc_n']}, total {last['gc_ms']} ms, longest {last['gc_max_ms']} ms")
        long = [tuple(x) for r in probe for x in r["gc_long"]]
        long = sorted(set(long))
        after_start = [x for x in long if x[0] >= t_wall0]
        if after_start:
            ms = np.array([x[2] for x in after_start])
            print(f"  GC pauses over 2 ms during the replay: {len(ms)} (generations "
                  f"{[sum(1 for x in after_start if x[1] == g) for g in range(3)]}), p50 {np.median(ms):.1f} ms, "
                  f"max {ms.max():.1f} ms")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--log", type=Path, help="a log (default: fgloc simulate paper, --loops times round)")
    ap.add_argument("--map", type=Path, help="its map, published by the replay on /map")
    ap.add_argument("--loops", type=int, default=1, help="simulated runs: times round the paper's rectangle")
    ap.add_argument("--rate", type=float, default=1.0, help="replay rate (x real time)")
    ap.add_argument("--domain", type=int, default=1 + os.getpid() % 100)
    ap.add_argument("--no-initial-pose", action="store_true", help="global localization at the start")
    ap.add_argument("--out", type=Path, help="write the samples and the report (JSON) here")
    ap.add_argument("--receive-only", action="store_true", help="fgloc's DDS receive path alone, no localizer")
    ap.add_argument("--now", action="store_true", help="replay with the header stamps on the wall clock (as a "
                    "robot's drivers stamp them)")
    ap.add_argument("--config", type=Path, help="fgloc live's --config")
    ap.add_argument("--compare", type=Path, help="a fgloc run output folder of the same log: compare /amcl_pose")
    ap.add_argument("--sample-s", type=float, default=10.0, help="wall seconds between RSS samples")
    ap.add_argument("--settle", type=float, default=2.0, help="minutes of log before the memory is judged")
    ap.add_argument("--last", type=float, default=5.0, help="minutes of log at the end whose RSS slope is judged "
                    "against zero (flat: 0 within the slope's 95 %% interval)")
    ap.add_argument("--png", type=Path, help="plot the live process's RSS over minutes of log into this PNG")
    ap.add_argument("--probe", action="store_true", help="sample malloc / Python memory inside the live process")
    ap.add_argument("--tracemalloc", action="store_true", help="--probe: tracemalloc on in the live process")
    ap.add_argument("--trim-s", type=float, default=0.0, help="--probe: malloc_trim(0) every this many seconds")
    ap.add_argument("--trace-after-s", type=float, default=0.0, help="--tracemalloc: start tracing this many "
                    "seconds into the live process (then what is traced is what was allocated since and lives)")
    ap.add_argument("--snap-s", type=float, default=0.0, help="--tracemalloc: a snapshot this often; the lines "
                    "whose memory grew most since the first are printed")
    ap.add_argument("--maps-s", type=float, default=0.0, help="--probe: the live process's memory mappings "
                    "(/proc/self/smaps) this often; the ones whose RSS grew most after settling are printed")
    ap.add_argument("--no-dds", action="store_true", help="replay and node in this process, no DDS (implies --probe)")
    a = ap.parse_args()
    if a.no_dds:
        a.probe = True
    os.environ["FGLOC_PROBE_TRACE_AFTER_S"] = str(a.trace_after_s)  # read by MemProbe in the live process
    os.environ["FGLOC_PROBE_SNAP_S"] = str(a.snap_s)
    os.environ["FGLOC_PROBE_MAPS_S"] = str(a.maps_s)
    tmp = Path(tempfile.mkdtemp(prefix="bench_ros2_"))
    init = ["--initial-pose", "2.5", "3.0", "0.0"]
    if a.log is None:
        from fgloc.sim import run_scenario, write_sim

        t0 = time.monotonic()
        write_sim(run_scenario({"name": "bench", "loops": a.loops}, seed=0), tmp)
        log, map_yaml = tmp / "log.mcap", tmp / "map.yaml"
        print(f"simulated the paper run x{a.loops} in {time.monotonic() - t0:.0f} s", flush=True)
    else:
        log, map_yaml = a.log, a.map
        if a.no_initial_pose:
            init = []
    common = ["--domain", str(a.domain), "--interface", "lo"]
    poses: list[tuple[float, float, float]] = []
    sub = None
    if a.compare is not None:
        from fgloc.ros2 import codec, qos
        from fgloc.ros2.transport import CycloneTransport

        sub = CycloneTransport(a.domain, "lo")

        def on_pose(data: bytes, arrival: float) -> None:
            f = codec.decode("geometry_msgs/msg/PoseWithCovarianceStamped", data)
            poses.append((f.stamp, f.pose[0], f.pose[1]))  # type: ignore[attr-defined]

        sub.subscribe("/amcl_pose", "geometry_msgs/msg/PoseWithCovarianceStamped", qos.LATCHED_PUB.with_depth(5000),
                      on_pose)
        sub.start()
    probe_path = tmp / "probe.jsonl" if a.probe else None
    rep_out = ""
    samples: list[tuple[float, float]] = []  # wall s since the replay started, RSS MB
    load0 = os.getloadavg()[0]
    if a.no_dds:
        report, t_wall0 = in_process(a, log, map_yaml, init, probe_path)
        report = json.loads(json.dumps(report, default=str))
    else:
        cmd = [sys.executable, "-c", RECEIVER, str(a.domain)] if a.receive_only else \
            fgloc("live", "--ros2", *common, "--quiet", "--json", *init,
                  *(["--config", str(a.config)] if a.config else []))
        if a.probe and not a.receive_only:
            cmd = [sys.executable, "-c", PROBED % str(Path(__file__).resolve().parent), str(probe_path),
                   str(a.sample_s), "1" if a.tracemalloc else "0", str(a.trim_s), *cmd[3:]]
        live = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        proc = psutil.Process(live.pid)
        replay = subprocess.Popen(fgloc("replay", str(log), "--ros2", *common, "--rate", str(a.rate), "--wait", "60",
                                        "--quiet", *(["--map", str(map_yaml)] if map_yaml else []),
                                        *(["--now"] if a.now else [])),
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        t_start = time.monotonic()
        t_wall0 = time.time()
        while replay.poll() is None:
            samples.append((time.monotonic() - t_start, proc.memory_info().rss / 2**20))
            t_next = t_start + len(samples) * a.sample_s
            while replay.poll() is None and time.monotonic() < t_next:
                time.sleep(0.2)
        rep_out = replay.stdout.read() if replay.stdout else ""
        time.sleep(3.0)  # the live node's backlog
        samples.append((time.monotonic() - t_start, proc.memory_info().rss / 2**20))
        live.send_signal(signal.SIGTERM)  # as SIGINT (Ctrl-C); SIGINT stays ignored in a background shell
        out, err = live.communicate(timeout=300)
        if live.returncode not in (0, 130):
            print(f"fgloc live exited {live.returncode}:\n{err[-3000:]}", file=sys.stderr)
            return 1
        report = json.loads(out)
    probe = [json.loads(line) for line in probe_path.read_text().splitlines()] if probe_path else []
    if a.no_dds:  # the probe's RSS, from the replay's start
        samples = [(r["wall"] - t_wall0, r["rss"] / 2**20) for r in probe if r["wall"] >= t_wall0]
    print(rep_out.strip().splitlines()[0] if rep_out.strip() else "replay: no output")
    print(f"load average (1 min, {os.cpu_count()} cores): {load0:.1f} at the start, "
          f"{os.getloadavg()[0]:.1f} at the end")
    if a.receive_only:
        print(f"receive-only: {report['received']} messages decoded")
        report = {"ros2": {"problems": []}}
    else:
        r2 = report["ros2"]
        c = report["counters"]
        how = f"at the match, {r2['tf_refined']} refined" if r2["tf_at_match"] else "with the online pose"
        print(f"scans fused {c['scans_fused']}, skipped as a backlog {c['scans_skipped_backlog']}, fixes {c['fixes']}, "
              f"poses published {r2['published']}, map->odom {r2['tf_published']} ({how})")

        if c.get("malloc_trims"):
            print(f"malloc_trim(0) in the fusion loop: {c['malloc_trims']} calls, mean "
                  f"{c['malloc_trim_us'] / c['malloc_trims'] / 1e3:.2f} ms, longest "
                  f"{c['malloc_trim_us_max'] / 1e3:.2f} ms")

        def pp(d: dict) -> str:
            return f"p50 {d['p50']:.2f} ms, p99 {d['p99']:.2f} ms"

        print(f"scan arrival -> map->odom published: {pp(r2['scan_to_tf_ms'])}")
        if r2.get("scan_to_fused_ms", {}).get("n"):
            print(f"  side by side, the same scans: map->odom out before the session's fused pose (now) "
                  f"{pp(r2['scan_to_tf_ms'])} | after it (before: the fused pose first) {pp(r2['scan_to_fused_ms'])}")
        print(f"scan arrival -> /amcl_pose (the back-end's online pose) published: {pp(r2['scan_to_pose_ms'])}; "
              f"from the odometry / IMU past the scan's stamp in: {pp(r2['inputs_in_to_pose_ms'])}")
        tm = r2["tf_at_match_ms"]
        if tm["handle"]["n"]:
            print(f"map->odom at the match: arrival -> handling began {pp(tm['queue'])}; handling -> published "
                  f"{pp(tm['handle'])}, of which the fusion thread's CPU {pp(tm['cpu'])}")
            slow = r2.get("tf_at_match_slowest") or []
            n1 = min(len(slow), max(1, round(0.01 * r2["scan_to_tf_ms"]["n"])))
            if n1 and "process_cpu_ms" in slow[0]:
                top = slow[:n1]

                def mean(k: str) -> float:
                    return float(np.mean([x.get(k, np.nan) for x in top]))

                idle = float(np.mean([max(0.0, x["tf_ms"] - x.get("process_cpu_ms", 0.0)) for x in top]))
                print(f"the slowest 1 % ({n1} scans, {mean('tf_ms'):.1f} ms on average, at "
                      f"{min(x['since_start_s'] for x in top):.0f}-{max(x['since_start_s'] for x in top):.0f} s "
                      f"after the start): queue {mean('queue_ms'):.1f} + handling {mean('handle_ms'):.1f} ms; "
                      f"the fusion thread's CPU {mean('cpu_ms'):.1f} ms, the process's CPU (every thread) "
                      f"{mean('process_cpu_ms'):.1f} ms of which GC {mean('gc_ms'):.1f} ms; no thread of fgloc "
                      f"running {idle:.1f} ms")
            g = r2.get("gc")
            if g:
                print(f"cyclic GC in the node (whole run): passes {g['passes']}, {g['total_ms']} ms, longest "
                      f"{g['longest_ms']} ms")
            d = r2["tf_at_match_vs_online_mm"]
            print(f"map->odom at the match vs from the online pose: p50 {d['p50']:.2f} mm, p99 {d['p99']:.2f} mm, "
                  f"max {d['max']:.2f} mm over {d['n']} scans")
        scan = next((e for e in r2["endpoints"] if e["topic"] == "/scan" and e["direction"] == "sub"), {})
        if scan.get("delivery_ms"):
            print(f"/scan written -> taken by fgloc's receive thread: {pp(scan['delivery_ms'])}")
    t = np.array([s[0] for s in samples]) * a.rate / 60.0  # minutes of log
    m = np.array([s[1] for s in samples])
    settle = min(a.settle, 0.25 * t[-1])
    after = t >= settle
    if after.sum() >= 3:
        slope = float(np.polyfit(t[after], m[after], 1)[0])
        marks = [float(np.interp(q * t[-1], t, m)) for q in (0.25, 0.5, 0.75, 1.0)]
        first = float(np.interp(settle, t, m))
        print(f"live RSS: {first:.1f} MB after {settle:.1f} min of log; at 1/4, 1/2, 3/4, end of "
              f"{t[-1]:.1f} min: " + ", ".join(f"{v:.1f}" for v in marks)
              + f" MB; growth after settling {m[-1] - first:+.1f} MB (max {m[after].max() - first:+.1f}), "
              f"slope {slope:+.3f} MB per minute of log ({len(samples)} samples every {a.sample_s:g} s)")
        last = t >= t[-1] - a.last
        fit = slope_interval(t[last], m[last]) if last.sum() >= 4 else None
        if fit is not None:
            b, half = fit
            verdict = "flat: 0 within the interval" if abs(b) <= half else "not flat: 0 outside the interval"
            print(f"live RSS over the last {a.last:g} min of log ({last.sum()} samples): slope {b:+.3f} +- "
                  f"{half:.3f} MB per minute of log (95 %, two standard errors of the fit): {verdict}; "
                  f"{m[last][-1] - float(np.interp(t[-1] - a.last, t, m)):+.2f} MB over them")
        if a.png is not None:
            import matplotlib

            matplotlib.use("Agg")
            import matplotlib.pyplot as plt

            fig, (ax0, ax) = plt.subplots(2, 1, figsize=(7, 5.5), height_ratios=(1, 1.4))
            ax0.plot(t, m, ".-", ms=3)
            ax0.axvline(settle, color="0.6", ls="--", lw=0.8)
            ax0.set_ylabel("RSS (MB)")
            ax0.set_title(f"fgloc live --ros2, rate {a.rate:g}: RSS over the replay; below, after "
                          f"{settle:.1f} min of log", fontsize=9)
            ax0.grid(alpha=0.3)
            ax.plot(t[after], m[after], ".-", ms=3)
            ax.set_xlabel("minutes of log")
            ax.set_ylabel("RSS (MB)")
            title = f"slope after {settle:.1f} min: {slope:+.3f} MB/min"
            if fit is not None:
                tl = t[last]
                c = np.polyfit(tl, m[last], 1)
                ax.plot(tl, np.polyval(c, tl), "r-", lw=1.5, label=f"last {a.last:g} min: {fit[0]:+.3f} +- "
                        f"{fit[1]:.3f} MB/min")
                ax.legend(fontsize=8, loc="lower right")
            ax.set_title(title, fontsize=9)
            ax.grid(alpha=0.3)
            fig.tight_layout()
            fig.savefig(a.png, dpi=110)
            print(f"plot: {a.png}")
    if len(probe) >= 3:
        print_probe(probe, t_wall0, a.rate, settle if len(samples) else a.settle, a.trim_s)
    if a.compare is not None and sub is not None:
        from fgloc.io.tum import read_tum

        sub.close()
        ref = read_tum(a.compare / "online.tum")

        def matched(offset: float, tol: float) -> list[tuple[int, float, float]]:
            out = []
            for t_s, x, y in poses:
                k = int(np.searchsorted(ref.stamps, t_s - offset - tol))
                if k < len(ref.stamps) and abs(ref.stamps[k] - (t_s - offset)) <= tol:
                    out.append((k, x, y))
            return out

        offset, tol = 0.0, 1e-6
        if a.now and poses:  # the stamps were moved onto the wall clock by one offset: find it
            tol = 5e-6  # float64 seconds since 1970: ~0.2 us
            first = min(p[0] for p in poses)
            offset = max((first - s for s in ref.stamps[:200]), key=lambda o: len(matched(o, tol)))
        d = [float(np.hypot(x - ref.poses[k, 0], y - ref.poses[k, 1])) for k, x, y in matched(offset, tol)]
        if d:
            print(f"/amcl_pose vs {a.compare}/online.tum: {len(d)} of {len(ref.stamps)} stamps; distance max "
                  f"{1e3 * max(d):.2f} mm, median {1e3 * float(np.median(d)):.2f} mm, "
                  f"p99 {1e3 * float(np.percentile(d, 99)):.2f} mm")
    if report["ros2"]["problems"]:
        print("DDS: " + "; ".join(report["ros2"]["problems"]))
    if a.out is not None:
        a.out.write_text(json.dumps({"samples": samples, "rate": a.rate, "report": report}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
