"""``fgloc run`` as a library function: :func:`run_log` takes a :class:`RunRequest`, returns a :class:`RunResult`.

It opens the log, checks the inputs the user named, builds a
:class:`~fgloc.localization.Localizer` and a :class:`~fgloc.localization.Session` with a
recorder sink, feeds the log through it and writes ``trajectory.tum`` (final),
``online.tum``, ``fixes.tum`` and ``config.yaml`` (the effective config).  With
``/ground_truth`` in the log it also evaluates.  Nothing here prints; the CLI
(:mod:`fgloc.commands.run`) parses and prints, tests and tools call this.

``run.mcap`` holds the inputs as the log stores them (a ROS 2 input's CDR bytes copied with
its own schema, no decode / encode round trip; other formats re-encoded), ``/fused_pose``
after each scan and the view's Foxglove channels (:mod:`fgloc.view.record`).  What the run
writes is placed at the log time of the input being processed, so it sits beside the inputs
on the input's recording clock.  ``RunResult.timings`` says where the time went (reading,
localizing, writing, the view's channels).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fgloc.errors import ConfigError, LogError

if TYPE_CHECKING:
    import numpy as np

    from fgloc.config import FglocConfig
    from fgloc.io.outputs import Outputs
    from fgloc.localization.stats import RunStats

#: the clock of ``RunResult.timings`` and ``wall_s`` (seconds); a benchmark sets ``time.thread_time``
#: to split the run's CPU time into its phases (``tools/bench_parts.py``)
PHASE_CLOCK: Callable[[], float] = time.perf_counter

#: a file in an output folder that fgloc writes (others are not overwritten without --force)
OUTPUT_FILES = ("trajectory.tum", "trajectory_status.csv", "online.tum", "fixes.tum", "run.mcap", "config.yaml")


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
    # topics: None = the default name, used when present; a name given = required (absent: error)
    scan_topic: str | None = None
    odom_topic: str | None = None
    imu_topic: str | None = None
    force: bool = False  # overwrite output files that fgloc did not write
    view: str | None = None  # [HOST:]PORT: serve a Foxglove WebSocket view while localizing (fgloc.view)
    realtime: float | None = None  # replay at this factor of real time (None: as fast as possible)
    view_channels: bool = True  # record the view's Foxglove channels into run.mcap (needs foxglove-sdk)
    covariance_period_s: float | None = None  # log time between fused-pose marginals (None: the session's default)
    # mounts the log lacks (sources.static_transforms entries; fgloc run --static-transform): over the config's
    static_transforms: list[dict] = field(default_factory=list)
    # the view's heavy channels in run.mcap at a bounded rate of log time (0: every scan; fgloc.view.record)
    view_scan_period_s: float = 0.2  # /fgloc/scan (the log's /scan is copied at its full rate)
    view_covariance_period_s: float = 0.5  # /fgloc/pose/covariance, drawn in base_link (sooner on a change)
    view_predicted_period_s: float = 0.1  # scans not matched (frontend_every): their pose, tf, fix at most this often


def _default_config() -> FglocConfig:
    from fgloc.config import FglocConfig

    return FglocConfig()


@dataclass
class RunResult:
    """What :func:`run_log` did (the CLI prints it; ``stats``: the localizer's counters)."""

    mode: str  # "map" or "odom"
    frame: str
    backend: str
    frontend: str
    poses: int
    online_poses: int
    fixes: int
    stats: RunStats
    wall_s: float
    log_s: float
    outdir: Path
    written: list[str]
    truncated: str | None = None
    metrics: Any = None  # fgloc.eval.metrics.Metrics of the final trajectory vs /ground_truth (every pose)
    metrics_online: Any = None
    # fgloc.eval.metrics.StatusSplit of each: the metrics over the poses the run vouches for (ok, degraded) and
    # the errors of those it does not (suspect, lost); what the summary prints
    by_status: Any = None
    by_status_online: Any = None
    eval_error: str | None = None
    config: FglocConfig = field(default_factory=_default_config)
    log: Path = field(default_factory=Path)
    lost_s: float = 0.0  # time the localizer spent lost (no pose, or no accepted fix for lost_after_s)
    ended_lost: bool = False
    damaged_chunks: int = 0  # damaged chunks of the input skipped (MCAP)
    damage: str | None = None  # one line on what could not be read (damaged chunks, undecodable messages)
    # seconds: setup (log, map, localizer), read (decoding the input), write (run.mcap: inputs and
    # /fused_pose; its chunks are compressed and written by a thread of their own, only the wait for
    # the last ones at the end is in it), view (the view's channels), localize (the rest of the loop),
    # finish (final smoothing), outputs (TUM, config, evaluation), total (the whole run_log call)
    timings: dict[str, float] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)  # what the result may be wrong about, one line each
    # the poses' statuses (fgloc.localization.monitor): counts of trajectory.tum's poses, the share suspect or
    # lost, the run-level verdicts (kind, message, unusable)
    status: dict[str, Any] = field(default_factory=dict)
    # the default layout's sources the log has no topic of their type for (a wheels-only log's IMU): name ->
    # one quiet line, said in place of the source's health line
    absent: dict[str, str] = field(default_factory=dict)

    @property
    def lost_share(self) -> float:
        return self.lost_s / self.log_s if self.log_s > 0 else (1.0 if self.ended_lost else 0.0)

    def failure(self) -> str | None:
        """One line when the result is not usable (fgloc run exits 3), else None: no pose at all, a
        verdict of the consistency monitor that makes it unusable (no scan matched the map, the map does
        not fit the log, the fusion diverged), lost at the end, lost longer than
        ``pipeline.max_lost_share`` of the run, or more than ``integrity.max_bad_share`` of the poses
        suspect or lost."""
        if self.poses == 0:
            return "no pose was estimated"
        for v in self.status.get("verdicts") or ():
            if v["unusable"]:
                return f"{v['message']}; pass --allow-lost to accept this"
        bad, limit = float(self.status.get("bad_share") or 0.0), self.config.integrity.max_bad_share
        if self.mode != "map":
            return self._bad_poses(bad, limit)
        share = self.config.pipeline.max_lost_share
        if self.ended_lost:
            return (f"the localizer was lost at the end of the run (lost {self.lost_s:.1f} s of "
                    f"{self.log_s:.1f} s); pass --allow-lost to accept this")
        if self.lost_share > share:
            return (f"the localizer was lost {self.lost_s:.1f} s of {self.log_s:.1f} s "
                    f"({100 * self.lost_share:.0f} % > pipeline.max_lost_share {100 * share:.0f} %); "
                    f"pass --allow-lost to accept this")
        return self._bad_poses(bad, limit)

    def _bad_poses(self, bad: float, limit: float) -> str | None:
        if bad <= limit:
            return None
        c = self.status.get("counts") or {}
        return (f"{100 * bad:.0f} % of the poses are suspect or lost ({c.get('suspect', 0)} suspect, "
                f"{c.get('lost', 0)} lost of {self.poses}; integrity.max_bad_share {100 * limit:.0f} %); "
                f"pass --allow-lost to accept this")

    def as_dict(self) -> dict[str, Any]:
        from fgloc.io.yamlio import yaml_ready

        d = {k: getattr(self, k) for k in ("mode", "frame", "backend", "frontend", "poses", "online_poses",
                                          "fixes", "wall_s", "log_s", "truncated", "written", "eval_error",
                                          "lost_s", "ended_lost", "damaged_chunks", "damage", "timings", "status")}
        d["stats"] = yaml_ready(self.stats.to_dict())
        d["outdir"] = str(self.outdir)
        return d


