"""Which logs a batch covers and the jobs made from them.

* ``LOGS`` arguments are files, folders (searched recursively for ``*.mcap``, ROS 1 ``*.bag`` and
  CARMEN ``*.clf``/``.clf.gz``/``.clf.bz2``; a folder holding ``metadata.yaml`` is a ROS 2
  bag and counts as one log) or glob patterns (``'runs/**/*.mcap'``, quoted so that the shell
  leaves them to us).  Files under the batch's own output folder are never picked up.
* ``--manifest FILE``: a CSV with the header ``log,map,x,y,yaw`` (extra columns ignored), one
  log per row; relative paths are relative to the manifest's folder; an empty ``map`` uses
  ``--map`` (or none), empty ``x,y,yaw`` use ``--initial-pose`` (or global localization).
* Each log's outputs go to ``OUTDIR/<name>/``, ``<name>`` its file name without the log
  suffixes; logs with the same name get their parent folders' names in front
  (``day1/run.mcap``, ``day2/run.mcap`` -> ``day1_run``, ``day2_run``).  A name is one harmless
  path component whatever the log is called (:func:`fgloc.io.outputs.safe_name`: ``...mcap``
  gives ``__``, never ``..``; no separators, no leading dot), never a file of OUTDIR itself
  (``summary.csv``): outputs stay inside OUTDIR.
"""

from __future__ import annotations

import csv
import glob
import io
from pathlib import Path
from typing import Any

from fgloc.batch.jobs import Job
from fgloc.errors import ConfigError

#: the log files a folder is searched for (every format fgloc run and fgloc map read; a rosbag2
#: folder is found by its metadata.yaml)
RUN_SUFFIXES = (".mcap", ".bag", ".clf", ".clf.gz", ".clf.bz2")
MAP_SUFFIXES = RUN_SUFFIXES
STRIP_SUFFIXES = (".mcap", ".clf", ".log", ".gz", ".bz2", ".db3", ".bag")
GLOB_CHARS = set("*?[")


def _under(p: Path, folder: Path | None) -> bool:
    if folder is None:
        return False
    try:
        p.resolve().relative_to(folder.resolve())
        return True
    except ValueError:
        return False


def _is_bag_folder(d: Path) -> bool:
    return (d / "metadata.yaml").is_file()


def _search(folder: Path, suffixes: tuple[str, ...], exclude: Path | None) -> list[Path]:
    if _is_bag_folder(folder):
        return [folder]
    found: list[Path] = []
    bags = sorted(d for d in folder.rglob("*") if d.is_dir() and _is_bag_folder(d) and not _under(d, exclude))
    for f in sorted(folder.rglob("*")):
        if not f.is_file() or _under(f, exclude) or any(b in f.parents for b in bags):
            continue
        if f.name.lower().endswith(suffixes):
            found.append(f)
    return sorted(found + bags)


def discover_logs(args: list[str], suffixes: tuple[str, ...] = RUN_SUFFIXES,
                  exclude: Path | None = None) -> list[Path]:
    """Expand files, folders and globs into a sorted, duplicate-free list of absolute log paths.

    A pattern that matches nothing, a missing path or a folder without logs is a
    :class:`ConfigError` (a typo should not start a batch of the wrong logs).
    """
    out: list[Path] = []
    for a in args:
        if GLOB_CHARS & set(a) and not Path(a).exists():
            hits = sorted(Path(h) for h in glob.glob(a, recursive=True))
            if not hits:
                raise ConfigError(f"{a}: pattern matches no file")
            for h in hits:
                out += _search(h, suffixes, exclude) if h.is_dir() else [h]
            continue
        p = Path(a)
        if p.is_dir():
            found = _search(p, suffixes, exclude)
            if not found:
                raise ConfigError(f"{p}: no logs ({', '.join('*' + s for s in suffixes)}) in this folder")
            out += found
        elif p.exists():
            out.append(p)
        else:
            raise ConfigError(f"{p}: log file not found")
    seen: dict[Path, None] = {}
    for p in out:
        seen.setdefault(p.resolve(), None)
    return list(seen)


