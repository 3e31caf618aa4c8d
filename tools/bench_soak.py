#!/usr/bin/env python
"""Soak: `fgloc live` over a long run against the emulators, its resident memory sampled.

A robot drives laps of a room (:func:`fgloc.testing.soak.lap_world`: odometry 50 Hz, compass 20 Hz,
scans 25 Hz of 541 beams) for ``--minutes`` of log; this process replays it
through the STM32 emulator (fgloc's serial frames over a real TCP socket, pyserial's ``socket://``) and the
SICK emulator (CoLa-A over real TCP) at ``--speed`` times real time, into ``fgloc live`` in its own process
(the map, the start pose, a config with the robot's geometry and noise), and samples that process's RSS
(psutil) as the replay goes.  At the end it stops `fgloc live` with SIGTERM (a service manager's stop) and prints

* the RSS after the first ``--settle`` minutes of log, at each quarter and at the end; the largest rise
  over the settled RSS (the issue's bound: within 20 MB); the slope of a line fitted after settling
  (MB per hour of log) and what it makes in a day;
* the scans sent, fused and skipped as a backlog (an accelerated replay on a busy machine skips scans:
  those exercise the input paths and the recording, not the localizer, so the slope per fused scan is
  printed too).

    python tools/bench_soak.py                                    # 60 min of log at 4x (15 min), smoother
    python tools/bench_soak.py --minutes 60 --speed 4 --record --png soak.png
    python tools/bench_soak.py --minutes 10 --speed 2 -o          # -o keeps every pose (32 B each)
    python tools/bench_soak.py --minutes 60 --in-process --record  # no devices: as fast as it goes

``--in-process``: the same messages, map, config and session as ``fgloc live`` builds (its history and
trajectory windows, ``--record`` into an MCAP), pushed through the live runner's own ingest in this
process as fast as the localizer goes (:func:`fgloc.testing.soak.feed_live`): every buffer of the
localizer, back-end, health estimators, live trajectory and recording, without the devices' threads and
the queue between them and the runner (whose length is the host's speed, not the session's).  On a busy
host the device soak's queue grows while `fgloc live` waits for the CPU; this mode's memory is the
session's own.
"""

from __future__ import annotations

