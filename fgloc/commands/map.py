"""``fgloc map LOG -o MAPDIR``: build a map_server map and trajectory from a log by pose-graph SLAM,
then check the map against itself; ``fgloc map-check MAP.yaml LOG``: the same check for any map
and log (a mapping log, or a localization log with its trajectory: where the world changed).

    fgloc map intel.clf.bz2 -o maps/intel [--resolution 0.05] [--config mapper.yaml]
    fgloc map run.mcap -o maps/run --start 0 --end 0.5      # only the first half of the scans
    fgloc map-check maps/intel/map.yaml intel.clf.bz2        # re-check a mapping run
    fgloc map-check maps/office/map.yaml today.mcap --trajectory run/trajectory.tum -o check/
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from fgloc.app import mounts
from fgloc.io.stop import checkpoint

FORCE_HELP = "overwrite output files that fgloc did not write"

EXIT_FLAGGED = 1  # fgloc map / map-check: done, but the check flagged something (README, Exit codes)


class _Bar:
    """A progress callback over a tqdm bar, whose total a check sets once it knows it (``set_total``)."""

    def __init__(self, bar) -> None:  # noqa: ANN001
        self.bar = bar

    def __call__(self, n: int) -> None:
        checkpoint()  # a Ctrl-C / SIGTERM stops here, between two scans (fgloc.io.stop)
        self.bar.update(n)

    def set_total(self, total: int) -> None:
        self.bar.total = total
        self.bar.refresh()


def _is_run_config(opts: dict) -> bool:
    """Whether a ``--config`` file is an fgloc run's config (``fgloc run --config``): sections of
    :class:`~fgloc.config.FglocConfig` at its top."""
    import dataclasses

    from fgloc.config import FglocConfig

    return bool(set(opts) & {f.name for f in dataclasses.fields(FglocConfig)})


def _with_run_config_mounts(config: Path, opts: dict, transforms: list) -> list:
    """The mounts for the mapper: a run config's ``sources.static_transforms`` (the same file
    ``fgloc run --config`` reads), under the command line's ``--static-transform`` of the same frame."""
    if not _is_run_config(opts):
        return transforms
    from fgloc.frames.static import parse_static_transforms
    from fgloc.frames.tf import frame_name

    entries = (opts.get("sources") or {}).get("static_transforms") or []
    given = {frame_name(t.child) for t in transforms}
    mine = [t for t in parse_static_transforms(entries, source=f"{config}: sources.static_transforms")
            if frame_name(t.child) not in given]
    return [*mine, *transforms]


def _run_config_odometry(config: Path, opts: dict) -> str | None:
    """A run config's one odometry source's topic (``sources.inputs``: what ``fgloc run --config``
    reads), said on stderr; None: not a run config, or none or several odometry sources."""
    if not _is_run_config(opts):
        return None
    inputs = (opts.get("sources") or {}).get("inputs") or {}
    odo = [(k, v.get("topic")) for k, v in inputs.items() if isinstance(v, dict) and v.get("type") == "odometry"]
    if len(odo) != 1 or not isinstance(odo[0][1], str) or not odo[0][1]:
        return None
    typer.echo(f"fgloc: {config}: the odometry of sources.inputs.{odo[0][0]}, {odo[0][1]} (as fgloc run reads it)",
               err=True)
    return odo[0][1]


def _bars(quiet: bool):
    """``(bars, factory)``: one tqdm bar per stage (mapping, self-check / map-check) with its total, on
    a terminal only (a pipe or a log file gets no carriage-return lines)."""
    import sys

    from tqdm import tqdm

    bars: list = []
    show = not quiet and sys.stderr.isatty()

    def factory(n: int, what: str = "mapping"):
        for b in bars:  # one bar at a time: the previous stage is done
            b.close()
        bar = tqdm(total=n or None, unit="scan", desc=what, disable=not show, leave=False)
        bars.append(bar)
        return _Bar(bar)

    return bars, factory