def topics_line(summary: dict[str, Any]) -> str:
    """The log's topics with their types and message counts, on one line."""
    items = [f"{t} ({v['type']}, {v['count']})" for t, v in sorted(summary["topics"].items())]
    return ", ".join(items) or "none"


def _check_inputs(reader: Any, log: Path, summary: dict[str, Any],
                  roles: tuple[tuple[str, str, str, bool], ...]) -> None:
    """One-line errors for inputs that cannot be localized with: a topic the user named that is
    absent, a role's topic of another type (it would be skipped and the run would 'succeed'
    empty), topics stamped by different clocks.  Each names the log's topics.  A multi-echo scan
    serves for a LaserScan (its first echoes)."""
    from fgloc.io.topics import LASER_SCAN, role_reads

    types = reader.topic_types()
    for option, topic, want, named in roles:
        have = types.get(topic)
        if named and not reader.has(topic):
            raise LogError(f"{log}: {option} {topic}: no such topic with messages in the log; its topics: "
                           f"{topics_line(summary)}")
        if have is not None and reader.has(topic) and have != want and not (want == LASER_SCAN
                                                                             and role_reads("scan", have)):
            raise LogError(f"{log}: topic '{topic}' has type {have}, expected {want} (rename with {option}); "
                           f"its topics: {topics_line(summary)}")
    skew = reader.clock_skew([t for _, t, _, _ in roles])
    if skew is not None:
        raise LogError(f"{log}: {skew}")


def _initial_pose(values: Any) -> np.ndarray | None:
    if values is None:
        return None
    import numpy as np

    pose0 = np.asarray(values, dtype=float).reshape(-1)
    if pose0.shape != (3,) or not np.all(np.isfinite(pose0)):
        raise ConfigError("--initial-pose needs three finite numbers: X Y YAW (m, m, rad in the map frame)")
    if abs(float(pose0[2])) > 2 * np.pi:
        raise ConfigError(f"--initial-pose: yaw {pose0[2]:g} is in radians (did you mean "
                          f"{np.radians(pose0[2]):.4f} for {pose0[2]:g} deg?)")
    return pose0


MAP_IMAGES = (".pgm", ".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


def _check_map_arg(map_yaml: Path | None) -> None:
    if map_yaml is not None and Path(map_yaml).suffix.lower() in MAP_IMAGES:
        raise ConfigError(f"{map_yaml}: this is the map's image; pass its map_server YAML "
                          f"(e.g. {Path(map_yaml).with_suffix('.yaml')}), which says the resolution and origin")


def legacy_outputs(outdir: Path) -> tuple[str, ...]:
    """The files of a run folder written before folders had a record of what fgloc wrote (its
    config.yaml has the ``run:`` section)."""
    import yaml

    try:  # libyaml's parser where PyYAML has it (4x faster than the pure-Python one on a run's config.yaml)
        data = yaml.load((outdir / "config.yaml").read_text(), Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))
    except (OSError, UnicodeDecodeError, yaml.YAMLError):
        return ()
    return OUTPUT_FILES if isinstance(data, dict) and isinstance(data.get("run"), dict) else ()


def run_outputs(outdir: Path, inputs: list[Path | None], force: bool) -> Outputs:
    """``fgloc run``'s outputs (:class:`fgloc.io.outputs.Outputs`): never an input (even with
    ``force``); files of the output names that fgloc run did not write only with ``force``;
    written into a staging folder and published together when the run is complete."""
    from fgloc.io.outputs import Outputs

    return Outputs(outdir, OUTPUT_FILES, command="run", inputs=inputs, force=force, legacy=legacy_outputs)


def check_outputs(outdir: Path, inputs: list[Path | None], force: bool) -> None:
    """The refusals of :func:`run_outputs`, one line each, nothing written."""
    run_outputs(outdir, inputs, force).check()