import argparse
import json
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import psutil

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--minutes", type=float, default=60.0, help="minutes of log replayed")
    ap.add_argument("--speed", type=float, default=4.0, help="replay speed (1 = real time)")
    ap.add_argument("--settle", type=float, default=5.0, help="minutes of log before the memory is judged")
    ap.add_argument("--backend", default="smoother")
    ap.add_argument("--frontend", default="native")
    ap.add_argument("--record", action="store_true", help="fgloc live --record (into a temporary folder)")
    ap.add_argument("-o", "--output", action="store_true", help="fgloc live -o (keeps the whole trajectory)")
    ap.add_argument("--sample-s", type=float, default=2.0, help="wall seconds between RSS samples")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--in-process", action="store_true",
                    help="no devices: the live runner's ingest in this process, as fast as it goes")
    ap.add_argument("--png", type=Path, help="plot RSS over minutes of log into this PNG")
    ap.add_argument("--csv", type=Path, help="write the samples (log min, wall s, RSS MB) here")
    a = ap.parse_args(argv)

    import yaml
    from tqdm import tqdm

    from fgloc.live.serial_link import RobotParams
    from fgloc.testing.emulators import EmulatorPair
    from fgloc.testing.harness import live_config_overrides
    from fgloc.testing.soak import lap_world

    world = lap_world(seed=a.seed)
    duration_s = a.minutes * 60.0
    rp = RobotParams.from_dict({"drive": "mecanum"})
    tmp = Path(tempfile.mkdtemp(prefix="fgloc-soak-"))
    if a.in_process:
        samples, report, n_scans = _in_process(a, world, rp, tmp)
        return _report(a, samples, report, n_scans, tmp)
    msgs = list(world.messages(duration_s))  # the lap's scans share their range arrays: an hour costs little
    map_yaml = world.map.save(tmp / "map.yaml")
    cfg = tmp / "robot.yaml"
    cfg.write_text(yaml.safe_dump(live_config_overrides(msgs, rp, world.mount)))
    x, y, yaw = (float(v) for v in world.pose(0.0))
    # the emulators listen now and start the replay 15 s from now: `fgloc live` starts and connects meanwhile
    pair = EmulatorPair.create(msgs, rp, mode="tcp", speed=a.speed, duration=duration_s, lead_s=15.0)
    del msgs
    cmd = [sys.executable, "-m", "fgloc.cli", "live", "--serial", pair.stm32.url, "--laser", pair.sick.address,
           "--map", str(map_yaml), "--initial-pose", f"{x}", f"{y}", f"{yaw}", "--config", str(cfg),
           "--backend", a.backend, "--frontend", a.frontend, "--json", "-q"]
    if a.record:
        cmd += ["--record", str(tmp / "live.mcap")]
    if a.output:
        cmd += ["-o", str(tmp / "live.tum")]
    # its output into files: a pipe read only at the end fills (64 KB of event lines on a busy host) and
    # blocks fgloc live in its next write
    out_f, err_f = (tmp / "live.json").open("w+"), (tmp / "live.err").open("w+")
    proc = subprocess.Popen(cmd, stdout=out_f, stderr=err_f, text=True)
    ps = psutil.Process(proc.pid)
    pair.start()
    samples: list[tuple[float, float, float]] = []  # (log min, wall s since the replay started, RSS MB)
    start = pair.clock.start_host
    n_scans = len(pair.sick.scans)
    with tqdm(total=round(a.minutes, 1), desc=f"replaying at {a.speed:g}x", unit="log min") as bar:
        while not (pair.stm32.done.is_set() and pair.sick.done.is_set()):
            time.sleep(a.sample_s)
            if proc.poll() is not None:
                break
            wall = time.time() - start
            if wall > 0:
                samples.append((wall * a.speed / 60.0, wall, ps.memory_info().rss / 2**20))
                bar.n = round(min(samples[-1][0], a.minutes), 1)
                bar.set_postfix_str(f"RSS {samples[-1][2]:.0f} MB")
    time.sleep(1.0)
    if proc.poll() is None:
        samples.append(((time.time() - start) * a.speed / 60.0, time.time() - start, ps.memory_info().rss / 2**20))
        proc.send_signal(signal.SIGTERM)  # SIGINT: a shell's background job ignores it
    cpu_s = sum(ps.cpu_times()[:2])
    proc.wait(timeout=600)
    pair.stop()
    out_f.seek(0)
    err_f.seek(0)
    out, err = out_f.read(), err_f.read()
    if proc.returncode not in (0, 130):
        print(f"fgloc live exited {proc.returncode}:\n{err[-3000:]}", file=sys.stderr)
        return 1
    print(f"fgloc live used {cpu_s:.0f} CPU s in {samples[-1][1]:.0f} s of replay "
          f"({100 * cpu_s / max(samples[-1][1], 1e-9):.0f} % of a core)")
    return _report(a, samples, json.loads(out), n_scans, tmp)


def _in_process(a: argparse.Namespace, world: Any, rp: Any,
                tmp: Path) -> tuple[list[tuple[float, float, float]], dict[str, Any], int]:
    """``fgloc live``'s session and runner without devices, the lap world through its ingest; RSS
    sampled every 10 s of log."""
    from tqdm import tqdm

    from fgloc.config import parse_config
    from fgloc.live.app import LIVE_HISTORY_S, LiveSession
    from fgloc.localization import build_session
    from fgloc.testing.harness import live_config_overrides
    from fgloc.testing.soak import feed_live

    duration_s = a.minutes * 60.0
    cfg = parse_config(live_config_overrides(list(world.messages(world.lap_s)), rp, world.mount))
    session = build_session(world.map, world.mount, backend=a.backend, frontend=a.frontend,
                            initial_pose=world.pose(0.0), config=cfg)
    session.loc.keep_history(LIVE_HISTORY_S)   # as fgloc live without --out-smoothed
    live = LiveSession(session, None, None, config=cfg, record=tmp / "live.mcap" if a.record else None,
                       trajectory_window_s=None if a.output else LIVE_HISTORY_S)
    live.start()
    ps = psutil.Process()
    samples: list[tuple[float, float, float]] = []
    start = time.time()
    with tqdm(total=round(a.minutes, 1), desc="in process", unit="log min") as bar:
        def sample(t: float) -> None:
            samples.append((t / 60.0, time.time() - start, ps.memory_info().rss / 2**20))
            bar.n = round(min(samples[-1][0], a.minutes), 1)
            bar.set_postfix_str(f"RSS {samples[-1][2]:.0f} MB")

        feed_live(live.runner, world.messages(duration_s), every_s=10.0, on_progress=sample)
        sample(duration_s)
    summary = live.close()
    n_scans = int(summary.counters.get("scans_fused", 0)) + int(summary.counters.get("scans_skipped_backlog", 0))
    report = {"counters": summary.counters,
              "latency_ms": {"p50": summary.latency_p50_ms, "p99": summary.latency_p99_ms}}
    return samples, report, n_scans


