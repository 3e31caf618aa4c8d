"""``fgloc run`` as a library function: :func:`run_log` takes a :class:`RunRequest`, returns a :class:`RunResult`.

It opens the log, checks the inputs the user named, builds a
:class:`~fgloc.localization.Localizer` and a :class:`~fgloc.localization.Session` with a
recorder sink (``run.mcap``: the inputs and ``/fused_pose``), feeds the log through it and
writes ``trajectory.tum`` (final), ``online.tum``, ``fixes.tum`` and ``config.yaml`` (the
effective config).  With ``/ground_truth`` in the log it also evaluates.  Nothing here
prints; the CLI (:mod:`fgloc.commands.run`) parses and prints, tests and tools call this.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fgloc.config import FglocConfig, load_config
from fgloc.errors import ConfigError, LogError

#: a file in an output folder that fgloc writes (others are not overwritten without --force)
OUTPUT_FILES = ("trajectory.tum", "online.tum", "fixes.tum", "run.mcap", "config.yaml")


@dataclass
class RunRequest:
    """What to localize and where to write it (the ``fgloc run`` arguments)."""

    log: Path
    outdir: Path
    map_yaml: Path | None = None
    backend: str = "smoother"
    frontend: str = "native"
    initial_pose: tuple[float, float, float] | None = None  # x_m, y_m, yaw_rad in the map
    config: FglocConfig | Path | None = None  # a config, a YAML file overlaid on the defaults, or the defaults
    scan_topic: str = "/scan"
    odom_topic: str = "/odom"
    imu_topic: str = "/imu"
    force: bool = False  # overwrite output files that fgloc did not write
    view: str | None = None  # [HOST:]PORT: serve a Foxglove WebSocket view while localizing (fgloc.view)
    realtime: float | None = None  # replay at this factor of real time (None: as fast as possible)
    view_channels: bool = True  # record the view's Foxglove channels into run.mcap (needs foxglove-sdk)


@dataclass
class RunResult:
    """What :func:`run_log` did (the CLI prints it; ``stats`` are the localizer's counters)."""

    mode: str  # "map" or "odom"
    frame: str
    backend: str
    frontend: str
    poses: int
    online_poses: int
    fixes: int
    stats: dict[str, Any]
    wall_s: float
    log_s: float
    outdir: Path
    written: list[str]
    truncated: str | None = None
    metrics: Any = None  # fgloc.eval.metrics.Metrics of the final trajectory vs /ground_truth
    metrics_online: Any = None
    eval_error: str | None = None
    config: FglocConfig = field(default_factory=FglocConfig)

    def as_dict(self) -> dict[str, Any]:
        from fgloc.io.yamlio import yaml_ready

        d = {k: getattr(self, k) for k in ("mode", "frame", "backend", "frontend", "poses", "online_poses",
                                          "fixes", "wall_s", "log_s", "truncated", "written", "eval_error")}
        d["stats"] = yaml_ready(self.stats)
        d["outdir"] = str(self.outdir)
        return d


def _check_inputs(reader: Any, log: Path, roles: tuple[tuple[str, str], ...]) -> None:
    """One-line errors for inputs that cannot be localized with: a role's topic of another type
    (it would be skipped and the run would 'succeed' empty) or topics stamped by different clocks."""
    types = reader.topic_types()
    for topic, want in roles:
        have = types.get(topic)
        if have is not None and reader.has(topic) and have != want:
            raise LogError(f"{log}: topic '{topic}' has type {have}, expected {want} (rename with --*-topic)")
    skew = reader.clock_skew([t for t, _ in roles])
    if skew is not None:
        raise LogError(f"{log}: {skew}")


def _initial_pose(values: Any) -> np.ndarray | None:
    if values is None:
        return None
    pose0 = np.asarray(values, dtype=float).reshape(-1)
    if pose0.shape != (3,) or not np.all(np.isfinite(pose0)):
        raise ConfigError("--initial-pose needs three finite numbers: X Y YAW (m, m, rad)")
    return pose0


def run_log(req: RunRequest, progress: Callable[[int | None], Any] | None = None,
            announce: Callable[[str], None] | None = None) -> RunResult:
    """Localize ``req.log`` and write the outputs into ``req.outdir`` (see the module docstring).

    ``progress(total)``: optional factory of a progress bar (an object with ``update(n)`` and
    context-manager methods, e.g. tqdm) over the messages read.  ``announce(line)``: where the
    Foxglove view says where it serves (``req.view``).
    """
    from fgloc.io.log import IMU, LASER_SCAN, ODOMETRY, LogReader, LogWriter, Topics
    from fgloc.io.tum import write_tum
    from fgloc.localization import Localizer, RecorderSink, Routes, Session
    from fgloc.localization.session import CallbackSink
    from fgloc.maps import OccupancyMap

    config = req.config if isinstance(req.config, FglocConfig) else load_config(req.config)
    log = Path(req.log)
    outdir = Path(req.outdir)
    scan_topic, odom_topic, imu_topic = req.scan_topic, req.odom_topic, req.imu_topic
    topics = Topics(scan=scan_topic, odom=odom_topic, imu=imu_topic)
    pose0 = _initial_pose(req.initial_pose)
    reader = LogReader(log, topics)
    summ = reader.summary()
    counts = {t: v["count"] for t, v in summ["topics"].items()}
    n_scan, n_odom, n_imu = counts.get(scan_topic, 0), counts.get(odom_topic, 0), counts.get(imu_topic, 0)
    if n_odom == 0 and n_imu == 0 and n_scan == 0:
        raise LogError(f"{log}: no {scan_topic}, {odom_topic} or {imu_topic} messages to localize with")
    _check_inputs(reader, log, ((scan_topic, LASER_SCAN), (odom_topic, ODOMETRY), (imu_topic, IMU)))
    occ_map = OccupancyMap.load(req.map_yaml) if req.map_yaml is not None else None
    mode = "map"
    if occ_map is None or n_scan == 0:
        occ_map = None
        mode = "odom"
    laser_mount = reader.laser_mount()
    loc = Localizer(occ_map, laser_mount, backend=req.backend, frontend=req.frontend, initial_pose=pose0,
                    config=config)
    outdir.mkdir(parents=True, exist_ok=True)
    want = {t for t in (scan_topic, odom_topic, imu_topic, topics.tf_static) if reader.has(t)}
    total = sum(counts.get(t, 0) for t in want)
    t_wall = time.perf_counter()
    from fgloc.view import ViewHook, check_rate, paced

    realtime = check_rate(req.realtime)
    with LogWriter(outdir / "run.mcap") as writer, \
            ViewHook(loc, topics, view=req.view, record_to=writer if req.view_channels else None,
                     announce=announce) as view:
        sinks: list[Any] = [RecorderSink(writer, topics.fused)]
        if view.active:
            sinks.append(view)  # the Foxglove view and its channels in run.mcap (fgloc.view)
        bar = progress(total) if progress is not None else None
        if bar is not None:
            sinks.append(CallbackSink(on_message=lambda topic, msg: bar.update(1)))
        session = Session(loc, Routes.default(topics), sinks)
        try:
            final = session.run(paced(reader.messages(want), realtime))
        finally:
            if bar is not None and hasattr(bar, "close"):
                bar.close()
    wall = time.perf_counter() - t_wall
    online = loc.online_trajectory()
    fixes = loc.fixes_trajectory()
    frame = "odom" if mode == "odom" else "map"
    written = []
    if len(final):
        written.append(write_tum(outdir / "trajectory.tum", final))
    if len(online):
        written.append(write_tum(outdir / "online.tum", online))
    if len(fixes):
        written.append(write_tum(outdir / "fixes.tum", fixes))
    from fgloc.config.schema import to_dict
    from fgloc.io.yamlio import write_yaml

    effective = to_dict(config)
    effective["run"] = {
        "log": str(log), "map": str(req.map_yaml) if req.map_yaml else None, "mode": mode, "backend": req.backend,
        "frontend": loc.frontend_name, "initial_pose": None if pose0 is None else pose0.tolist(),
        "topics": {"scan": scan_topic, "odom": odom_topic, "imu": imu_topic},
    }
    write_yaml(outdir / "config.yaml", effective)
    sim_s = float(final.duration) if len(final) else float(summ.get("duration") or 0.0)
    result = RunResult(
        mode=mode, frame=frame, backend=req.backend, frontend=loc.frontend_name, poses=len(final),
        online_poses=len(online), fixes=len(fixes), stats=loc.stats, wall_s=wall, log_s=sim_s,
        truncated=reader.truncated, outdir=outdir,
        written=[p.name for p in written] + ["run.mcap", "config.yaml"], config=config,
    )
    gt = reader.ground_truth() if reader.has(topics.ground_truth) else None
    if gt is not None and len(final) > 1:
        from fgloc.eval.metrics import evaluate

        try:
            result.metrics = evaluate(final, gt, align=(mode == "odom"))
            result.metrics_online = evaluate(online, gt, align=(mode == "odom")) if len(online) > 1 else None
        except LogError as e:
            result.eval_error = str(e)
    return result