def run_log(req: RunRequest, progress: Callable[[int | None], Any] | None = None,
            announce: Callable[[str], None] | None = None) -> RunResult:
    """Localize ``req.log`` and write the outputs into ``req.outdir`` (see the module docstring).

    ``progress(total)``: optional factory of a progress bar (an object with ``update(n)`` and
    context-manager methods, e.g. tqdm) over the messages read.  ``announce(line)``: where the
    Foxglove view says where it serves (``req.view``).

    The outputs are checked before the log is opened (:func:`run_outputs`) and published together
    when the run is complete: an error, a Ctrl-C or a full disk leaves ``req.outdir`` as it was.
    A stop requested by a signal (:mod:`fgloc.io.stop`) ends the run between two messages.
    """
    t_start = PHASE_CLOCK()
    if req.map_yaml is not None:  # fgloc map's output folder: its map.yaml (an input, recorded as such)
        import dataclasses

        from fgloc.maps import map_file

        req = dataclasses.replace(req, map_yaml=map_file(req.map_yaml))
    config = _effective_config(req)
    inputs = _open_inputs(req, config)
    config = _with_tilted_imu_mounts(config, inputs)
    session, mirror_scans = _build_session(req, config, inputs)
    with inputs.outputs as outs:
        loop = _localize(req, outs.dir, session, inputs, mirror_scans, t_start, progress, announce)
        result = _write_outputs(req, outs.dir, config, session.loc, inputs, loop)
    result.outdir = outs.folder
    _evaluate(result, inputs, loop.final, session.loc.online_trajectory(), session.loc.monitor)
    result.timings = loop.timings(PHASE_CLOCK())
    return result


@dataclass
class _Inputs:
    """The log opened and checked (:func:`_open_inputs`): its reader, the topic of each role, the
    message counts, the config's source topics and the topics to read."""

    log: Path
    reader: Any
    topics: Any  # fgloc.io.topics.Topics
    summary: dict[str, Any]
    counts: dict[str, int]
    sources: dict[str, str]  # the config's sources: topic -> type
    initial_pose: np.ndarray | None
    outputs: Outputs  # checked, not yet begun (run_log writes through it)

    def count(self, topic: str) -> int:
        return self.counts.get(topic, 0)

    @property
    def n_scan(self) -> int:
        return self.count(self.topics.scan)

    def wanted(self) -> set[str]:
        """Every topic localized with: every configured source's (a second IMU, a pose source),
        not only the first of each."""
        t = self.topics
        return {x for x in (t.scan, t.odom, t.imu, t.tf_static, *self.sources) if self.reader.has(x)}


def _with_tilted_imu_mounts(config: FglocConfig, inputs: _Inputs) -> FglocConfig:
    """``config`` with a mount for each IMU frame the log and the config leave unmounted while its
    readings show it tilted on the robot (:mod:`fgloc.app.imutilt`); the same config otherwise."""
    import dataclasses

    from fgloc.app.imutilt import tilted_imu_mounts

    t = inputs.topics
    imus = [x for x in (t.imu, *(x for x, k in inputs.sources.items() if k == "imu")) if inputs.reader.has(x)]
    if not imus:
        return config
    odoms = [t.odom, *(x for x, k in inputs.sources.items() if k == "odometry")]
    entries = tilted_imu_mounts(inputs.reader, imus, config.sources.static_transforms, config.sources.base_frame,
                                inputs.log, odoms)
    if not entries:
        return config
    sources = dataclasses.replace(config.sources, static_transforms=[*config.sources.static_transforms, *entries])
    return dataclasses.replace(config, sources=sources)


def _effective_config(req: RunRequest) -> FglocConfig:
    """The run's config: the request's (or its YAML over the defaults) with ``--static-transform``."""
    from fgloc.config import FglocConfig, load_config

    config = req.config if isinstance(req.config, FglocConfig) else load_config(req.config)
    if req.static_transforms:
        config = _with_static_transforms(config, req.static_transforms)
    return _named_topics_over_inputs(config, _named_topics(req))


def _named_topics_over_inputs(config: FglocConfig, named: dict[str, str | None]) -> FglocConfig:
    """``--odom-topic`` / ``--imu-topic`` with a config that lists ``sources.inputs`` (a converted
    robot_localization file names its own robot's topics; the log at hand has others): the config's one
    input of that type reads the named topic, said on stderr; ``""`` (none of that input) leaves the
    config's inputs of that type out, said too.  With no input of the type, or several, or none left,
    a one-line :class:`ConfigError` says which key to set."""
    import dataclasses
    import logging

    inputs = config.sources.inputs
    if not inputs:
        return config
    say = logging.getLogger("fgloc.app.run").warning
    new = dict(inputs)
    for role, typ, option in (("odom", "odometry", "--odom-topic"), ("imu", "imu", "--imu-topic")):
        topic = named[role]
        if topic is None:
            continue
        of_type = [k for k, v in inputs.items() if isinstance(v, dict) and v.get("type") == typ]
        if topic == "":
            for k in of_type:
                del new[k]
                say('%s "": sources.inputs.%s (%s) is not read', option, k, inputs[k].get("topic"))
            if not new:
                raise ConfigError(f'{option} "": the config\'s sources.inputs list nothing else to localize with')
            continue
        if len(of_type) != 1:
            listed = (f"{len(of_type)} {typ} sources ({', '.join(of_type)}): set the one to read in "
                      f"sources.inputs.NAME.topic" if of_type else
                      f"no {typ} source: add one, sources.inputs.NAME: {{type: {typ}, topic: {topic}}}")
            raise ConfigError(f"{option} {topic}: the config's sources.inputs list {listed}")
        name = of_type[0]
        was = inputs[name].get("topic")
        if was != topic:
            new[name] = {**inputs[name], "topic": topic}
            say("%s %s: sources.inputs.%s reads it (the config names %s)", option, topic, name, was)
    return dataclasses.replace(config, sources=dataclasses.replace(config.sources, inputs=new))