def map_cmd(
    log: Annotated[Path, typer.Argument(help="CARMEN .clf/.log(.gz/.bz2) or ROS 2 MCAP log")],
    outdir: Annotated[Path, typer.Option("-o", "--output", help="output folder (map.yaml/.pgm/.png, TUMs, check)")],
    resolution: Annotated[float, typer.Option(help="map cell size (m)")] = 0.05,
    config: Annotated[Path | None, typer.Option(help="YAML with mapping options (MapperConfig fields)")] = None,
    start: Annotated[float | None, typer.Option(help="first fraction of the scans to use (0..1)")] = None,
    end: Annotated[float | None, typer.Option(help="last fraction of the scans to use (0..1)")] = None,
    scan_topic: Annotated[str, typer.Option(help="sensor_msgs/LaserScan topic (a log without /scan: its only "
                                            "LaserScan topic)")] = "/scan",
    odom_topic: Annotated[str | None, typer.Option(help="nav_msgs/Odometry topic [/odom, or a run config's one "
                                                   "odometry source; a log without it: its only Odometry topic; "
                                                   "without any, or \"\": the scans are matched to each other "
                                                   "alone]")] = None,
    no_check: Annotated[bool, typer.Option("--no-check", help="skip the self-check")] = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="no progress bar (none either when stderr is not a "
                                        "terminal)")] = False,
    no_progress: Annotated[bool, typer.Option("--no-progress", hidden=True, help="the old name of --quiet")] = False,
    static_transform: Annotated[tuple[str, str, float, float, float, float, float, float] | None,
                                typer.Option("--static-transform", help=mounts.RPY_HELP)] = None,
    static_transform_xyzw: Annotated[tuple[str, str, float, float, float, float, float, float, float] | None,
                                     typer.Option("--static-transform-xyzw", help=mounts.XYZW_HELP)] = None,
    force: Annotated[bool, typer.Option("--force", help=FORCE_HELP)] = False,
) -> None:
    """Build a map (ray-traced log-odds occupancy) and the optimized trajectory from a log, and
    self-check it: re-match the scans of every place against the map of the other passes.  Exit 0 done
    (CONSISTENT or NOT CHECKED), 1 the map is written but its self-check flagged it, 2 a usage error."""
    import yaml

    from fgloc.config.schema import load_yaml
    from fgloc.errors import ConfigError
    from fgloc.io.outputs import refuse_file_name
    from fgloc.mapping.build import MAP_FILES, build_map
    from fgloc.mapping.slam import MapperConfig

    refuse_file_name(outdir, MAP_FILES, "map")
    transforms = mounts.static_transforms(static_transform, static_transform_xyzw)

    opts: dict = {}
    if config is not None:
        try:
            opts = load_yaml(config.read_text()) or {}
        except (OSError, yaml.YAMLError) as e:
            raise ConfigError(f"{config}: cannot read mapping config ({e.__class__.__name__})") from None
        if not isinstance(opts, dict):
            raise ConfigError(f"{config}: mapping config must be a mapping")
        transforms = _with_run_config_mounts(config, opts, transforms)
        if odom_topic is None:
            odom_topic = _run_config_odometry(config, opts)
        opts = opts.get("mapping", {} if _is_run_config(opts) else opts)
    if odom_topic is None:
        odom_topic = "/odom"
    opts["resolution"] = resolution
    if not (resolution > 0):
        raise ConfigError(f"resolution must be positive, got {resolution}")
    cfg = MapperConfig.from_dict(opts)
    from fgloc.io import stop
    from fgloc.io.topics import resolve_name

    bars, factory = _bars(quiet or no_progress)
    try:
        with stop.cooperative():  # stops between scans: never in the middle of numba or GTSAM code
            out = build_map(log, outdir, cfg, start, end, factory, resolve_name(scan_topic), resolve_name(odom_topic),
                            self_check=not no_check, static_transforms=transforms, force=force, inputs=(config,))
    finally:
        for b in bars:
            b.close()
    s = out.slam.stats
    t = out.timings
    typer.echo(
        f"{out.n_scans} scans, {s['keyframes']} keyframes, {s['loops']} loop closures "
        f"({s['loop_tries']} tried); {t['total_s']:.1f} s (SLAM {t['slam_s']:.1f} s, check {t['check_s']:.1f} s)"
    )
    for w in out.warnings:
        typer.echo(f"warning: {w}", err=True)
    files = "map.yaml, map.pgm, map.png, trajectory.tum (every scan), trajectory_keyframes.tum, mapping.yaml"
    if out.check is not None:
        typer.echo(out.check.verdict)
        for line in out.check.suspects:
            typer.echo(f"  {line}")
        files += ", check.yaml, check.png"
    typer.echo(f"wrote {outdir}/: {files}")
    if out.check is not None and not out.check.passed:
        # as fgloc map-check: the map is written, but its own check flagged it (exit 1; --no-check skips it)
        typer.echo(f"fgloc map: the self-check flagged the map: see {outdir}/check.png", err=True)
        raise SystemExit(EXIT_FLAGGED)


