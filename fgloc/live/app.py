"""Assemble a live session: config -> serial link + laser client + localization session + outputs.

:func:`run_live` is ``fgloc live`` as a library function (a :class:`LiveRequest` in, a
:class:`LiveReport` out): it builds the localization session with
:func:`fgloc.localization.build_session`, wraps it in a :class:`LiveSession` (and the
Foxglove view), runs until the duration, a signal or a dead sensor thread, and writes the
trajectories asked for.  :class:`LiveSession` is what the end-to-end tests drive
(``start()``, ``runner.run(...)``, ``close()``).  ``close()`` stops the sensor threads,
fuses what is still queued, closes the recording (a valid MCAP) and returns the summary.
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fgloc.errors import ConfigError
from fgloc.live.serial_link import FrameConverter, SerialLink
from fgloc.types import StaticTransform, Trajectory

if TYPE_CHECKING:
    from fgloc.config import FglocConfig
    from fgloc.io.outputs import OutputFile
    from fgloc.live.sick import SickClient
    from fgloc.localization import Session

EVENTS_KEPT = 1_000  # a live session's event lines kept (the newest)
#: kept this far back: without -o the live trajectory, without --out-smoothed the localizer's fixes and trajectories
#: (``fgloc live`` and ``fgloc live --ros2``: what an output writes is kept whole; nothing else reads further back)
LIVE_HISTORY_S = 60.0


def parse_host_port(s: str) -> tuple[str, int]:
    host, sep, port = s.rpartition(":")
    if not sep or not host or not port.isdigit():
        raise ConfigError(f"--laser {s}: expected HOST:PORT (e.g. 192.168.0.1:2111)")
    return host, int(port)


@dataclass
class LiveSummary:
    duration_s: float
    counters: dict[str, Any]
    health: dict[str, str]
    latency_p50_ms: float
    latency_p99_ms: float
    n_poses: int
    events: list[str]


class LiveSession:
    """Serial + laser + a localization session (:func:`fgloc.localization.build_session`) +
    recorder + publisher, wired through a :class:`LiveRunner`."""

    def __init__(self, session: Session, serial_url: str | None, laser: str | None, *args: Any, **kwargs: Any) -> None:
        """See :meth:`_setup` (the arguments); a set-up that fails removes the recording it began."""
        self.recording: Any = None
        try:
            self._setup(session, serial_url, laser, *args, **kwargs)
        except BaseException:
            if self.recording is not None:
                self.recorder.close()
                self.recording.discard()
            raise

    def _setup(
        self,
        session: Session,
        serial_url: str | None,
        laser: str | None,
        config: FglocConfig | None = None,
        record: str | Path | None = None,
        publish: list[str] | None = None,
        status_sink: Any = None,
        event_sink: Any = None,
        serial_port: Any = None,
        record_force: bool = False,
        trajectory_window_s: float | None = None,
    ) -> None:
        # here, not at the top: every command's config (fgloc.config's live sections) imports this module
        from fgloc.config import parse_config
        from fgloc.live.publish import UdpPublisher
        from fgloc.live.runner import LiveRunner
        from fgloc.live.sick import SickClient

        cfg = parse_config(config)
        self.cfg = cfg
        robot = cfg.robot
        sc, lc = cfg.serial, cfg.laser
        mount = np.asarray(lc.mount, dtype=float)
        self.laser_mount = StaticTransform("base_link", "laser", mount)
        self.recorder: Any = None
        self.record_path = Path(record) if record else None
        self.record_error: str | None = None  # the recording's disk error, one line
        self.hurried = False  # a second signal: close without the final smoothing
        self.events: deque[str] = deque(maxlen=EVENTS_KEPT)  # the newest (a day of flapping sensors is bounded)
        self._event_sink = event_sink
        if record:
            self._open_recording(Path(record), record_force)
        self.publisher = UdpPublisher(publish) if publish else None

        def ev(msg: str) -> None:
            self.events.append(f"{time.strftime('%H:%M:%S')} {msg}")
            self.runner.push("event", msg, time.time())  # into the recording, from the fusion thread
            if event_sink is not None:
                event_sink(msg)

        self.runner = LiveRunner(
            session, recorder=self.recorder, publisher=self.publisher, status_sink=status_sink,
            event_sink=ev, laser_mount=self.laser_mount,
            silence_s=cfg.health.silence_s, trajectory_window_s=trajectory_window_s,
            queue_max_msgs=cfg.health.queue_max_msgs,
        )
        ts, cs, gs = sc.twist_std, sc.compass_std_deg, sc.gyro_std_dps
        conv = FrameConverter(
            robot,
            compass_clockwise=sc.compass_clockwise,
            twist_var=None if ts is None else (ts[0] ** 2, ts[1] ** 2, ts[2] ** 2),
            yaw_var=float("nan") if cs is None else math.radians(cs) ** 2,
            yaw_rate_var=float("nan") if gs is None else math.radians(gs) ** 2,
            align_clock=sc.align_clock,
        )
        self.serial: SerialLink | None = None
        if serial_url or serial_port is not None:
            self.serial = SerialLink(serial_url, conv, self.runner.push, baudrate=sc.baudrate,
                                     port=serial_port, on_event=ev)
            self.runner.sources["serial"] = self.serial.counters
        self.laser: SickClient | None = None
        if laser:
            host, port = parse_host_port(laser)
            self.laser = SickClient(
                host, port, on_scan=lambda scan, arrival: self.runner.push("scan", scan, arrival),
                range_min=lc.range_min_m, range_max=lc.range_max_m, angle_offset_deg=lc.angle_offset_deg,
                time_increment_from=lc.time_increment_from, align_clock=lc.align_clock,
                stall_timeout_s=lc.stall_timeout_s, on_event=ev, layer_field=lc.layer_field,
                start_measurement=lc.start_measurement,
            )
            self.runner.sources["laser"] = self.laser.counters
        self._t0 = time.monotonic()
        self.closed = False
        self.smoothed: Trajectory | None = None  # Localizer.finish() at close (fixed-lag / batch result)

    def _open_recording(self, path: Path, force: bool) -> None:
        """``--record``: written as ``PATH.partial`` (renamed at a clean close), never over an existing
        file without ``force``; a disk error stops the recording with one event line and keeps
        what was written (:class:`fgloc.io.outputs.OutputFile`, :class:`~fgloc.io.outputs.GuardedFile`)."""
        from fgloc.io.mcap_writer import LIBRARY, LogWriter
        from fgloc.io.outputs import GuardedFile, OutputError, OutputFile, problem

        recording = OutputFile(path, command="live", force=force, precious=True, option="--record",
                               what="recording")
        recording.__enter__()

        def failed(e: OSError) -> None:
            self.record_error = f"{path}: {problem(e)}"
            msg = f"recording stopped: {path}: {problem(e)} (localization goes on)"
            self.events.append(f"{time.strftime('%H:%M:%S')} {msg}")
            if self._event_sink is not None:
                self._event_sink(msg)

        try:
            self._record_file = GuardedFile(open(recording.path, "wb"), on_error=failed)  # noqa: SIM115
            self.recorder = LogWriter(path, file=self._record_file, library=f"{LIBRARY} live")
        except OSError as e:
            recording.discard(e)
            raise OutputError(f"{path}: cannot write the recording ({problem(e)})") from None
        self.recording = recording

    def _close_recording(self) -> None:
        """Finish the recording and publish it; after a disk error keep ``PATH.partial`` and say so."""
        from fgloc.io.outputs import OutputError

        try:
            self.recorder.close()
        except OSError as e:  # the guard holds write errors; this is a last resort
            self._record_file.error = self._record_file.error or e
        if self._record_file.error is None:
            try:
                self.recording.publish()
                return
            except OutputError as e:
                self.record_error = str(e)
                return
        self.recording.discard(self._record_file.error)
        if self.recording.kept is not None:
            self.record_error = f"{self.record_error}; what was recorded until then is in {self.recording.kept}"

    def hurry(self) -> None:
        """Close without the final smoothing (a second Ctrl-C): the recording and the live
        trajectory are still finished."""
        self.hurried = True

    def start(self) -> None:
        self._t0 = time.monotonic()
        if self.serial is not None:
            self.serial.start()
        if self.laser is not None:
            self.laser.start()

    def live_trajectory(self) -> Trajectory:
        return self.runner.live_trajectory()

    def write_trajectories(self, tums: dict[str, OutputFile]) -> None:
        """After :meth:`close`: the live trajectory into ``tums["-o"]``, the smoothed one into
        ``tums["--out-smoothed"]`` (each when asked for and not empty), as TUM."""
        from fgloc.io.tum import write_tum

        traj = self.live_trajectory()
        if "-o" in tums and len(traj):
            with tums["-o"] as o:
                write_tum(o.path, traj)
        if "--out-smoothed" in tums and self.smoothed is not None and len(self.smoothed):
            with tums["--out-smoothed"] as o:
                write_tum(o.path, self.smoothed)

    def close(self) -> LiveSummary:
        """Stop sensors, fuse the backlog, close the recording; idempotent."""
        if not self.closed:
            self.closed = True
            if self.laser is not None:
                self.laser.stop()
            if self.serial is not None:
                self.serial.stop()
            self.runner.drain()
            if self.hurried:
                self.events.append("final smoothing skipped (a second signal)")
            else:
                try:
                    self.smoothed = self.runner.loc.finish()
                except Exception as e:  # noqa: BLE001 - the live trajectory is already safe
                    self.events.append(f"smoothing at shutdown failed: {type(e).__name__}: {e}")
            if self.recorder is not None:
                self._close_recording()
            if self.publisher is not None:
                self.publisher.close()
        p50, p99 = self.runner.latency_percentiles()
        return LiveSummary(
            duration_s=time.monotonic() - self._t0,
            counters=self.runner.all_counters(),
            health=self.runner.health_states(),
            latency_p50_ms=p50,
            latency_p99_ms=p99,
            n_poses=self.runner.trajectory.total,
            events=list(self.events),
        )


@dataclass
class LiveRequest:
    """What ``fgloc live`` runs (its arguments)."""

    serial: str | None = None  # pyserial URL of the STM32 stream
    laser: str | None = None  # SICK scanner HOST:PORT
    map_yaml: Path | None = None  # map_server YAML (None: odometry + compass only)
    backend: str = "smoother"
    frontend: str = "native"
    initial_pose: tuple[float, float, float] | None = None  # x_m, y_m, yaw_rad in the map
    config: Path | None = None  # YAML overlaid on the defaults
    laser_mount: tuple[float, float, float] | None = None  # base_link -> laser x_m, y_m, yaw_rad (over laser.mount)
    record: Path | None = None  # every received message into this MCAP
    publish: list[str] = field(default_factory=list)  # udp://HOST:PORT
    duration_s: float | None = None  # stop after this long (None: until a signal)
    out: Path | None = None  # the live fused trajectory (online poses) as TUM
    out_smoothed: Path | None = None  # the localizer's smoothed trajectory at exit as TUM
    view: str | None = None  # [HOST:]PORT: serve a Foxglove WebSocket view
    force: bool = False  # replace existing record / out / out_smoothed files (never otherwise)


@dataclass
class LiveReport:
    """What :func:`run_live` did: ``report`` is what ``fgloc live`` prints (JSON), ``failed`` the
    sensor threads that died (a bug: bad input is counted, never fatal)."""

    report: dict[str, Any]
    failed: list[str]
    record_error: str | None = None  # the recording's disk error, one line (what was kept where)
    hurried: bool = False  # a second signal: closed without the final smoothing


def live_session(req: LiveRequest, status_sink: Callable[[str], None] | None = None,
                 event_sink: Callable[[str], None] | None = None) -> LiveSession:
    """The config, the map and the localization session of ``req``, in a :class:`LiveSession`
    reading its serial stream and laser (not started)."""
    import numpy as np

    from fgloc.localization import build_session
    from fgloc.maps import load_map

    if not req.serial and not req.laser:
        raise ConfigError("fgloc live: give --serial URL and/or --laser HOST:PORT")
    from fgloc.backends import Capability, check_backend

    backend = check_backend(req.backend, Capability.LIVE)
    from fgloc.config import load_config

    cfg = load_config(req.config)
    if req.laser_mount is not None:
        from fgloc.config import parse_config

        cfg = parse_config({"laser": {"mount": list(req.laser_mount)}}, source="--laser-mount", base=cfg)
    occ = load_map(req.map_yaml) if req.map_yaml is not None else None
    init = None if req.initial_pose is None else np.array(req.initial_pose, dtype=float)
    mount = StaticTransform("base_link", "laser", np.asarray(cfg.laser.mount, dtype=float))
    session = build_session(occ, mount, backend=backend, frontend=req.frontend, initial_pose=init, config=cfg)
    # the live trajectory is kept whole for -o only, the fixes and the back-end's trajectories for
    # --out-smoothed only; else their last minute (memory bounded over days)
    if req.out_smoothed is None:
        session.loc.keep_history(LIVE_HISTORY_S)
    return LiveSession(session, req.serial, req.laser, config=cfg, record=req.record, publish=req.publish or None,
                       status_sink=status_sink, event_sink=event_sink, record_force=req.force,
                       trajectory_window_s=None if req.out is not None else LIVE_HISTORY_S)


def trajectory_outputs(out: Path | None, out_smoothed: Path | None, force: bool) -> dict[str, OutputFile]:
    """``fgloc live``'s ``-o`` / ``--out-smoothed`` files (those given), checked now: before the
    session starts, never over an existing file without ``force`` (:mod:`fgloc.io.outputs`)."""
    from fgloc.io.outputs import OutputFile

    tums = {name: OutputFile(p, command="live", force=force, option=name, what="trajectory")
            for name, p in (("-o", out), ("--out-smoothed", out_smoothed)) if p is not None}
    for o in tums.values():
        o.check()
    return tums


def run_live(req: LiveRequest, status_sink: Callable[[str], None] | None = None,
             event_sink: Callable[[str], None] | None = None,
             on_stopped: Callable[[], None] | None = None) -> LiveReport:
    """``fgloc live``: build the session (:func:`live_session`), serve the view, run until
    ``req.duration_s``, SIGINT / SIGTERM or a dead sensor thread, close and write ``req.out`` /
    ``req.out_smoothed``.  A second signal skips the final smoothing; the recording and the live
    trajectory are finished all the same (:mod:`fgloc.io.stop`; a third exits at once).  The
    output files are checked before the session starts (never over an existing file without
    ``req.force``).  ``status_sink(line)``: the status line; ``event_sink(line)``: events (sensor
    silent / back, the view's address, a recording stopped by its disk); ``on_stopped()``: called
    once the session is closed (the CLI ends its status line)."""
    from fgloc.io import stop as stopping

    tums = trajectory_outputs(req.out, req.out_smoothed, req.force)
    session = live_session(req, status_sink, event_sink)
    viewer = None
    if req.view is not None:  # the Foxglove view (fgloc.view), also recorded into --record
        from fgloc.view import ViewHook

        try:
            viewer = ViewHook(session.runner.loc, None, view=req.view, record_to=session.recorder,
                              announce=event_sink)
        except BaseException:
            session.close()
            raise
        session.runner.session.add_sink(viewer)
    stop = session.runner.stop_event

    def dead_workers() -> list[str]:
        """Sensor threads that died (a bug: bad input is counted, never fatal)."""
        return [f"{name} thread died ({w.failure})" for name, w in (("serial", session.serial),
                                                                     ("laser", session.laser))
                if w is not None and w.failure]

    # SIGINT / SIGTERM: the first stops the session cleanly; a second hurries the shutdown
    with stopping.cooperative(on_stop=stop.set, on_hurry=session.hurry):
        try:
            session.start()
            session.runner.run(duration=req.duration_s, until=lambda: bool(dead_workers()))
        finally:
            if viewer is not None:
                session.runner.drain()  # the backlog reaches the view (and its channels the recording)
                viewer.close()
            summary = session.close()
            if on_stopped is not None:
                on_stopped()
        session.write_trajectories(tums)
    failed = dead_workers()
    report = {
        "duration_s": round(summary.duration_s, 2),
        "poses": summary.n_poses,
        "latency_ms": {"p50": summary.latency_p50_ms, "p99": summary.latency_p99_ms},
        "health": summary.health,
        "counters": summary.counters,
        "record": str(req.record) if req.record else None,
        "record_error": session.record_error,
        "failed_threads": failed,
    }
    if viewer is not None:
        report["view"] = viewer.stats()
    return LiveReport(report, failed, session.record_error, session.hurried)