def _open_inputs(req: RunRequest, config: FglocConfig) -> _Inputs:
    """Check the arguments and the outputs, open the log, choose each role's topic and check
    that the log can be localized with (one-line errors naming the log's topics)."""
    from fgloc.io import open_log
    from fgloc.io.topics import Topics, pick_topics
    from fgloc.localization.sources import source_topics

    log = Path(req.log)
    # a config's sources: name the odometry / IMU topics (a converted robot_localization file)
    src = source_topics(config.sources)
    named = _named_topics(req)
    scan_topic = named["scan"] if named["scan"] is not None else "/scan"
    odom_topic = named["odom"] if named["odom"] is not None else \
        next((t for t, k in src.items() if k == "odometry"), "/odom")
    imu_topic = named["imu"] if named["imu"] is not None else next((t for t, k in src.items() if k == "imu"), "/imu")
    topics = Topics(scan=scan_topic, odom=odom_topic, imu=imu_topic)
    pose0 = _initial_pose(req.initial_pose)
    _check_map_arg(req.map_yaml)
    cfg_path = req.config if isinstance(req.config, (str, Path)) else None
    outputs = run_outputs(Path(req.outdir), [log, req.map_yaml, cfg_path], req.force)
    outputs.check()
    reader = open_log(log, topics)
    # a default topic the log lacks: its only one of that type (fgloc import's rule), said on stderr;
    # a topic named on the command line is kept, and a config with sources names the inputs it wants
    picked = pick_topics(reader, log, {"scan": (scan_topic, named["scan"] is not None),
                                       "odom": (odom_topic, named["odom"] is not None or bool(src)),
                                       "imu": (imu_topic, named["imu"] is not None or bool(src))})
    topics = Topics(scan=picked["scan"], odom=picked["odom"], imu=picked["imu"])
    reader.topics = topics
    summ = reader.summary()
    inputs = _Inputs(log, reader, topics, summ, {t: v["count"] for t, v in summ["topics"].items()}, src, pose0,
                     outputs)
    _check_localizable(req, inputs)
    return inputs


def _named_topics(req: RunRequest) -> dict[str, str | None]:
    """The topics the request names, resolved as ROS resolves names (``scan`` -> ``/scan``); None: not
    named; ``""``: none of that input."""
    from fgloc.io.topics import resolve_name

    return {k: None if v is None else resolve_name(v) for k, v in
            (("scan", req.scan_topic), ("odom", req.odom_topic), ("imu", req.imu_topic))}


def _check_localizable(req: RunRequest, inputs: _Inputs) -> None:
    """One-line errors for a log that cannot be localized as asked: a role's topic absent or of
    another type, no input at all, none of the config's sources, scans only without a map, an IMU
    alone without a map, a map without scans."""
    from fgloc.io.topics import IMU, LASER_SCAN, ODOMETRY, normalize_type

    log, reader, summ, src = inputs.log, inputs.reader, inputs.summary, inputs.sources
    scan_topic, odom_topic, imu_topic = inputs.topics.scan, inputs.topics.odom, inputs.topics.imu
    n_scan, n_odom, n_imu = inputs.count(scan_topic), inputs.count(odom_topic), inputs.count(imu_topic)
    named = _named_topics(req)
    _check_inputs(reader, log, summ, (("--scan-topic", scan_topic, LASER_SCAN, bool(named["scan"])),
                                      ("--odom-topic", odom_topic, ODOMETRY, bool(named["odom"])),
                                      ("--imu-topic", imu_topic, IMU, bool(named["imu"]))))
    if n_odom == 0 and n_imu == 0 and n_scan == 0:
        # several topics of a type and none by its default name: which one is the robot's is the user's
        # to say (no default picks one of two odometries); the line names the options that do
        have = {opt: sorted(t for t, v in summ["topics"].items() if v["count"] and normalize_type(v["type"]) == typ)
                for opt, typ in (("--scan-topic", LASER_SCAN), ("--odom-topic", ODOMETRY), ("--imu-topic", IMU))}
        if any(have.values()):
            raise LogError(f"{log}: no {scan_topic}, {odom_topic} or {imu_topic} messages to localize with; name "
                           "the log's topics to use: " + ", ".join(f"{opt} {' | '.join(ts)}" for opt, ts in
                                                                     have.items() if ts)
                           + " (or list them in a config's sources.inputs: fgloc config init)")
        raise LogError(f"{log}: no {scan_topic}, {odom_topic} or {imu_topic} messages to localize with; its "
                       f"topics: {topics_line(summ)}")
    configured = [t for t in src if t not in (scan_topic, odom_topic, imu_topic) and reader.has(t)]
    if src and not any(reader.has(t) for t in src):
        # a converted robot_localization file names its robot's topics; this log has others
        kinds = [f"{t} ({v['type']}, {v['count']})" for t, v in summ["topics"].items()
                 if v["count"] and normalize_type(v["type"]) in (ODOMETRY, IMU)]
        raise LogError(f"{log}: none of the config's sources is in the log (sources.inputs: "
                       + ", ".join(f"{t} ({k})" for t, k in src.items()) + "); "
                       + (f"its odometry / IMU topics: {', '.join(kinds)}: set sources.inputs.NAME.topic"
                          if kinds else f"its topics: {topics_line(summ)}"))
    if req.map_yaml is None and n_odom == 0 and n_imu == 0 and not configured:
        raise LogError(f"{log}: the log has laser scans only ({n_scan} on {scan_topic}), no odometry or IMU: "
                       f"localize them on a map with --map MAP.yaml (fgloc map {log} builds one from the scans), "
                       f"or name the odometry / IMU topic with --odom-topic / --imu-topic; its topics: "
                       f"{topics_line(summ)}")
    if req.map_yaml is None and n_odom == 0 and not configured:
        # an IMU turns the robot but never moves it: every pose would stay at the start
        absent = (f" (the config's odometry source reads {odom_topic}, not in the log)"
                  if src.get(odom_topic) == "odometry" else "")
        raise LogError(f"{log}: no odometry{absent}, and the IMU ({n_imu} on {imu_topic}) gives heading only: "
                       f"without a map every pose would stay at the start; localize on a map with --map MAP.yaml, or "
                       f"name the odometry topic with --odom-topic; its topics: {topics_line(summ)}")
    if req.map_yaml is not None and n_scan == 0:
        raise LogError(f"{log}: --map needs laser scans, but the log has none on {scan_topic} (name the scan "
                       f"topic with --scan-topic, or leave out --map for odometry alone); its topics: "
                       f"{topics_line(summ)}")


