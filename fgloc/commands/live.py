"""``fgloc live``: fuse the STM32 serial stream and a SICK laser live (see fgloc.live)."""

from __future__ import annotations

import signal
import sys
import threading
from pathlib import Path

import typer

EXIT_THREAD_DIED = 1  # a sensor thread died: the session stopped (the summary is still printed)


def register(app: typer.Typer) -> None:
    @app.command("live")
    def live(
        serial: str = typer.Option(None, "--serial", help="pyserial URL: /dev/ttyUSB0, socket://H:P, loop://, rfc2217://"),
        laser: str = typer.Option(None, "--laser", help="SICK scanner HOST:PORT (CoLa-A, usually port 2111)"),
        map_yaml: Path = typer.Option(None, "--map", help="map_server MAP.yaml (without: odometry + compass only)"),
        backend: str = typer.Option("smoother", "--backend", help="smoother | ekf"),
        frontend: str = typer.Option("native", "--frontend", help="scan matcher: native | amcl | kiss"),
        initial_pose: tuple[float, float, float] = typer.Option(
            (float("nan"), float("nan"), float("nan")), "--initial-pose", help="X Y YAW (m, m, rad) in the map"
        ),
        record: Path = typer.Option(None, "--record", help="record every received message to this MCAP"),
        publish: list[str] = typer.Option(None, "--publish", help="udp://127.0.0.1:PORT (JSON lines; repeatable)"),
        duration: float = typer.Option(None, "--duration", help="stop after S seconds (default: until Ctrl-C)"),
        config: Path = typer.Option(None, "--config", help="YAML overlaid on the defaults (`fgloc config show`; "
                                    "`fgloc config init` writes one)"),
        laser_mount: tuple[float, float, float] = typer.Option(
            (float("nan"), float("nan"), float("nan")), "--laser-mount", help="base_link->laser X Y YAW"
        ),
        out: Path = typer.Option(None, "--out", help="write the live fused trajectory (online poses) as TUM"),
        out_smoothed: Path = typer.Option(None, "--out-smoothed",
                                          help="write the localizer's smoothed trajectory at exit as TUM"),
        quiet: bool = typer.Option(False, "--quiet", help="no status line"),
        view: str = typer.Option(None, "--view", help="[HOST:]PORT: serve a Foxglove WebSocket view "
                                 "(127.0.0.1 unless a host is given; layout: `fgloc view layout`)"),
    ) -> None:
        """Localize live: STM32 wheel counts + compass over serial, SICK laser over TCP."""
        import math

        import numpy as np

        from fgloc.errors import ConfigError
        from fgloc.live.app import LiveSession, load_config
        from fgloc.live.publish import dumps
        from fgloc.maps import load_map

        if not serial and not laser:
            raise ConfigError("fgloc live: give --serial URL and/or --laser HOST:PORT")
        if backend not in ("smoother", "ekf"):
            raise ConfigError(f"--backend {backend}: expected smoother or ekf")
        cfg = load_config(config)
        if not any(math.isnan(v) for v in laser_mount):
            from fgloc.config import parse_config

            cfg = parse_config({"laser": {"mount": list(laser_mount)}}, source="--laser-mount", base=cfg)
        occ = load_map(map_yaml) if map_yaml is not None else None
        init = None if any(math.isnan(v) for v in initial_pose) else np.array(initial_pose, dtype=float)

        from fgloc.localization import Localizer
        from fgloc.types import StaticTransform

        mount = StaticTransform("base_link", "laser", np.asarray(cfg.laser.mount, dtype=float))
        loc = Localizer(occ, mount, backend=backend, frontend=frontend, initial_pose=init, config=cfg)
        tty = sys.stderr.isatty()
        last_len = [0]

        def status(line: str) -> None:
            if quiet:
                return
            if tty:
                pad = max(0, last_len[0] - len(line))
                sys.stderr.write("\r" + line + " " * pad)
                last_len[0] = len(line)
            else:
                status.n = getattr(status, "n", 0) + 1  # type: ignore[attr-defined]
                if status.n % 20 == 1:  # type: ignore[attr-defined]  # every 5 s when not a terminal
                    sys.stderr.write(line + "\n")
            sys.stderr.flush()

        def event(msg: str) -> None:
            sys.stderr.write(("\n" if tty and not quiet else "") + f"fgloc live: {msg}\n")
            sys.stderr.flush()

        session = LiveSession(loc, serial, laser, config=cfg, record=record, publish=publish or None,
                              status_sink=status, event_sink=event)
        viewer = None
        if view is not None:  # the Foxglove view (fgloc.view), also recorded into --record
            from fgloc.view import ViewHook

            try:
                viewer = ViewHook(loc, None, view=view, record_to=session.recorder, announce=event)
            except BaseException:
                session.close()
                raise
            session.runner.session.add_sink(viewer)
        stop = session.runner.stop_event
        hits = [0]

        def on_signal(signum, frame) -> None:  # noqa: ANN001
            hits[0] += 1
            stop.set()
            if hits[0] > 1:
                raise KeyboardInterrupt

        old = {}
        if threading.current_thread() is threading.main_thread():
            for s in (signal.SIGINT, signal.SIGTERM):
                old[s] = signal.signal(s, on_signal)
        def dead_workers() -> list[str]:
            """Sensor threads that died (a bug: bad input is counted, never fatal)."""
            return [f"{name} thread died ({w.failure})" for name, w in (("serial", session.serial),
                                                                         ("laser", session.laser))
                    if w is not None and w.failure]

        try:
            session.start()
            session.runner.run(duration=duration, until=lambda: bool(dead_workers()))
        finally:
            if viewer is not None:
                session.runner.drain()  # the backlog reaches the view (and its channels the recording)
                viewer.close()
            summary = session.close()
            for s, h in old.items():
                signal.signal(s, h)
            if tty and not quiet:
                sys.stderr.write("\n")
        traj = session.live_trajectory()
        if out is not None and len(traj):
            from fgloc.io.tum import write_tum

            write_tum(out, traj)
        if out_smoothed is not None and session.smoothed is not None and len(session.smoothed):
            from fgloc.io.tum import write_tum

            write_tum(out_smoothed, session.smoothed)
        failed = dead_workers()
        report = {
            "duration_s": round(summary.duration_s, 2),
            "poses": summary.n_poses,
            "latency_ms": {"p50": summary.latency_p50_ms, "p99": summary.latency_p99_ms},
            "health": summary.health,
            "counters": summary.counters,
            "record": str(record) if record else None,
            "failed_threads": failed,
        }
        if viewer is not None:
            report["view"] = viewer.stats()
        print(dumps(report, indent=1))  # standard JSON: unknown numbers (NaN) are null
        if failed:
            sys.stderr.write(f"fgloc live: error: {'; '.join(failed)}; stopped\n")
            raise SystemExit(EXIT_THREAD_DIED)
