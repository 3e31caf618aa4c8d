"""``fgloc live``: fuse the STM32 serial stream and a SICK laser live (see fgloc.live)."""

from __future__ import annotations

import sys
from pathlib import Path

import typer

from fgloc.app.units import pose_value

ROS2_SWITCH_INTERVAL_S = 0.0005  # fgloc live --ros2: the GIL's switch interval (Python's default: 5 ms)
EXIT_THREAD_DIED = 1  # a sensor thread died, or a sensor asked for never delivered: the summary is still printed


def check_serial_path(serial: str | None) -> None:
    """A serial device path (not a pyserial URL) that does not exist or cannot be opened for reading
    and writing is a one-line :class:`~fgloc.errors.ConfigError` before anything starts (a port that
    existed and goes away later is reconnected to)."""
    import os

    from fgloc.errors import ConfigError

    if not serial or "://" in serial:
        return
    if not os.path.exists(serial):
        raise ConfigError(f"{serial}: no such serial port (is the adapter plugged in? see ls /dev/ttyUSB* "
                          "/dev/ttyACM*; a pyserial URL such as socket://HOST:PORT works too)")
    if not os.access(serial, os.R_OK | os.W_OK):
        raise ConfigError(f"{serial}: permission denied (add your user to the port's group, e.g. sudo usermod "
                          "-aG dialout $USER, then log in again)")


def silent_sensors(report: dict, serial: str | None, laser: str | None) -> list[str]:
    """The sensors asked for that delivered nothing the whole session (one phrase each)."""
    c = report.get("counters") or {}
    out = []
    if serial and not (c.get("serial") or {}).get("frames_ok"):
        out.append(f"serial {serial}: no frame received")
    if laser and not (c.get("laser") or {}).get("scans"):
        connected = (c.get("laser") or {}).get("connects")
        out.append(f"laser {laser}: no scan received" + ("" if connected else " (never connected)"))
    return out


def summary_line(report: dict) -> str:
    """The session in one line (``--json`` prints the whole report)."""
    c = report.get("counters") or {}
    ser, las = c.get("serial"), c.get("laser")
    parts = [f"{report.get('duration_s', 0):.1f} s, {report.get('poses', 0)} poses, "
             f"{c.get('scans_fused', 0)} scans fused, {c.get('fixes', 0)} fixes"]
    if ser is not None:
        parts.append(f"serial {ser.get('frames_ok', 0)} frames (crc errors {ser.get('crc_errors', 0)}, dropped "
                     f"{ser.get('dropped', 0)}, disconnects {ser.get('disconnects', 0)})")
    if las is not None:
        parts.append(f"laser {las.get('scans', 0)} scans (malformed {las.get('malformed', 0)}, connects "
                     f"{las.get('connects', 0)})")
    if c.get("queue_dropped"):  # a host too slow for its input: the oldest messages went
        by_kind = ", ".join(f"{k} {v}" for k, v in sorted((c.get("queue_dropped_by_kind") or {}).items()))
        parts.append(f"input queue full: {c['queue_dropped']} oldest messages dropped ({by_kind})")
    return "fgloc live: " + "; ".join(parts)


def _recording_and_hurry(record_error: str | None, hurried: bool, out_smoothed: Path | None) -> None:
    """Exit 2 with the recording's disk error (the other outputs are written), else 130 when a
    second signal hurried the shutdown (what was complete is written)."""
    if record_error:
        from fgloc.io.outputs import OutputError

        raise OutputError(record_error)
    if hurried:
        from fgloc.io import stop

        stop.note("the final smoothing was skipped" + (" (--out-smoothed not written)" if out_smoothed else ""))
        raise SystemExit(stop.EXIT_INTERRUPTED)