def _build_session(req: RunRequest, config: FglocConfig, inputs: _Inputs) -> tuple[Any, bool]:
    """The map, the laser mount and the session (:func:`fgloc.localization.build_session`; its
    sinks are added by :func:`_localize`), and whether the scans are to be read mirrored."""
    from fgloc.localization import Routes, build_session
    from fgloc.maps import OccupancyMap

    occ_map = OccupancyMap.load(req.map_yaml) if req.map_yaml is not None else None
    if req.static_transforms:  # a command-line mount of a frame the log's sensors do not have is an error
        from fgloc.app.mounts import check_frames

        t = inputs.topics
        imus = [t.imu, *(x for x, k in inputs.sources.items() if k == "imu")]
        check_frames(req.static_transforms, _sensor_frames(inputs.reader, t.scan if inputs.n_scan else None, imus),
                     inputs.log)
    laser_mount, mirror_scans = _laser_mount(inputs.reader, inputs.n_scan, config, req.static_transforms)
    session = build_session(occ_map, laser_mount, backend=req.backend, frontend=req.frontend,
                            initial_pose=inputs.initial_pose, config=config, routes=Routes.default(inputs.topics),
                            covariance_period_s=req.covariance_period_s)
    # a configured source silent the whole log is warned about with the log's topics of its type
    session.sources.log_topics = {t: v["type"] for t, v in inputs.summary["topics"].items()}
    return session, mirror_scans


@dataclass
class _Loop:
    """What :func:`_localize` measured: the final trajectory and the phases' clock readings."""

    final: Any  # Trajectory
    t_start: float  # run_log called
    t_wall: float  # the loop began (set-up done)
    t_fin: float  # the log was read: final smoothing began
    t_done: float  # final smoothing done
    t_closed: float  # run.mcap and the view closed
    spent: dict[str, float]  # read, write, view: seconds inside the loop

    @property
    def wall_s(self) -> float:
        return self.t_closed - self.t_wall

    def timings(self, t_end: float) -> dict[str, float]:
        spent, loop = self.spent, self.t_fin - self.t_wall
        return {
            "setup_s": self.t_wall - self.t_start, "read_s": spent["read"], "write_s": spent["write"],
            "view_s": spent["view"], "localize_s": max(0.0, loop - spent["read"] - spent["write"] - spent["view"]),
            "finish_s": self.t_done - self.t_fin, "outputs_s": t_end - self.t_closed, "total_s": t_end - self.t_start,
        }


def _localize(req: RunRequest, outdir: Path, session: Any, inputs: _Inputs, mirror_scans: bool, t_start: float,
              progress: Callable[[int | None], Any] | None, announce: Callable[[str], None] | None) -> _Loop:
    """Feed the log through the session with its sinks (``outdir/run.mcap``: the inputs' own bytes and
    ``/fused_pose``; the view; the progress bar), then the final smoothing."""
    from fgloc.app.startup import setup_done
    from fgloc.io.mcap_writer import LogWriter
    from fgloc.io.stop import checkpoint
    from fgloc.localization import RecorderSink
    from fgloc.view import ViewHook, check_rate, paced

    reader, topics, loc = inputs.reader, inputs.topics, session.loc
    want = inputs.wanted()
    total = sum(inputs.count(t) for t in want)
    t_wall = PHASE_CLOCK()
    realtime = check_rate(req.realtime)
    spent = {"read": 0.0, "write": 0.0, "view": 0.0}
    clock = _LogClock()
    with LogWriter(outdir / "run.mcap") as writer, \
            ViewHook(loc, topics, view=req.view, record_to=writer if req.view_channels else None,
                     announce=announce) as view:
        # the inputs are copied by _copied (their own bytes); the recorder writes /fused_pose
        session.add_sink(_TimedSink(RecorderSink(writer, topics.fused, record_inputs=False, log_time_ns=clock.now),
                                    spent, "write"))
        session.add_sink(_TimedSink(_StatusSink(writer, loc, clock.now), spent, "write"))  # /fgloc/pose/status
        if view.active:
            rec = view.recorder
            if rec is not None and hasattr(rec, "clock"):
                rec.clock = clock.now  # the view's channels on the input's log-time clock too
                rec.scan_period_s = req.view_scan_period_s
                rec.covariance_period_s = req.view_covariance_period_s
                rec.predicted_period_s = req.view_predicted_period_s
            session.add_sink(_TimedSink(view, spent, "view"))  # the Foxglove view and its channels (fgloc.view)
        bar = progress(total) if progress is not None else None
        if bar is not None:
            session.add_sink(_ProgressSink(bar))
        setup_done()  # the CLI paused the cyclic collector for the imports and the set-up (fgloc.app.startup)
        # the evaluation's ground truth taken on the way through the log, not read again after it
        reader.collect_ground_truth = reader.has(topics.ground_truth)
        try:
            feed = session.feed
            messages = _copied(reader.records(want), writer, clock, spent)
            if mirror_scans:
                messages = _mirrored_scans(messages, topics.scan, loc.laser_mount.child.lstrip("/"))
            for topic, msg in (messages if realtime is None else paced(messages, realtime)):
                feed(topic, msg)
            checkpoint()
            t_fin = PHASE_CLOCK()
            final = session.finish()
            t_done = PHASE_CLOCK()
        finally:
            if bar is not None and hasattr(bar, "close"):
                bar.close()
    t_closed = PHASE_CLOCK()
    spent["write"] += t_closed - t_done  # the file's last chunk and its index (and the view's last messages)
    return _Loop(final, t_start, t_wall, t_fin, t_done, t_closed, spent)


