"""``fgloc map`` and ``fgloc map-check``'s work: read a log, run the SLAM and the self-check, write
map.yaml/.pgm, map.png, trajectory TUMs, check.png/check.yaml, mapping.yaml.

Thin I/O around :mod:`fgloc.mapping.slam` and :mod:`fgloc.mapping.selfcheck`; the caller passes
progress callbacks.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from fgloc.errors import LogError, MapError
from fgloc.io import stop
from fgloc.io.outputs import Outputs
from fgloc.io.tum import read_tum, write_tum
from fgloc.mapping.render import render_check_png, render_map_png
from fgloc.mapping.selfcheck import (
    CheckConfig,
    CheckResult,
    LoopInfo,
    check_against_map,
    check_consistency,
    map_accuracy_m,
)
from fgloc.mapping.slam import MapperConfig, SlamResult, build_occupancy, run_slam
from fgloc.mapping.source import ScanRecord, has_return, log_messages, pair_scans, scan_problem
from fgloc.maps import OccupancyMap
from fgloc.types import StaticTransform, Trajectory, Transform3D

ProgressFactory = Callable[[int, str], Callable[[int], None]]

#: the files of ``fgloc map`` and of a check (``fgloc map-check``, the map's self-check)
CHECK_FILES = ("check.yaml", "check.png")
MAP_FILES = ("map.yaml", "map.pgm", "map.png", "trajectory.tum", "trajectory_keyframes.tum", "mapping.yaml",
             *CHECK_FILES)


def _yaml_keys(path: Path) -> set[str]:
    try:
        doc = yaml.safe_load(path.read_text())
    except (OSError, UnicodeDecodeError, yaml.YAMLError):
        return set()
    return set(doc) if isinstance(doc, dict) else set()


def legacy_map_files(folder: Path) -> tuple[str, ...]:
    """The files of a map folder that fgloc map wrote before folders had a record of it (its
    mapping.yaml says so)."""
    return MAP_FILES if {"scans", "stats", "self_check"} <= _yaml_keys(folder / "mapping.yaml") else ()


def legacy_check_files(folder: Path) -> tuple[str, ...]:
    """check.yaml / check.png that fgloc wrote before folders had a record of it."""
    if legacy_map_files(folder) or {"verdict", "passed", "mode"} <= _yaml_keys(folder / "check.yaml"):
        return CHECK_FILES
    return ()


@dataclass
class MapOutput:
    outdir: Path
    occ: OccupancyMap
    slam: SlamResult
    n_scans: int
    timings: dict = field(default_factory=dict)
    check: CheckResult | None = None
    warnings: list[str] = field(default_factory=list)


def load_records(log: str | Path, start: float | None = None, end: float | None = None,
                 scan_topic: str = "/scan", odom_topic: str = "/odom",
                 static_transforms: list[Transform3D] | None = None,
                 skipped: dict[str, int] | None = None,
                 ) -> tuple[list[ScanRecord], StaticTransform]:
    """Scans with odometry from ``log``; ``start``/``end`` keep scans in that fraction [0, 1] of the log;
    ``static_transforms``: mounts the log lacks (the laser's wins over the log's); a default topic
    the log lacks is its only one of that type (:func:`fgloc.io.topics.pick_topics`).

    Scans that cannot be mapped (:func:`fgloc.mapping.source.scan_problem`) are left out and
    counted by reason into ``skipped``; a log with no usable scan, or none with a return within
    range (every beam NaN, inf, 0 or beyond range_max: nothing to map), is a one-line
    :class:`LogError`, never a map."""
    recs, mount = pair_scans(log_messages(log, scan_topic, odom_topic, static_transforms or ()), log)
    bad: dict[str, int] = {}
    kept = []
    for r in recs:
        why = scan_problem(r.scan)
        if why is None:
            kept.append(r)
        else:
            bad[why] = bad.get(why, 0) + 1
    if skipped is not None:
        skipped.update(bad)
    if not kept:
        raise LogError(f"{log}: no usable scan ({', '.join(f'{n} with {why}' for why, n in bad.items())})")
    if not any(has_return(r.scan) for r in kept):
        raise LogError(f"{log}: no scan has a return within range ({len(kept)} scans, every range NaN, inf, 0 "
                       f"or beyond range_max): nothing to map")
    recs = kept
    if start is not None or end is not None:
        n = len(recs)
        a = int(round((start or 0.0) * n))
        b = int(round((end if end is not None else 1.0) * n))
        recs = recs[a:b]
        if not recs:
            raise LogError(f"{log}: no scans in the selected part [{start}, {end}]")
    return recs, mount


def loop_infos(slam: SlamResult) -> list[LoopInfo]:
    kp = slam.keyframe_poses
    return [LoopInfo(float(slam.keyframes[lc.i].stamp), float(slam.keyframes[lc.j].stamp), kp[lc.i, :2].copy(),
                     kp[lc.j, :2].copy()) for lc in slam.loops]


def _release_memory() -> None:
    """Hand freed memory back to the OS between stages (glibc keeps freed heap otherwise, and the
    peak RSS of a long log would be the sum of its stages)."""
    import gc

    from fgloc import memory

    gc.collect()
    memory.trim()


def _fixed_mmap_threshold(nbytes: int = 8 << 20) -> None:
    """Large arrays (occupancy grids, big distance fields) from mmap, returned to the OS when freed:
    glibc's dynamic threshold would otherwise move them into the heap after the first free.  Not
    much lower: the loop and tracking fields (1-2 MB, allocated thousands of times) then come from
    fresh mmaps each time and their page faults cost system time (ACES: 1.5 s at 1 MB, 1.1 s at
    8 MB, 0.7 s at 32 MB); not higher: fr-clinic's peak RSS 460 MB at 8 MB, 489 MB at 32 MB."""
    from fgloc import memory

    memory.set_mmap_threshold(nbytes)


