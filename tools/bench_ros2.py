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

import numpy as np
import psutil


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


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--log", type=Path, help="a log (default: fgloc simulate paper, --loops times round)")
    ap.add_argument("--map", type=Path, help="its map, published by the replay on /map")
    ap.add_argument("--loops", type=int, default=1, help="simulated runs: times round the paper's rectangle")
    ap.add_argument("--rate", type=float, default=1.0, help="replay rate (x real time)")
    ap.add_argument("--domain", type=int, default=1 + os.getpid() % 200)
    ap.add_argument("--no-initial-pose", action="store_true", help="global localization at the start")
    ap.add_argument("--out", type=Path, help="write the samples and the report (JSON) here")
    ap.add_argument("--receive-only", action="store_true", help="fgloc's DDS receive path alone, no localizer")
    ap.add_argument("--now", action="store_true", help="replay with the header stamps on the wall clock (as a "
                    "robot's drivers stamp them)")
    ap.add_argument("--config", type=Path, help="fgloc live's --config")
    ap.add_argument("--compare", type=Path, help="a fgloc run output folder of the same log: compare /amcl_pose")
    ap.add_argument("--sample-s", type=float, default=10.0, help="wall seconds between RSS samples")
    ap.add_argument("--settle", type=float, default=2.0, help="minutes of log before the memory is judged")
    ap.add_argument("--png", type=Path, help="plot the live process's RSS over minutes of log into this PNG")
    a = ap.parse_args()
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
    cmd = [sys.executable, "-c", RECEIVER, str(a.domain)] if a.receive_only else \
        fgloc("live", "--ros2", *common, "--quiet", "--json", *init,
              *(["--config", str(a.config)] if a.config else []))
    live = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    proc = psutil.Process(live.pid)
    replay = subprocess.Popen(fgloc("replay", str(log), "--ros2", *common, "--rate", str(a.rate), "--wait", "60",
                                    "--quiet", *(["--map", str(map_yaml)] if map_yaml else []),
                                    *(["--now"] if a.now else [])),
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    t_start = time.monotonic()
    load0 = os.getloadavg()[0]
    samples: list[tuple[float, float]] = []  # wall s since the replay started, RSS MB
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
    report = json.loads(out)
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

        def pp(d: dict) -> str:
            return f"p50 {d['p50']:.2f} ms, p99 {d['p99']:.2f} ms"

        print(f"scan arrival -> map->odom published: {pp(r2['scan_to_tf_ms'])}")
        print(f"scan arrival -> /amcl_pose (the back-end's online pose) published: {pp(r2['scan_to_pose_ms'])}; "
              f"from the odometry / IMU past the scan's stamp in: {pp(r2['inputs_in_to_pose_ms'])}")
        tm = r2["tf_at_match_ms"]
        if tm["handle"]["n"]:
            print(f"map->odom at the match: arrival -> handling began {pp(tm['queue'])}; handling -> published "
                  f"{pp(tm['handle'])}, of which the fusion thread's CPU {pp(tm['cpu'])}")
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
        if a.png is not None:
            import matplotlib

            matplotlib.use("Agg")
            import matplotlib.pyplot as plt

            fig, ax = plt.subplots(figsize=(7, 3.5))
            ax.plot(t, m, ".-", ms=3)
            ax.axvline(settle, color="0.6", ls="--", lw=0.8)
            ax.set_xlabel("minutes of log")
            ax.set_ylabel("fgloc live --ros2 RSS (MB)")
            ax.set_title(f"rate {a.rate:g}, slope after {settle:.1f} min: {slope:+.3f} MB/min", fontsize=9)
            ax.grid(alpha=0.3)
            fig.tight_layout()
            fig.savefig(a.png, dpi=110)
            print(f"plot: {a.png}")
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