def _write_outputs(req: RunRequest, outdir: Path, config: FglocConfig, loc: Any, inputs: _Inputs,
                   loop: _Loop) -> RunResult:
    """``trajectory.tum``, ``online.tum``, ``fixes.tum`` (each when not empty) and ``config.yaml``
    (the effective config and a ``run:`` section); the result without its evaluation."""
    from fgloc.config.schema import to_dict
    from fgloc.io.tum import write_tum
    from fgloc.io.yamlio import write_yaml
    from fgloc.localization.stats import RunStats

    final, reader, topics = loop.final, inputs.reader, inputs.topics
    online = loc.online_trajectory()
    fixes = loc.fixes_trajectory()
    mode = "map" if loc.map is not None else "odom"
    written = []
    if len(final):
        written.append(write_tum(outdir / "trajectory.tum", final))
        written.append(_write_status(outdir / "trajectory_status.csv", final, online, loc.monitor))
    if len(online):
        written.append(write_tum(outdir / "online.tum", online))
    if len(fixes):
        written.append(write_tum(outdir / "fixes.tum", fixes))
    pose0 = inputs.initial_pose
    effective = to_dict(config)
    effective["run"] = {
        "log": str(inputs.log), "map": str(req.map_yaml) if req.map_yaml else None, "mode": mode,
        "backend": req.backend, "frontend": loc.frontend_name,
        "initial_pose": None if pose0 is None else pose0.tolist(),
        "topics": {"scan": topics.scan, "odom": topics.odom, "imu": topics.imu},
    }
    write_yaml(outdir / "config.yaml", effective)
    # the log's span, not only the poses': a run lost most of the log has poses over a fraction of it
    sim_s = max(float(final.duration) if len(final) else 0.0, float(inputs.summary.get("duration") or 0.0))
    stats = RunStats.of(loc.stats)
    result = RunResult(
        mode=mode, frame=mode, backend=req.backend, frontend=loc.frontend_name, poses=len(final),
        online_poses=len(online), fixes=len(fixes), stats=stats, wall_s=loop.wall_s, log_s=sim_s,
        truncated=reader.truncated, outdir=outdir,
        written=[p.name for p in written] + ["run.mcap", "config.yaml"], config=config,
        log=inputs.log, lost_s=float(stats.lost_s), ended_lost=bool(stats.ended_lost),
        damaged_chunks=int(reader.damaged_chunks), damage=reader.damage(),
        status=dict(loc.stats.get("status") or {}),
    )
    result.warnings = scale_warnings(result.stats, mount_assumed=(
        inputs.n_scan > 0 and mode == "map" and not config.sources.static_transforms
        and not (reader.has(topics.tf_static) or reader.has(topics.tf))))
    if mode == "map":
        result.warnings += unused_frontend_settings(config, loc.frontend_name)
    else:
        result.warnings += unused_log_maps(inputs.log, inputs.summary)
    result.absent = absent_default_sources(config, result.stats, inputs.summary)
    return result


def absent_default_sources(config: FglocConfig, stats: RunStats, summary: dict[str, Any]) -> dict[str, str]:
    """The default layout's sources that got no message because the log has no topic of their type at
    all (no IMU on a wheels-only log): ``{name: line}``, one quiet line each.  A configured source
    (``sources.inputs``) that stays silent is a mistake to warn about, and a log with topics of the
    type under other names keeps the source's health line (which topic is the robot's is the user's
    to name)."""
    from fgloc.io.topics import IMU, ODOMETRY, normalize_type

    if config.sources.inputs:
        return {}
    types = {normalize_type(v.get("type") or "") for v in (summary.get("topics") or {}).values() if v.get("count")}
    out = {}
    for name, d in stats.sources.items():
        what = {"imu": ("IMU", IMU), "odometry": ("odometry", ODOMETRY)}.get(d.kind)
        if d.silent and what is not None and what[1] not in types:
            out[name] = f"no {what[0]} in the log"
    return out


def unused_log_maps(log: Path, summary: dict[str, Any]) -> list[str]:
    """A run without ``--map`` on a log that carries its own map (a SLAM's or nav2 map_server's
    ``/map``): said, with the two commands that localize on it, once per map topic."""
    from fgloc.app.logmap import grid_topics

    topics = summary.get("topics") or {}
    grids = [t for t in grid_topics({t: v["type"] for t, v in topics.items()}) if topics[t].get("count")]
    return [f"the log's own map on {t} was not used (no --map): fgloc export {log}:{t} -o map.yaml, then "
            f"fgloc run {log} --map map.yaml" for t in grids]


def _write_status(path: Path, final: Any, online: Any, monitor: Any) -> Path:
    """``trajectory_status.csv``: each pose of ``final`` with its status and online covariance
    (:func:`fgloc.localization.monitor.status_rows`; the format is in the README, "Pose status")."""
    from fgloc.localization.monitor import status_csv, status_rows

    path.write_text(status_csv(status_rows(final, online, monitor)))
    return path