def register(app: typer.Typer) -> None:
    @app.command("live")
    def live(
        serial: str = typer.Option(None, "--serial", help="pyserial URL: /dev/ttyUSB0, socket://H:P, loop://, rfc2217://"),
        laser: str = typer.Option(None, "--laser", help="SICK scanner HOST:PORT (CoLa-A, usually port 2111)"),
        map_yaml: Path = typer.Option(None, "--map", help="map_server MAP.yaml (without: odometry + compass only)"),
        backend: str = typer.Option("smoother", "--backend", help="smoother | ekf"),
        frontend: str = typer.Option("native", "--frontend", help="scan matcher: native | amcl | kiss"),
        initial_pose: tuple[float, float, float] | None = typer.Option(
            None, "--initial-pose", parser=pose_value,
            help="X Y YAW in the map: m, m and rad, or the yaw with its unit (90deg); "
            "without it: global localization"
        ),
        record: Path = typer.Option(None, "--record", help="record every received message to this MCAP"),
        publish: list[str] = typer.Option(None, "--publish", help="udp://127.0.0.1:PORT (JSON lines; repeatable)"),
        duration: float = typer.Option(None, "--duration", help="stop after S seconds (default: until Ctrl-C)"),
        config: Path = typer.Option(None, "--config", help="YAML overlaid on the defaults (`fgloc config show`; "
                                    "`fgloc config init` writes one)"),
        laser_mount: tuple[float, float, float] | None = typer.Option(
            None, "--laser-mount", parser=pose_value,
            help="base_link->laser X Y YAW (m, m and rad, or the yaw with its unit: 180deg) "
            "[default: the config's laser.mount]"
        ),
        out: Path = typer.Option(None, "-o", "--output", help="write the live fused trajectory (online poses) as TUM"),
        out_old: Path = typer.Option(None, "--out", hidden=True, help="the old name of --output"),
        as_json: bool = typer.Option(False, "--json", help="print the whole report (every counter) as JSON at the "
                                     "end, not one summary line"),
        out_smoothed: Path = typer.Option(None, "--out-smoothed",
                                          help="write the localizer's smoothed trajectory at exit as TUM"),
        quiet: bool = typer.Option(False, "--quiet", "-q", help="no status line"),
        force: bool = typer.Option(False, "--force", help="overwrite existing --record / --output / --out-smoothed "
                                   "files (never replaced otherwise: a previous recording stays)"),
        view: str = typer.Option(None, "--view", help="[HOST:]PORT: serve a Foxglove WebSocket view "
                                 "(127.0.0.1 unless a host is given; layout: `fgloc view layout`)"),
        ros2: bool = typer.Option(False, "--ros2", help="a ROS 2 peer over DDS, in place of nav2's AMCL: the "
                                  "robot's /scan, /odom, /imu, /tf, /map in; /amcl_pose, map -> odom on /tf, "
                                  "/fgloc/status out (config section ros2)"),
        domain: int = typer.Option(None, "--domain", help="--ros2: DDS domain (default $ROS_DOMAIN_ID, else 0)"),
        interface: str = typer.Option(None, "--interface", help="--ros2: network interface (name or address) "
                                      "DDS uses"),
        scan_topic: str = typer.Option(None, "--scan-topic", help="--ros2: LaserScan topic (ros2.scan_topic)"),
    ) -> None:
        """Localize live: STM32 wheel counts + compass over serial, SICK laser over TCP; or (--ros2) a ROS 2
        robot's topics over DDS.  Exit 0 done, 1 a sensor thread died or a sensor asked for delivered
        nothing, 2 a usage error (a missing serial port)."""
        from fgloc.app.units import pose_arg
        from fgloc.live.app import LiveRequest, run_live
        from fgloc.live.publish import dumps

        if config is not None:  # a ported nav2 config's AMCL settings do nothing with the native front-end
            from fgloc.app.run import unused_frontend_settings
            from fgloc.config import load_config

            for w in unused_frontend_settings(load_config(config), frontend):
                sys.stderr.write(f"fgloc live: warning: {w}\n")
        if ros2:
            from fgloc.errors import ConfigError
            from fgloc.ros2.live import live_ros2
            from fgloc.ros2.live import summary_line as ros2_summary

            if serial or laser:
                raise ConfigError("fgloc live: --ros2 takes the robot's sensors from DDS; leave out --serial / --laser")
            import gc

            # the fusion loop and the DDS receive thread hand the GIL over every 0.5 ms, not 5 ms: a scan's
            # pose waits less behind the other thread (this process is the command's alone)
            sys.setswitchinterval(ROS2_SWITCH_INTERVAL_S)
            # once started, what is alive (the imports, the map, the localizer) is frozen: the collector's
            # full passes skip it (no pause while waiting: the wait for a map has no bound)
            rep = live_ros2(map_yaml=map_yaml, backend=backend, frontend=frontend,
                            initial_pose=pose_arg(initial_pose), record=record, publish=publish, duration=duration,
                            config=config, out=out or out_old, out_smoothed=out_smoothed, quiet=quiet, view=view,
                            domain=domain, interface=interface, scan_topic=scan_topic, force=force,
                            on_started=gc.freeze)
            print(dumps(rep, indent=1) if as_json else ros2_summary(rep))
            _recording_and_hurry(rep.get("record_error"), bool(rep.get("hurried")), out_smoothed)
            return

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

        check_serial_path(serial)
        req = LiveRequest(serial=serial, laser=laser, map_yaml=map_yaml, backend=backend, frontend=frontend,
                          initial_pose=pose_arg(initial_pose), config=config,
                          laser_mount=pose_arg(laser_mount, "--laser-mount"),
                          record=record, publish=publish or [], duration_s=duration, out=out or out_old,
                          out_smoothed=out_smoothed, view=view, force=force)
        r = run_live(req, status_sink=status, event_sink=event, on_stopped=stopped)
        if as_json:
            print(dumps(r.report, indent=1))  # standard JSON: unknown numbers (NaN) are null
        else:
            print(summary_line(r.report))
        if r.failed:
            sys.stderr.write(f"fgloc live: error: {'; '.join(r.failed)}; stopped\n")
            raise SystemExit(EXIT_THREAD_DIED)
        silent = silent_sensors(r.report, serial, laser)
        if silent:
            sys.stderr.write(f"fgloc live: error: {'; '.join(silent)} in {r.report.get('duration_s', 0):.1f} s\n")
            raise SystemExit(EXIT_THREAD_DIED)
        _recording_and_hurry(r.record_error, r.hurried, out_smoothed)
