"""``fgloc map LOG -o MAPDIR``: build a map_server map and trajectory from a log by pose-graph SLAM.

    fgloc map intel.clf.bz2 -o maps/intel [--resolution 0.05] [--config config/mapping.yaml]
    fgloc map run.mcap -o maps/run --start 0 --end 0.5      # only the first half of the scans
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer


def map_cmd(
    log: Annotated[Path, typer.Argument(help="CARMEN .clf/.log(.gz/.bz2) or ROS 2 MCAP log")],
    outdir: Annotated[Path, typer.Option("-o", "--output", help="output folder (map.yaml/.pgm/.png, TUMs)")],
    resolution: Annotated[float, typer.Option(help="map cell size (m)")] = 0.05,
    config: Annotated[Path | None, typer.Option(help="YAML with mapping options (MapperConfig fields)")] = None,
    start: Annotated[float | None, typer.Option(help="first fraction of the scans to use (0..1)")] = None,
    end: Annotated[float | None, typer.Option(help="last fraction of the scans to use (0..1)")] = None,
    scan_topic: Annotated[str, typer.Option(help="scan topic (MCAP)")] = "/scan",
    odom_topic: Annotated[str, typer.Option(help="odometry topic (MCAP)")] = "/odom",
    no_progress: Annotated[bool, typer.Option("--no-progress", help="no progress bar")] = False,
) -> None:
    """Build a map (ray-traced log-odds occupancy) and the optimized trajectory from a log."""
    import yaml
    from tqdm import tqdm

    from fgloc.errors import ConfigError
    from fgloc.mapping.build import build_map
    from fgloc.mapping.slam import MapperConfig

    opts: dict = {}
    if config is not None:
        try:
            opts = yaml.safe_load(config.read_text()) or {}
        except (OSError, yaml.YAMLError) as e:
            raise ConfigError(f"{config}: cannot read mapping config ({e.__class__.__name__})") from None
        if not isinstance(opts, dict):
            raise ConfigError(f"{config}: mapping config must be a mapping")
        opts = opts.get("mapping", opts)
    opts["resolution"] = resolution
    if not (resolution > 0):
        raise ConfigError(f"resolution must be positive, got {resolution}")
    cfg = MapperConfig.from_dict(opts)
    bars: list = []

    def factory(n: int):
        bar = tqdm(total=n, unit="scan", desc="mapping", disable=no_progress, leave=True)
        bars.append(bar)
        return bar.update

    try:
        out = build_map(log, outdir, cfg, start, end, factory, scan_topic, odom_topic)
    finally:
        for b in bars:
            b.close()
    s = out.slam.stats
    t = out.timings
    typer.echo(
        f"{out.n_scans} scans, {s['keyframes']} keyframes, {s['loops']} loop closures "
        f"({s['loop_tries']} tried); {t['total_s']:.1f} s (SLAM {t['slam_s']:.1f} s)"
    )
    typer.echo(f"wrote {outdir}/map.yaml, map.pgm, map.png, trajectory.tum, trajectory_scans.tum")


def register(app: typer.Typer) -> None:
    app.command("map")(map_cmd)