def _evaluate(result: RunResult, inputs: _Inputs, final: Any, online: Any, monitor: Any) -> None:
    """The final and online trajectories against the log's ``/ground_truth``, when it has one: over every
    pose, and split by the poses' statuses (``monitor``: the run's, as ``trajectory_status.csv`` has them)."""
    reader, mode = inputs.reader, result.mode
    gt = reader.ground_truth() if reader.has(inputs.topics.ground_truth) else None
    if gt is not None and len(final) > 1:
        from fgloc.eval.metrics import associate, association_metrics, split_by_status

        align = mode == "odom"
        try:
            a = associate(final, gt)
            result.metrics = association_metrics(a, align=align)
            result.by_status = split_by_status(a, monitor.at(final.stamps)[0], align=align)
            if len(online) > 1:
                a = associate(online, gt)
                result.metrics_online = association_metrics(a, align=align)
                result.by_status_online = split_by_status(a, monitor.at(online.stamps)[0], align=align)
        except LogError as e:
            result.eval_error = str(e)


def _with_static_transforms(config: FglocConfig, entries: list[dict]) -> FglocConfig:
    """``config`` with ``entries`` in ``sources.static_transforms`` (replacing the same child frame)."""
    import dataclasses

    from fgloc.frames.static import parse_static_transforms

    parse_static_transforms(entries, source="--static-transform")  # one-line errors, before reading the log
    children = {str(e.get("child", "")).lstrip("/") for e in entries}
    kept = [e for e in config.sources.static_transforms if str(e.get("child", "")).lstrip("/") not in children]
    sources = dataclasses.replace(config.sources, static_transforms=[*kept, *entries])
    return dataclasses.replace(config, sources=sources)


#: wheels rarely misjudge distance by half: a speed scale (reported / true) outside this is a scan
#: geometry that disagrees with the wheels (a laser mount that is wrong, e.g. missing or upside down)
SPEED_SCALE_PLAUSIBLE = (1 / 1.5, 1.5)


def scale_warnings(stats: RunStats, mount_assumed: bool) -> list[str]:
    """One line per odometry source whose speed scale against the scan fixes is implausible
    (:data:`SPEED_SCALE_PLAUSIBLE`), naming the laser mount as the first suspect when the log had
    none (``mount_assumed``: no tf, none configured)."""
    out = []
    lo, hi = SPEED_SCALE_PLAUSIBLE
    for name, d in stats.sources.items():
        sc = d.speed_scale
        if sc is None or lo <= float(sc) <= hi:
            continue
        why = ("the log has no transform to the laser and it was taken at the robot centre, upright: give its "
               "mount with --static-transform PARENT CHILD X Y Z ROLL PITCH YAW (an upside-down laser is ROLL 180)"
               if mount_assumed else "check the laser mount and the odometry's units")
        out.append(f"{name}: the wheels report {float(sc):.2f}x the distance the scan fixes moved: {why}")
    return out


def unused_frontend_settings(config: FglocConfig, frontend: str) -> list[str]:
    """One line per ``frontends.NAME`` section the config sets (any value off its default) for a
    front-end other than ``frontend``, the one that ran: those settings did nothing (a config
    ported with ``fgloc config from-nav2`` holds AMCL's, and the default front-end is native)."""
    from fgloc.config.schema import to_dict
    from fgloc.frontends.factory import FRONTENDS, FrontendsConfig, canonical_name

    used = canonical_name(frontend)
    defaults = FrontendsConfig()
    out = []
    for name in FRONTENDS:
        if name == used:
            continue
        base = to_dict(getattr(defaults, name))
        changed = [k for k, v in to_dict(getattr(config.frontends, name)).items() if v != base.get(k)]
        if changed:
            keys = ", ".join(changed[:4]) + (f" and {len(changed) - 4} more" if len(changed) > 4 else "")
            out.append(f"frontends.{name} sets {keys}: unused, the front-end is {used} (pass --frontend {name} "
                       "to localize with it)")
    return out


def _laser_mount(reader: Any, n_scan: int, config: FglocConfig,
                 cli: list[dict] | None = None) -> tuple[Any, bool]:
    """``(base_link -> laser, mirrored)``: the config's (``sources.static_transforms``, ``--static-transform``)
    when it names the scan's frame, else the log's; no lookup (and no 'no transform' warning) in a
    log without scans.  ``mirrored``: the configured laser is upside down, so its scans are to be
    read mirrored (:func:`fgloc.frames.tf.planar_mount`; the log's own upside-down tf is
    handled by the reader).  ``cli``: the command line's entries, so that a tilted mount's error
    names the option it came from (else the config's key)."""
    import numpy as np

    from fgloc.app.mounts import RPY_OPTION, XYZW_OPTION
    from fgloc.frames.static import parse_static_transforms
    from fgloc.frames.tf import mount_of, planar_mount
    from fgloc.types import StaticTransform

    if n_scan == 0:
        return StaticTransform("base_link", "laser", np.zeros(3)), False
    mine = mount_of(reader.scan_frame(), parse_static_transforms(config.sources.static_transforms),
                    config.sources.base_frame)
    if mine is None:
        return reader.laser_mount(), False
    given = next((e for e in cli or () if str(e.get("child", "")).lstrip("/") == mine.child.lstrip("/")), None)
    where = "sources.static_transforms" if given is None else XYZW_OPTION if "xyzw" in given else RPY_OPTION
    return planar_mount(mine, where)


def _sensor_frames(reader: Any, scan_topic: str | None, imu_topics: list[str]) -> dict[str, str]:
    """``{frame: what carries it}`` of the log's scans and IMU messages (each topic's first message)."""
    from fgloc.frames.tf import frame_name

    out: dict[str, str] = {}
    if scan_topic is not None:
        out[reader.scan_frame()] = "its scans"
    for t in dict.fromkeys(imu_topics):
        if reader.has(t):
            first = next(iter(reader.messages([t])), None)
            frame = frame_name(str(getattr(first[1], "frame_id", "") or "")) if first else ""
            if frame:
                out.setdefault(frame, f"its {t} messages")
    return out