def log_stem(p: Path) -> str:
    """``run.mcap`` -> ``run``, ``intel.clf.bz2`` -> ``intel``."""
    name = p.name
    changed = True
    while changed:
        changed = False
        for s in STRIP_SUFFIXES:
            if name.lower().endswith(s) and len(name) > len(s):
                name = name[: -len(s)]
                changed = True
    return name


#: files of OUTDIR itself, never a job's folder name
RESERVED = ("summary.csv", "table.md", "metrics.yaml")


def unique_names(paths: list[Path]) -> list[str]:
    """One output folder name per log: the stem, with parent folder names in front where needed;
    each a single safe path component (:func:`fgloc.io.outputs.safe_name`), none of :data:`RESERVED`."""
    from fgloc.io.outputs import safe_name

    depth = [0] * len(paths)

    def name(i: int) -> str:
        p = paths[i]
        parts = [q.name for q in list(p.parents)[: depth[i]]][::-1]
        return safe_name("_".join([*[x for x in parts if x], log_stem(p)]), "log")

    for _ in range(64):
        names = [name(i) for i in range(len(paths))]
        groups: dict[str, list[int]] = {}
        for i, n in enumerate(names):
            groups.setdefault(n, []).append(i)
        clash = [i for n, g in groups.items() if len(g) > 1 or n in RESERVED for i in g]
        if not clash:
            return names
        grew = False
        for i in clash:
            if depth[i] < len(paths[i].parents) - 1:
                depth[i] += 1
                grew = True
        if not grew:
            break
    names = [name(i) for i in range(len(paths))]
    counts: dict[str, int] = {n: 1 for n in RESERVED}
    out = []
    for n in names:  # the same name at every depth: number them
        counts[n] = counts.get(n, 0) + 1
        k = counts[n]
        while k > 1 and f"{n}_{k}" in names:
            k += 1
        counts[n] = k
        out.append(n if k == 1 else f"{n}_{k}")
    return out


# ---------------------------------------------------------------------------- manifest
def read_manifest(path: Path) -> list[dict[str, Any]]:
    """Rows ``{"log": Path, "map": Path | None, "pose": [x, y, yaw] | None}`` of a manifest CSV."""
    try:
        with path.open(newline="") as fh:
            text = fh.read()
    except FileNotFoundError:
        raise ConfigError(f"{path}: manifest not found") from None
    except (OSError, UnicodeDecodeError) as e:
        raise ConfigError(f"{path}: cannot read manifest ({e})") from None
    reader = csv.DictReader(io.StringIO(text))
    header = [h.strip() for h in (reader.fieldnames or [])]
    need = ["log", "map", "x", "y", "yaw"]
    if any(n not in header for n in need):
        raise ConfigError(f"{path}: manifest header must be 'log,map,x,y,yaw', got {','.join(header) or 'nothing'}")
    base = path.parent
    rows = []
    for k, raw in enumerate(reader, start=2):
        r = {(key or "").strip(): (v or "").strip() for key, v in raw.items() if key is not None}
        if not any(r.values()):
            continue
        if not r.get("log"):
            raise ConfigError(f"{path}:{k}: empty log column")
        log = Path(r["log"]).expanduser()
        log = log if log.is_absolute() else base / log
        mp = None
        if r.get("map"):
            mp = Path(r["map"]).expanduser()
            mp = mp if mp.is_absolute() else base / mp
        vals = [r.get("x", ""), r.get("y", ""), r.get("yaw", "")]
        pose = None
        if any(vals):
            if not all(vals):
                raise ConfigError(f"{path}:{k}: give all of x, y, yaw or none of them")
            from fgloc.app.units import pose_arg, pose_value

            try:
                pose = list(pose_arg((float(vals[0]), float(vals[1]), pose_value(vals[2])), f"{path}:{k}") or ())
            except (ValueError, ConfigError):
                raise ConfigError(f"{path}:{k}: x, y, yaw must be numbers (the yaw in rad, or with its unit: "
                                  f"90deg), got {','.join(vals)}") from None
        rows.append({"log": log.resolve(), "map": None if mp is None else mp.resolve(), "pose": pose})
    if not rows:
        raise ConfigError(f"{path}: manifest has no rows")
    return rows


