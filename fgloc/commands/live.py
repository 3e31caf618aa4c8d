"""``fgloc live``: fuse the STM32 serial stream and a SICK laser live (see fgloc.live)."""

from __future__ import annotations

import sys
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

        from fgloc.live.app import LiveRequest, run_live
        from fgloc.live.publish import dumps

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

        def stopped() -> None:
            if tty and not quiet:
                sys.stderr.write("\n")

        req = LiveRequest(serial=serial, laser=laser, map_yaml=map_yaml, backend=backend, frontend=frontend,
                          initial_pose=None if any(math.isnan(v) for v in initial_pose) else initial_pose,
                          config=config,
                          laser_mount=None if any(math.isnan(v) for v in laser_mount) else laser_mount,
                          record=record, publish=publish or [], duration_s=duration, out=out,
                          out_smoothed=out_smoothed, view=view)
        r = run_live(req, status_sink=status, event_sink=event, on_stopped=stopped)
        print(dumps(r.report, indent=1))  # standard JSON: unknown numbers (NaN) are null
        if r.failed:
            sys.stderr.write(f"fgloc live: error: {'; '.join(r.failed)}; stopped\n")
            raise SystemExit(EXIT_THREAD_DIED)