def _progress(factory: ProgressFactory | None, n: int, what: str) -> Callable[[int], None] | None:
    return factory(n, what) if factory is not None else None


def build_map(
    log: str | Path,
    outdir: str | Path,
    config: MapperConfig | None = None,
    start: float | None = None,
    end: float | None = None,
    progress_factory: ProgressFactory | None = None,
    scan_topic: str = "/scan",
    odom_topic: str = "/odom",
    self_check: bool = True,
    check_config: CheckConfig | None = None,
    static_transforms: list[Transform3D] | None = None,
    force: bool = False,
    inputs: tuple[Path | None, ...] = (),
) -> MapOutput:
    """Map ``log`` into ``outdir``: map.yaml/.pgm, map.png, trajectory.tum (every scan),
    trajectory_keyframes.tum, mapping.yaml (statistics, loop closures, warnings) and, with
    ``self_check``, check.yaml and check.png.  ``static_transforms``: mounts the log lacks
    (``fgloc map --static-transform``; the laser's wins over the log's).

    The files are published together at the end (:class:`fgloc.io.outputs.Outputs`): an error or
    a Ctrl-C leaves ``outdir`` as it was; files there that fgloc did not write are refused
    (before the log is read) unless ``force``; ``inputs``: other files the command read (a
    mapping config), never replaced."""
    cfg = config or MapperConfig()
    outdir = Path(outdir)
    outs = Outputs(outdir, MAP_FILES, command="map", inputs=(log, *inputs), force=force,
                   legacy=legacy_map_files, shares=("map-check",))
    outs.check()
    with outs:
        return _build_map(log, outs, cfg, start, end, progress_factory, scan_topic, odom_topic, self_check,
                          check_config, static_transforms)