def _mirrored_scans(messages: Any, scan_topic: str, frame: str) -> Any:
    """``(topic, message)`` with the scans of ``frame`` on ``scan_topic`` mirrored (an upside-down laser
    whose mount the user gave); the recording keeps the log's own (copied before)."""
    from fgloc.io.ros import mirror_scan

    for topic, msg in messages:
        if topic == scan_topic and getattr(msg, "frame_id", "").lstrip("/") == frame:
            msg = mirror_scan(msg)
        yield topic, msg


class _LogClock:
    """The log time (ns) of the input message being processed: where the run's own messages go."""

    def __init__(self) -> None:
        self.ns: int | None = None

    def now(self) -> int | None:
        return self.ns


def _copied(records: Any, writer: Any, clock: _LogClock, spent: dict[str, float]) -> Any:
    """``(topic, message)`` of ``records``, each first copied into ``writer`` as the log stores it
    (:func:`fgloc.io.mcap_writer.tee`, timed: ``spent['read']`` decoding, ``spent['write']``
    copying) and its log time set on ``clock``."""
    from fgloc.io.stop import checkpoint

    pc = PHASE_CLOCK
    it = iter(records)
    copy = writer.copy
    while True:
        checkpoint()  # a Ctrl-C / SIGTERM ends the run here, between two messages (fgloc.io.stop)
        t0 = pc()
        rec = next(it, None)
        t1 = pc()
        spent["read"] += t1 - t0
        if rec is None:
            return
        copy(rec)
        spent["write"] += pc() - t1
        clock.ns = rec.log_time_ns
        yield rec.topic, rec.msg


class _ProgressSink:
    """Advances a progress bar by the messages read, ``every`` at a time (a bar's ``update`` per
    message was a call per message for a display refreshed twice a second)."""

    wants_fused = False

    def __init__(self, bar: Any, every: int = 64) -> None:
        self.bar = bar
        self.every = every
        self.n = 0

    def on_message(self, topic: str, msg: object) -> None:
        self.n += 1
        if self.n >= self.every:
            self.bar.update(self.n)
            self.n = 0

    def on_scan(self, stamp: float, scan: Any, fix_or_reason: Any, fused: Any) -> None:
        pass

    def close(self) -> None:
        if self.n:
            self.bar.update(self.n)
            self.n = 0


#: run.mcap's channel of each fused pose's status (JSON: stamp, status, why, frame_id)
STATUS_TOPIC = "/fgloc/pose/status"
STATUS_SCHEMA = {"type": "object", "title": "fgloc.PoseStatus",
                 "properties": {"stamp": {"type": "number"}, "status": {"type": "string"}, "why": {"type": "string"},
                                "frame_id": {"type": "string"}}}


class _StatusSink:
    """Writes the status of every fused pose (:mod:`fgloc.localization.monitor`) on :data:`STATUS_TOPIC`
    beside ``/fused_pose``, at the log time of the input being processed."""

    wants_fused = True
    wants_messages = False

    def __init__(self, writer: Any, loc: Any, log_time_ns: Callable[[], int | None]) -> None:
        import json

        self.loc = loc
        self.log_time_ns = log_time_ns
        self.dumps = json.dumps
        self._tail: tuple[tuple[Any, Any, Any], str] | None = None  # (status, why, frame_id): the JSON after the stamp
        self.write = writer.raw_writer(STATUS_TOPIC, "fgloc.PoseStatus", json.dumps(STATUS_SCHEMA).encode(),
                                       schema_encoding="jsonschema", message_encoding="json")

    def on_message(self, topic: str, msg: object) -> None:
        pass

    def on_scan(self, stamp: float, scan: Any, fix_or_reason: Any, fused: Any) -> None:
        if fused is not None:
            self.on_pose(stamp, fused)

    def on_pose(self, stamp: float, fused: Any) -> None:
        status, why = self.loc.monitor.current
        lt = self.log_time_ns()
        # json.dumps of {"stamp", "status", "why", "frame_id"}: the fields after the stamp encoded once per status
        key, stamp = (status, why, fused.frame_id), float(fused.stamp)
        if self._tail is None or self._tail[0] != key:
            self._tail = (key, ", " + self.dumps({"status": status, "why": why, "frame_id": fused.frame_id})[1:])
        data = '{"stamp": ' + (repr(stamp) if math.isfinite(stamp) else self.dumps(stamp)) + self._tail[1]
        self.write(data.encode(), int(lt) if lt is not None else max(int(float(fused.stamp) * 1e9), 0))

    def close(self) -> None:
        pass


class _TimedSink:
    """A session sink whose time is added to ``spent[key]`` (RunResult.timings)."""

    def __init__(self, sink: Any, spent: dict[str, float], key: str) -> None:
        self.sink = sink
        self.spent = spent
        self.key = key
        self.wants_fused = bool(getattr(sink, "wants_fused", True))
        self.wants_messages = bool(getattr(sink, "wants_messages", True))

    def on_message(self, topic: str, msg: object) -> None:
        t0 = PHASE_CLOCK()
        try:
            self.sink.on_message(topic, msg)
        finally:
            self.spent[self.key] += PHASE_CLOCK() - t0

    def on_scan(self, stamp: float, scan: Any, fix_or_reason: Any, fused: Any) -> None:
        t0 = PHASE_CLOCK()
        try:
            self.sink.on_scan(stamp, scan, fix_or_reason, fused)
        finally:
            self.spent[self.key] += PHASE_CLOCK() - t0

    def on_pose(self, stamp: float, fused: Any) -> None:
        on_pose = getattr(self.sink, "on_pose", None)
        if on_pose is None:
            return
        t0 = PHASE_CLOCK()
        try:
            on_pose(stamp, fused)
        finally:
            self.spent[self.key] += PHASE_CLOCK() - t0

    def close(self) -> None:
        t0 = PHASE_CLOCK()
        try:
            self.sink.close()
        finally:
            self.spent[self.key] += PHASE_CLOCK() - t0
