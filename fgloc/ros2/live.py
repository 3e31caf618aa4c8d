"""``fgloc live --ros2``: the command's work (options in, summary out), around :class:`Ros2Live`."""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

#: glibc's own initial mmap threshold, kept fixed (see :func:`live_ros2`)
LIVE_MMAP_THRESHOLD_B = 128 * 1024


def summary_line(report: dict[str, Any]) -> str:
    """The session in one line (``--json`` prints the whole report)."""
    r = report.get("ros2") or {}
    if "waiting_for" in report:
        return f"fgloc live: stopped while waiting for {report['waiting_for']}"
    c = report.get("counters") or {}
    lat = r.get("scan_to_tf_ms") or {}
    pose = r.get("scan_to_pose_ms") or {}
    nan = float("nan")
    line = (f"fgloc live: {report.get('duration_s', 0):.1f} s, {r.get('published', 0)} poses published, "
            f"{c.get('scans_fused', 0)} scans fused, {c.get('fixes', 0)} fixes, scan -> tf p50 "
            f"{lat.get('p50', nan):.2f} ms p99 {lat.get('p99', nan):.2f} ms, scan -> /amcl_pose "
            f"p50 {pose.get('p50', nan):.2f} ms p99 {pose.get('p99', nan):.2f} ms")
    probs = r.get("problems") or []
    return line + ("; DDS: " + "; ".join(probs) if probs else "")


def live_ros2(*, map_yaml: Path | None, backend: str, frontend: str,
              initial_pose: tuple[float, float, float] | None,
              record: Path | None, publish: list[str] | None, duration: float | None, config: Path | None,
              out: Path | None, out_smoothed: Path | None, quiet: bool, view: str | None,
              domain: int | None, interface: str | None, scan_topic: str | None, force: bool = False,
              on_started: Callable[[], None] | None = None, transport: Any = None,
              stop: threading.Event | None = None) -> dict[str, Any]:
    """Run until Ctrl-C (or ``duration``); print the status line on stderr; return the summary.
    The output files are checked before anything starts (never over an existing file without
    ``force``, :mod:`fgloc.io.outputs`); a second Ctrl-C skips only the final smoothing.
    ``on_started()``: called once the localizer is built and the messages kept before it fused;
    ``transport``: a :class:`fgloc.ros2.transport.Transport` of the caller's (default: Cyclone DDS on
    ``ros2.domain_id``); ``stop``: set by the caller to end the run as a signal would."""
    from fgloc import memory
    from fgloc.backends import Capability, check_backend
    from fgloc.config import load_config, parse_config
    from fgloc.live.app import LIVE_HISTORY_S, LiveSession, trajectory_outputs
    from fgloc.localization import Session, build_session
    from fgloc.maps import load_map
    from fgloc.ros2.node import Ros2Live
    from fgloc.ros2.transport import CycloneTransport

    backend = check_backend(backend, Capability.LIVE)
    from fgloc.io import stop as stopping
    from fgloc.io.outputs import OutputFile

    if record is not None:
        OutputFile(record, command="live", force=force, precious=True, option="--record").check()
    tums = trajectory_outputs(out, out_smoothed, force)
    cfg = load_config(config)
    over = {k: v for k, v in (("domain_id", domain), ("interface", interface), ("scan_topic", scan_topic))
            if v is not None}
    if over:
        cfg = parse_config({"ros2": over}, source="command line", base=cfg)
    # blocks of 128 kB and more from mmap for the whole run: glibc's dynamic threshold (raised to each
    # freed mmapped block's size) moved the large transient buffers into the heap, which then grew
    # around the long-lived blocks between them (free space in its arenas rising for as long as it ran)
    memory.set_mmap_threshold(LIVE_MMAP_THRESHOLD_B)
    memory.set_trim_threshold(LIVE_MMAP_THRESHOLD_B)  # glibc's default, which the dynamic threshold had raised
    occ = load_map(map_yaml) if map_yaml is not None else None
    init = None if initial_pose is None else np.array(initial_pose, dtype=float)
    tty = sys.stderr.isatty()
    last_len = [0]
    n_lines = [0]

    def status(line: str) -> None:
        if quiet:
            return
        if tty:
            sys.stderr.write("\r" + line + " " * max(0, last_len[0] - len(line)))
            last_len[0] = len(line)
        else:
            n_lines[0] += 1
            if n_lines[0] % 20 == 1:  # every 5 s when not a terminal
                sys.stderr.write(line + "\n")
        sys.stderr.flush()

    def event(msg: str) -> None:
        sys.stderr.write(("\n" if tty and not quiet else "") + f"fgloc live: {msg}\n")
        sys.stderr.flush()

    viewer: list[Any] = []

    def make_session(occ_map: Any, mount: Any) -> Session:
        session = build_session(occ_map, mount, backend=backend, frontend=frontend, initial_pose=init, config=cfg)
        # as `fgloc live`: the fixes and the back-end's trajectories are kept whole for --out-smoothed only,
        # else their last minute (memory bounded over days; /amcl_pose needs only the newest online poses)
        if out_smoothed is None:
            session.loc.keep_history(LIVE_HISTORY_S)
        return session

    def make_live(session: Session) -> LiveSession:
        # the live trajectory whole for -o, else its last minute: nothing here reads it without -o
        live = LiveSession(session, None, None, config=cfg, record=record, publish=publish or None,
                           event_sink=event, record_force=force,
                           trajectory_window_s=None if out is not None else LIVE_HISTORY_S)
        if view is not None:
            from fgloc.view import ViewHook

            try:
                viewer.append(ViewHook(session.loc, None, view=view, record_to=live.recorder, announce=event))
            except BaseException:
                live.close()
                raise
            session.add_sink(viewer[0])
        return live

    c = cfg.ros2
    if transport is None:
        transport = CycloneTransport(c.domain_id, c.interface, node_name=c.node_name, namespace=c.node_namespace,
                                     distro=c.ros_distro)
    try:
        node = Ros2Live(cfg, transport, make_session, make_live, occ_map=occ, event=event, on_started=on_started)
    except BaseException:
        transport.close()
        raise
    stop = threading.Event() if stop is None else stop

    def hurry() -> None:  # a second Ctrl-C: close without the final smoothing (fgloc.io.stop)
        if node.session is not None:
            node.session.hurry()

    event(f"joined DDS domain {transport.domain_id}" + (f" on {cfg.ros2.interface}" if cfg.ros2.interface else "")
          + f"; subscribed to {', '.join(i.topic for i in node.inputs)}")
    last = [0.0]

    def shown() -> bool:
        now = time.monotonic()
        if now - last[0] >= 0.25:
            last[0] = now
            status(node.status_line())
        return False

    summary = None
    with stopping.cooperative(on_stop=stop.set, on_hurry=hurry):
        try:
            transport.start()
            node.run(stop, duration=duration, until=shown)
        finally:
            if viewer and node.runner is not None:
                node.runner.drain()
                viewer[0].close()
            summary = node.close()
            if tty and not quiet:
                sys.stderr.write("\n")
    report: dict[str, Any] = {"ros2": node.report()}
    if summary is not None:
        session = node.session
        session.write_trajectories(tums)
        report.update({"duration_s": round(summary.duration_s, 2), "poses": summary.n_poses,
                       "latency_ms": {"p50": summary.latency_p50_ms, "p99": summary.latency_p99_ms},
                       "health": summary.health, "counters": summary.counters,
                       "record": str(record) if record else None, "record_error": session.record_error,
                       "hurried": session.hurried})
    else:
        report["waiting_for"] = node.startup.waiting_for
    if viewer:
        report["view"] = viewer[0].stats()
    return report