# ---------------------------------------------------------------------------- jobs
def _abs(p: Path | None) -> str | None:
    return None if p is None else str(Path(p).expanduser().resolve())


def run_jobs(logs: list[Path], outdir: Path, map_yaml: Path | None = None, initial_pose: list[float] | None = None,
             config: Path | None = None, backend: str = "smoother", frontend: str = "native",
             scan_topic: str | None = None, odom_topic: str | None = None, imu_topic: str | None = None,
             manifest: list[dict[str, Any]] | None = None, allow_lost: bool = False) -> list[Job]:
    """``fgloc run`` jobs: the LOGS with the common options, then the manifest's rows."""
    entries: list[tuple[Path, Path | None, list[float] | None]] = [(p, map_yaml, initial_pose) for p in logs]
    for r in manifest or []:
        entries.append((r["log"], r["map"] if r["map"] is not None else map_yaml,
                        r["pose"] if r["pose"] is not None else initial_pose))
    seen: dict[str, int] = {}
    uniq: list[tuple[Path, Path | None, list[float] | None]] = []
    for e in entries:  # a log given twice runs once (the manifest row, with its own map, wins)
        key = _abs(e[0]) or ""
        if key in seen:
            uniq[seen[key]] = e
        else:
            seen[key] = len(uniq)
            uniq.append(e)
    names = unique_names([Path(_abs(e[0]) or "") for e in uniq])
    out = Path(outdir).resolve()
    jobs = []
    for (log, mp, pose), name in zip(uniq, names, strict=True):
        inputs = {"log": _abs(log)}
        if mp is not None:
            inputs["map"] = _abs(mp)
        if config is not None:
            inputs["config"] = _abs(config)
        params: dict[str, Any] = {"backend": backend, "frontend": frontend,
                  "initial_pose": None if pose is None else [float(v) for v in pose],
                  "scan_topic": scan_topic, "odom_topic": odom_topic, "imu_topic": imu_topic}
        jobs.append(Job("run", name, str(out / name), {k: v for k, v in inputs.items() if v}, params,
                        accept_lost=allow_lost))
    return jobs


def map_jobs(logs: list[Path], outdir: Path, resolution: float = 0.05, config: Path | None = None,
             start: float | None = None, end: float | None = None, scan_topic: str = "/scan",
             odom_topic: str = "/odom") -> list[Job]:
    """``fgloc map`` jobs, one per log."""
    names = unique_names([Path(_abs(p) or "") for p in logs])
    out = Path(outdir).resolve()
    jobs = []
    for log, name in zip(logs, names, strict=True):
        inputs = {"log": _abs(log) or ""}
        if config is not None:
            inputs["config"] = _abs(config) or ""
        params = {"resolution": float(resolution), "start": start, "end": end,
                  "scan_topic": scan_topic, "odom_topic": odom_topic}
        jobs.append(Job("map", name, str(out / name), inputs, params))
    return jobs


def bench_paper_jobs(seeds: int, outdir: Path, variants: list[tuple[str, str, str, str]],
                     config: Path | None = None, keep_seed0: bool = True) -> list[Job]:
    """One job per seed 0..N-1 of the paper benchmark; seed 0 keeps its trajectories (for the plots)."""
    if seeds < 1:
        raise ConfigError("--seeds must be at least 1")
    out = Path(outdir).resolve()
    width = max(3, len(str(seeds - 1)))
    jobs = []
    for s in range(seeds):
        name = f"seed-{s:0{width}d}"
        inputs = {"config": _abs(config) or ""} if config is not None else {}
        jobs.append(Job("bench-paper", name, str(out / name), inputs,
                        {"seed": s, "variants": [list(v) for v in variants], "keep": keep_seed0 and s == 0}))
    return jobs