def _build_map(log: str | Path, outs: Outputs, cfg: MapperConfig, start: float | None, end: float | None,
               progress_factory: ProgressFactory | None, scan_topic: str, odom_topic: str, self_check: bool,
               check_config: CheckConfig | None, static_transforms: list[Transform3D] | None) -> MapOutput:
    outdir = outs.folder
    _fixed_mmap_threshold()
    t0 = time.perf_counter()
    skipped: dict[str, int] = {}
    recs, mount = load_records(log, start, end, scan_topic, odom_topic, static_transforms, skipped)
    t1 = time.perf_counter()
    stop.checkpoint()
    res = run_slam(recs, mount, cfg, _progress(progress_factory, len(recs), "mapping"))
    _release_memory()
    stop.checkpoint()
    t2 = time.perf_counter()
    occ = build_occupancy(res, recs, mount, cfg)
    t3 = time.perf_counter()
    occ.save(outs.path("map.yaml"))
    write_tum(outs.path("trajectory.tum"), res.scan_trajectory)
    write_tum(outs.path("trajectory_keyframes.tum"), res.keyframe_trajectory)
    kp = res.keyframe_poses
    segs = np.array([[kp[lc.i, :2], kp[lc.j, :2]] for lc in res.loops]).reshape(-1, 2, 2)
    render_map_png(outs.path("map.png"), occ, res.scan_trajectory.poses[:, :2],
                   f"{Path(log).name}: {len(res.scan_trajectory)} scans, {len(res.keyframes)} keyframes, "
                   f"{len(res.loops)} loop closures", segs)
    _release_memory()
    t4 = time.perf_counter()
    loops = loop_infos(res)
    check = None
    if self_check:
        stop.checkpoint()
        check = check_consistency(recs, np.asarray(mount.pose), res.scan_trajectory, loops, check_config,
                                  _progress(progress_factory, 0, "self-check"))
        if np.isfinite(check.registration_m):  # the map declares what its passes measured
            occ.accuracy_m = round(map_accuracy_m(check.registration_m, occ.resolution), 4)
            occ.save(outs.path("map.yaml"))
        write_check(outs.dir, check, occ, res.scan_trajectory, f"{Path(log).name}: self-check")
    t5 = time.perf_counter()
    timings = {"read_s": t1 - t0, "slam_s": t2 - t1, "occupancy_s": t3 - t2, "write_s": t4 - t3,
               "check_s": t5 - t4, "total_s": t5 - t0}
    stats = {k: int(v) for k, v in res.stats.items()}
    warnings = list(res.warnings)
    if skipped:
        n_skip = sum(skipped.values())
        warnings.insert(0, f"{n_skip} of {n_skip + len(recs)} scans skipped as unusable: "
                           + "; ".join(f"{n} with {why}" for why, n in skipped.items()))
    outs.path("mapping.yaml").write_text(yaml.safe_dump({
        "log": str(log), "scans": len(recs), "skipped_scans": dict(skipped), "stats": stats,
        "timings_s": {k: round(v, 3) for k, v in timings.items()},
        "warnings": warnings,
        "self_check": check.verdict if check is not None else "not run",
        "accuracy_m": occ.accuracy_m,
        **({"registration": _registration_doc(check)} if check is not None else {}),
        "loop_closures": [[round(lp.t_old, 6), round(lp.t_new, 6), *[round(float(v), 4) for v in lp.xy_old],
                           *[round(float(v), 4) for v in lp.xy_new]] for lp in loops],
    }, sort_keys=False, width=200))
    return MapOutput(outdir, occ, res, len(recs), timings, check, warnings)


def write_check(outdir: Path, check: CheckResult, occ: OccupancyMap, trajectory: Trajectory | None,
                title: str) -> None:
    """check.yaml (verdict, per-region scores, suspects, changes) and check.png."""
    outdir.mkdir(parents=True, exist_ok=True)
    t0 = check.t_first
    regions = [{
        "center_m": [round(float(r.center[0]), 2), round(float(r.center[1]), 2)], "size_m": r.size_m,
        "score": None if not np.isfinite(r.score) else round(float(r.score), 3), "flagged": bool(r.flagged),
        "tests": r.n_tests, "checked": r.n_checked, "inconsistent": r.n_bad,
        "passes_s": [[round(p.t0 - t0, 1), round(p.t1 - t0, 1), p.n_checked, p.n_bad] for p in r.passes],
        "offset_m": round(r.offset_m, 3), "offset_deg": round(r.offset_deg, 2),
    } for r in check.regions]
    changes = [{"kind": c.kind, "center_m": [round(float(v), 2) for v in c.center],
                "bbox_m": [round(float(v), 2) for v in c.bbox], "cells": c.cells, "returns": c.observations,
                "share_of_returns": round(float(c.share), 4), "minor": not c.major}
               for c in check.changes]
    doc = {"verdict": check.verdict, "passed": bool(check.passed), "mode": check.mode,
           **({"registration": _registration_doc(check)} if check.mode == "consistency" else {}),
           "times": "seconds after the log's first scan", "first_scan_stamp": float(t0),
           "stats": {k: int(v) for k, v in check.stats.items()}, "suspects": check.suspects,
           "passes_off_s": [[round(a - t0, 1), round(b - t0, 1)] for a, b in check.culprits],
           "changes": changes, "regions": regions}
    (outdir / "check.yaml").write_text(yaml.safe_dump(doc, sort_keys=False, width=200))
    xy = trajectory.poses[:, :2] if trajectory is not None and len(trajectory) else None
    render_check_png(outdir / "check.png", occ, check, xy, title)