def map_check_cmd(
    map_yaml: Annotated[Path, typer.Argument(help="map_server YAML (fgloc map's map.yaml or any other)")],
    log: Annotated[Path, typer.Argument(help="the log: the mapping log, or a localization log")],
    outdir: Annotated[Path | None, typer.Option("-o", "--output", help="where check.yaml/.png go "
                                                "(default: the map's folder)")] = None,
    trajectory: Annotated[Path | None, typer.Option(help="TUM poses of the log's scans (default: trajectory.tum "
                                                    "next to the map, i.e. the mapping run's own)")] = None,
    mode: Annotated[str, typer.Option(help="consistency (passes vs each other), localization (log vs map, "
                                      "changed world) or auto (localization when --trajectory is given)")] = "auto",
    scan_topic: Annotated[str, typer.Option(help="sensor_msgs/LaserScan topic (a log without /scan: its only "
                                            "LaserScan topic)")] = "/scan",
    odom_topic: Annotated[str, typer.Option(help="nav_msgs/Odometry topic (a log without /odom: its only "
                                            "Odometry topic)")] = "/odom",
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="no progress bar (none either when stderr is not a "
                                        "terminal)")] = False,
    no_progress: Annotated[bool, typer.Option("--no-progress", hidden=True, help="the old name of --quiet")] = False,
    static_transform: Annotated[tuple[str, str, float, float, float, float, float, float] | None,
                                typer.Option("--static-transform", help=mounts.RPY_HELP)] = None,
    static_transform_xyzw: Annotated[tuple[str, str, float, float, float, float, float, float, float] | None,
                                     typer.Option("--static-transform-xyzw", help=mounts.XYZW_HELP)] = None,
    force: Annotated[bool, typer.Option("--force", help=FORCE_HELP)] = False,
) -> None:
    """Check a map against a log: which regions disagree between passes (and which loop closures
    are suspect), or where the world no longer matches the map.  Exit 0 when it passes, 1 when
    it flags something."""
    from fgloc.io.topics import resolve_name
    from fgloc.mapping.build import map_check
    from fgloc.maps import map_file

    map_yaml = map_file(map_yaml)  # fgloc map's output folder: its map.yaml
    transforms = mounts.static_transforms(static_transform, static_transform_xyzw)
    from fgloc.io import stop

    bars, factory = _bars(quiet or no_progress)
    try:
        with stop.cooperative():
            res = map_check(map_yaml, log, outdir, trajectory, mode, None, factory, resolve_name(scan_topic),
                            resolve_name(odom_topic), static_transforms=transforms, force=force)
    finally:
        for b in bars:
            b.close()
    typer.echo(res.verdict)
    for line in res.suspects:
        typer.echo(f"  {line}")
    typer.echo(f"wrote {outdir if outdir is not None else map_yaml.parent}/check.yaml, check.png")
    if not res.passed:  # SystemExit: fgloc.cli runs click with standalone_mode=False, which swallows typer.Exit codes
        raise SystemExit(EXIT_FLAGGED)


def register(app: typer.Typer) -> None:
    app.command("map")(map_cmd)
    app.command("map-check")(map_check_cmd)
