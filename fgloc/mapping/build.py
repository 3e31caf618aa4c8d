"""``fgloc map``'s work: read a log, run the SLAM, write map.yaml/.pgm, trajectory TUMs, map.png.

Thin I/O around :mod:`fgloc.mapping.slam`; the caller passes a progress callback.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from fgloc.errors import LogError
from fgloc.io.tum import write_tum
from fgloc.mapping.render import render_map_png
from fgloc.mapping.slam import MapperConfig, SlamResult, build_occupancy, run_slam
from fgloc.mapping.source import ScanRecord, log_messages, pair_scans
from fgloc.maps import OccupancyMap
from fgloc.types import StaticTransform


@dataclass
class MapOutput:
    outdir: Path
    occ: OccupancyMap
    slam: SlamResult
    n_scans: int
    timings: dict = field(default_factory=dict)


def load_records(log: str | Path, start: float | None = None, end: float | None = None,
                 scan_topic: str = "/scan", odom_topic: str = "/odom"
                 ) -> tuple[list[ScanRecord], StaticTransform]:
    """Scans with odometry from ``log``; ``start``/``end`` keep scans in that fraction [0, 1] of the log."""
    recs, mount = pair_scans(log_messages(log, scan_topic, odom_topic))
    if start is not None or end is not None:
        n = len(recs)
        a = int(round((start or 0.0) * n))
        b = int(round((end if end is not None else 1.0) * n))
        recs = recs[a:b]
        if not recs:
            raise LogError(f"{log}: no scans in the selected part [{start}, {end}]")
    return recs, mount


def build_map(
    log: str | Path,
    outdir: str | Path,
    config: MapperConfig | None = None,
    start: float | None = None,
    end: float | None = None,
    progress_factory: Callable[[int], Callable[[int], None]] | None = None,
    scan_topic: str = "/scan",
    odom_topic: str = "/odom",
) -> MapOutput:
    """Map ``log`` into ``outdir`` (map.yaml, map.pgm, map.png, trajectory.tum, trajectory_scans.tum,
    mapping.yaml with statistics)."""
    cfg = config or MapperConfig()
    outdir = Path(outdir)
    t0 = time.perf_counter()
    recs, mount = load_records(log, start, end, scan_topic, odom_topic)
    t1 = time.perf_counter()
    progress = progress_factory(len(recs)) if progress_factory else None
    res = run_slam(recs, mount, cfg, progress)
    t2 = time.perf_counter()
    occ = build_occupancy(res, recs, mount, cfg)
    t3 = time.perf_counter()
    outdir.mkdir(parents=True, exist_ok=True)
    occ.save(outdir / "map.yaml")
    write_tum(outdir / "trajectory.tum", res.keyframe_trajectory)
    write_tum(outdir / "trajectory_scans.tum", res.scan_trajectory)
    kp = res.keyframe_poses
    segs = np.array([[kp[lc.i, :2], kp[lc.j, :2]] for lc in res.loops]).reshape(-1, 2, 2)
    render_map_png(outdir / "map.png", occ, res.scan_trajectory.poses[:, :2],
                   f"{Path(log).name}: {len(res.keyframes)} keyframes, {len(res.loops)} loop closures", segs)
    t4 = time.perf_counter()
    timings = {"read_s": t1 - t0, "slam_s": t2 - t1, "occupancy_s": t3 - t2, "write_s": t4 - t3, "total_s": t4 - t0}
    stats = {k: int(v) for k, v in res.stats.items()}
    (outdir / "mapping.yaml").write_text(yaml.safe_dump({
        "log": str(log), "scans": len(recs), "stats": stats,
        "timings_s": {k: round(v, 3) for k, v in timings.items()},
    }, sort_keys=False))
    return MapOutput(outdir, occ, res, len(recs), timings)