def _report(a: argparse.Namespace, samples: list[tuple[float, float, float]], report: dict[str, Any],
            n_scans: int, tmp: Path) -> int:
    c = report.get("counters", {})
    s = np.array(samples)
    if a.csv:
        np.savetxt(a.csv, s, delimiter=",", header="log_min,wall_s,rss_mb", fmt="%.3f")
    settled = s[s[:, 0] >= a.settle]
    how = "in process, as fast as it goes" if a.in_process else f"at {a.speed:g}x over real TCP"
    print(f"\nfgloc live --backend {a.backend} --frontend {a.frontend}{' --record' if a.record else ''}"
          f"{' -o' if a.output else ''}: {a.minutes:g} min of log {how} ({len(s)} samples, "
          f"{s[-1, 1] / 60.0:.1f} min wall)")
    if a.in_process:  # (no arrival times: no latency)
        print(f"scans {n_scans}, fused {c.get('scans_fused', 0)}; fixes {c.get('fixes', 0)}")
    else:
        print(f"scans sent {n_scans}, read {c.get('laser', {}).get('scans', 0)}, fused {c.get('scans_fused', 0)}, "
              f"skipped as a backlog {c.get('scans_skipped_backlog', 0)}; fixes {c.get('fixes', 0)}; "
              f"latency p50 {report['latency_ms']['p50']:.1f} ms p99 {report['latency_ms']['p99']:.1f} ms; "
              f"at most {c.get('queue_max', 0)} messages queued")
    if c.get("queue_max", 0) > 500:  # 2 s of input at 4x
        print("  fgloc live fell behind the replay (its queue holds messages): try a lower --speed")
    if len(settled) < 3:
        print(f"too short to judge: fewer than 3 samples after {a.settle:g} min of log")
        return 1
    base = float(settled[0, 2])
    marks = [(f"{m:.3g} min", float(np.interp(m, s[:, 0], s[:, 2])))
             for m in (1.0, a.settle, *(q * a.minutes for q in (0.25, 0.5, 0.75)))] + [("end", float(s[-1, 2]))]
    print("RSS: " + ", ".join(f"{k} {v:.1f} MB" for k, v in marks))
    rise = float(settled[:, 2].max() - base)
    slope_h = float(np.polyfit(settled[:, 0], settled[:, 2], 1)[0]) * 60.0
    fused = max(int(c.get("scans_fused", 0)), 1)
    per_scan = slope_h * 2**20 / (fused / (s[-1, 0] / 60.0))
    print(f"after {a.settle:g} min of log: largest rise {rise:.1f} MB over {base:.1f} MB; slope {slope_h:+.1f} MB "
          f"per hour of log ({slope_h * 24:+.0f} MB a day), {per_scan:+.0f} B per fused scan")
    print(f"files in {tmp}")
    if a.png:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(7, 3.5))
        ax.plot(s[:, 0], s[:, 2], lw=1)
        ax.axvline(a.settle, color="0.6", ls="--", lw=0.8)
        ax.axhspan(base, base + 20.0, color="tab:green", alpha=0.1, label="settled RSS + 20 MB")
        ax.set_xlabel("minutes of log")
        ax.set_ylabel("fgloc live RSS (MB)")
        how = "in process" if a.in_process else f"{a.speed:g}x over TCP"
        ax.set_title(f"fgloc live, {a.backend}, {how}: {slope_h:+.1f} MB per hour of log")
        ax.legend(loc="lower right")
        fig.tight_layout()
        fig.savefig(a.png, dpi=110)
        print(f"plot: {a.png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