def _registration_doc(check: CheckResult) -> dict:
    """How well the passes register where they agree (the source of map.yaml's accuracy_m)."""
    ok = np.isfinite(check.registration_m)
    return {"scans": int(check.registration_n),
            "rms_per_axis_m": round(float(check.registration_m), 4) if ok else None,
            "rms_heading_deg": round(float(check.registration_deg), 3) if ok else None}


def read_loops(mapping_yaml: Path) -> list[LoopInfo]:
    """Loop closures listed in a mapping.yaml (empty when absent or unreadable)."""
    try:
        doc = yaml.safe_load(mapping_yaml.read_text()) or {}
        rows = doc.get("loop_closures") or []
        return [LoopInfo(float(r[0]), float(r[1]), np.array(r[2:4], dtype=float), np.array(r[4:6], dtype=float))
                for r in rows if len(r) >= 6]
    except (OSError, yaml.YAMLError, TypeError, ValueError, AttributeError):
        return []


def map_check(
    map_yaml: str | Path,
    log: str | Path,
    outdir: str | Path | None = None,
    trajectory: str | Path | None = None,
    mode: str = "auto",
    config: CheckConfig | None = None,
    progress_factory: ProgressFactory | None = None,
    scan_topic: str = "/scan",
    odom_topic: str = "/odom",
    static_transforms: list[Transform3D] | None = None,
    force: bool = False,
) -> CheckResult:
    """Self-check ``log`` against the map ``map_yaml``; writes check.yaml / check.png to ``outdir``
    (default: the map's folder).

    ``mode`` "consistency" re-matches the log's scans against its other passes (a mapping log with
    the map's own trajectory, ``trajectory.tum`` next to the map unless ``trajectory`` is given);
    "localization" compares the log's scans at the poses of ``trajectory`` (e.g. ``fgloc run``'s
    trajectory.tum) with the map and reports changed-world regions; "auto" picks consistency
    when no trajectory is given, localization otherwise.  ``static_transforms``: mounts the log
    lacks (``fgloc map-check --static-transform``, as given to ``fgloc map`` and ``fgloc run``).
    check.yaml and check.png are published together at the end; files there that fgloc did not
    write are refused (before any work) unless ``force``.
    """
    map_yaml = Path(map_yaml)
    out = Path(outdir) if outdir is not None else map_yaml.parent
    outs = Outputs(out, CHECK_FILES, command="map-check", force=force, legacy=legacy_check_files, shares=("map",),
                   inputs=(map_yaml, _map_image(map_yaml), log, trajectory))
    outs.check()
    occ = OccupancyMap.load(map_yaml)
    if mode not in ("auto", "consistency", "localization"):
        raise MapError(f"unknown check mode '{mode}' (auto, consistency or localization)")
    if mode == "auto":
        mode = "consistency" if trajectory is None else "localization"
    tpath = Path(trajectory) if trajectory is not None else map_yaml.parent / "trajectory.tum"
    if not tpath.exists():
        raise LogError(f"{tpath}: trajectory not found (give --trajectory, e.g. fgloc run's trajectory.tum)")
    traj = read_tum(tpath)
    if len(traj) == 0:
        raise LogError(f"{tpath}: trajectory has no poses")
    recs, mount = load_records(log, scan_topic=scan_topic, odom_topic=odom_topic,
                               static_transforms=static_transforms)
    stop.checkpoint()
    if mode == "consistency":
        loops = read_loops(map_yaml.parent / "mapping.yaml")
        res = check_consistency(recs, np.asarray(mount.pose), traj, loops, config,
                                _progress(progress_factory, 0, "self-check"))
    else:
        res = check_against_map(recs, np.asarray(mount.pose), traj, occ, config,
                                _progress(progress_factory, 0, "map-check"))
    if res.stats.get("posed_scans", 0) == 0:
        raise LogError(f"{log}: no scan lies within the time span of {tpath} (is it this log's trajectory?)")
    with outs:
        write_check(outs.dir, res, occ, traj, f"{Path(log).name} vs {map_yaml.name} ({res.mode})")
    return res


def _map_image(map_yaml: Path) -> Path | None:
    """The image a map YAML names (an input of map-check: never overwritten)."""
    try:
        doc = yaml.safe_load(map_yaml.read_text())
        img = doc.get("image") if isinstance(doc, dict) else None
    except (OSError, UnicodeDecodeError, yaml.YAMLError):
        return None
    return map_yaml.parent / str(img) if img else None
