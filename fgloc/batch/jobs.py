"""Batch jobs: what a worker is given (:class:`Job`), what it hands back (:class:`JobResult`),
and :func:`execute`, the function every engine runs in its worker processes.

A job names its inputs by absolute path (``inputs``: role -> path; roles ``log``, ``map``,
``config``).  Two ways for them to reach the worker:

* **by path** (default): the worker opens the paths itself and writes its outputs straight
  into ``job.outdir``; on a cluster this needs storage mounted at the same path on every node
  (NFS, a shared volume);
* **shipped** (``--ship-inputs``): the driver reads each input file (a map YAML with its
  image, a bag folder with its files) and hands the bytes over (Ray: one object-store entry per
  distinct file, so a map shared by 100 logs is stored once); the worker writes them into a
  temporary folder under their original names, runs there, and returns its output files as
  bytes, which the driver writes into ``job.outdir``.  No shared storage is needed.  Paths of
  the temporary folder in outputs and error messages are replaced by the original paths.

Either way the outputs go through :class:`fgloc.io.outputs.Outputs` (:func:`job_outputs`): the
job's folder stays inside OUTDIR (never a symbolic link), files there that fgloc did not write
are refused unless ``--force``, and a job's files are published together when it succeeded
(an error, a crash or a Ctrl-C leaves the folder as it was).

The result of a job never depends on where it ran: the worker calls the same library
function the single-log command calls, with the same arguments.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import socket
import tempfile
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fgloc.batch import adapter
from fgloc.errors import FglocError

if TYPE_CHECKING:
    from fgloc.io.outputs import Outputs

#: job kinds and the adapter function each one calls
KINDS = ("run", "map", "bench-paper")

#: shipped inputs of one role: (path relative to the role's folder, bytes)
Blob = list[tuple[str, bytes]]


@dataclass
class Job:
    """One unit of batch work: a log to localize or map, or a benchmark seed."""

    kind: str
    name: str                                   # output folder name under the batch OUTDIR
    outdir: str                                 # absolute: OUTDIR/<name>
    inputs: dict[str, str] = field(default_factory=dict)   # role -> absolute path
    params: dict[str, Any] = field(default_factory=dict)   # JSON-able options
    #: a lost run counts as done, not failed (``--allow-lost``): how the result is judged, not
    #: what is computed, so it is no part of the fingerprint (changing it re-runs nothing)
    accept_lost: bool = False
    #: replace files in the job's folder that fgloc did not write (``--force``; no part of the fingerprint)
    force: bool = False

    def fingerprint(self) -> str:
        """Hash of kind, options and inputs (path, size, mtime): a finished job whose fingerprint
        changed is run again."""
        ins = {}
        for role, p in sorted(self.inputs.items()):
            try:
                st = os.stat(p)
                ins[role] = [p, st.st_size, st.st_mtime_ns]
            except OSError:
                ins[role] = [p, None, None]
        doc = json.dumps({"kind": self.kind, "params": self.params, "inputs": ins}, sort_keys=True)
        return hashlib.sha256(doc.encode()).hexdigest()[:16]


@dataclass
class JobResult:
    """What a worker returns: the summary row, or the one-line error."""

    name: str
    ok: bool
    error: str | None = None
    row: dict[str, Any] = field(default_factory=dict)      # summary-table values (see summary.COLUMNS)
    written: list[str] = field(default_factory=list)       # output files, relative to the job's outdir
    files: dict[str, bytes] | None = None                  # shipped mode: the output files' bytes
    traceback: str | None = None                           # for unexpected (non-fgloc) errors
    host: str = ""
    wall_s: float = 0.0                                    # the whole job in the worker
    cpu_s: float = 0.0                                     # CPU time of the worker process during the job


def one_line(e: BaseException) -> str:
    """An exception as one line: fgloc errors as they are, others with their type."""
    text = str(e).strip().splitlines()[0] if str(e).strip() else ""
    if isinstance(e, FglocError):
        return text or e.__class__.__name__
    return f"{e.__class__.__name__}: {text}" if text else e.__class__.__name__


# ---------------------------------------------------------------------------- shipping
def input_files(role: str, path: str) -> list[tuple[str, Path]]:
    """The files behind one input, relative to the folder they are materialized in: a file as its
    name, a folder (bag) as its files under its name, a map YAML with its image."""
    p = Path(path)
    if p.is_dir():
        return [(str(f.relative_to(p.parent)), f) for f in sorted(p.rglob("*")) if f.is_file()]
    out = [(p.name, p)]
    if role == "map":
        img = map_image(p)
        if img is not None and img.is_file():
            out.append((image_relpath(p, img), img))
    return out


def map_image(yaml_path: Path) -> Path | None:
    """The image a map_server YAML names (None if the YAML does not parse; the worker then
    reports the map's own error)."""
    import yaml

    try:
        meta = yaml.safe_load(yaml_path.read_text())
        img = Path(str(meta["image"]))
    except Exception:  # noqa: BLE001 - any unreadable YAML: ship it alone, the map loader says why
        return None
    return img if img.is_absolute() else yaml_path.parent / img


def image_relpath(yaml_path: Path, img: Path) -> str:
    """Where the image goes beside the shipped YAML: its relative path when it is inside the
    YAML's folder, else its name (the shipped YAML is rewritten to point there)."""
    try:
        return str(img.resolve().relative_to(yaml_path.resolve().parent))
    except ValueError:
        return img.name


def read_blob(role: str, path: str) -> Blob:
    """Read one input's files (driver side) for shipping."""
    return [(rel, f.read_bytes()) for rel, f in input_files(role, path)]


def _materialize(job: Job, blobs: dict[str, Blob], tmp: Path) -> dict[str, str]:
    """Write shipped inputs under ``tmp/<role>/`` and return role -> local path."""
    import yaml

    local: dict[str, str] = {}
    for role, path in job.inputs.items():
        if role not in blobs:
            local[role] = path
            continue
        base = tmp / role
        for rel, data in blobs[role]:
            dst = base / rel
            if base.resolve() not in dst.resolve().parents:
                raise FglocError(f"{path}: shipped file name {rel!r} leaves its folder")
            dst.parent.mkdir(parents=True, exist_ok=True)
            dst.write_bytes(data)
        here = base / Path(path).name
        if role == "map" and len(blobs[role]) > 1:
            try:
                meta = yaml.safe_load(here.read_text())
                img_rel = blobs[role][1][0]
                if isinstance(meta, dict) and str(meta.get("image")) != img_rel:
                    meta["image"] = img_rel
                    here.write_text(yaml.safe_dump(meta, sort_keys=False))
            except (OSError, yaml.YAMLError):
                pass
        local[role] = str(here)
    return local


def _replacements(local: dict[str, str], job: Job) -> list[tuple[str, str]]:
    """(temporary path, original path) pairs of the shipped inputs."""
    return [(lp, job.inputs[role]) for role, lp in local.items() if lp != job.inputs[role]]


def _unlocalize(text: str, pairs: list[tuple[str, str]]) -> str:
    for a, b in pairs:
        text = text.replace(a, b)
    return text


def job_outputs(job: Job) -> Outputs:
    """The job's outputs in ``job.outdir`` (:class:`fgloc.io.outputs.Outputs`): the names the
    single-log command writes, by that command (``fgloc run`` and ``fgloc batch run`` replace each
    other's files), the folder confined to OUTDIR."""
    from fgloc.io.outputs import Outputs, confined

    folder = Path(job.outdir)
    confined(folder.parent, job.name, folder=True)
    names, legacy = adapter.output_names(job.kind, job.params)

    def earlier(f: Path) -> list[str]:  # written before folders had a record: the command's own, or batch's marker
        return [*legacy(f), *_marker_files(f)]

    return Outputs(folder, names, command=job.kind, inputs=job.inputs.values(), force=job.force, legacy=earlier)


def _marker_files(folder: Path) -> list[str]:
    """The files an earlier batch's completion marker lists with their sizes unchanged."""
    try:
        doc = json.loads((folder / "batch-done.json").read_text())
        files = doc.get("files") or {}
        return [rel for rel, size in files.items() if (folder / rel).stat().st_size == size]
    except (OSError, ValueError, AttributeError, TypeError):
        return []


# ---------------------------------------------------------------------------- the worker
def execute(job: Job, blobs: dict[str, Blob] | None = None) -> JobResult:
    """Run one job (in a worker process): never raises for a failing log, returns its error.

    By path the job's outputs are written and published into ``job.outdir`` through
    :func:`job_outputs`; shipped, they are written into the worker's temporary folder and
    returned as bytes (the driver publishes them the same way).  Text outputs (YAML, JSON) that
    name the temporary paths get the original ones.
    """
    t0, c0 = time.perf_counter(), time.process_time()
    host = f"{socket.gethostname()}:{os.getpid()}"
    tmp = Path(tempfile.mkdtemp(prefix="fgloc-batch-")) if blobs is not None else None
    local = dict(job.inputs)
    pairs: list[tuple[str, str]] = []
    try:
        if tmp is not None:
            local = _materialize(job, blobs or {}, tmp)
        pairs = _replacements(local, job)
        if tmp is not None:
            stage = tmp / "out"
            row = _run_kind(job, {k: Path(v) for k, v in local.items()}, stage)
            written = sorted(str(f.relative_to(stage)) for f in stage.rglob("*") if f.is_file()
                             and not f.name.startswith("."))
            _unlocalize_files(stage, written, pairs)
            files = {rel: (stage / rel).read_bytes() for rel in written}
        else:
            with job_outputs(job) as outs:
                row = _run_kind(job, {k: Path(v) for k, v in local.items()}, outs.dir)
                _unlocalize_files(outs.dir, outs.staged(), pairs + [(str(outs.dir), str(outs.folder))])
            written, files = outs.published, None
        return JobResult(job.name, True, row=row, written=written, files=files, host=host,
                         wall_s=time.perf_counter() - t0, cpu_s=time.process_time() - c0)
    except KeyboardInterrupt:
        raise
    except BaseException as e:  # noqa: BLE001 - failure isolation: every error becomes a row
        msg = _unlocalize(one_line(e), pairs or _replacements(local, job))
        tb = None if isinstance(e, FglocError) else _unlocalize(traceback.format_exc(), pairs)
        return JobResult(job.name, False, error=msg, traceback=tb, host=host, wall_s=time.perf_counter() - t0,
                         cpu_s=time.process_time() - c0)
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)


def _unlocalize_files(folder: Path, written: list[str], pairs: list[tuple[str, str]]) -> None:
    for rel in written:
        if rel.endswith((".yaml", ".json", ".txt", ".md")):
            text = (folder / rel).read_text()
            fixed = _unlocalize(text, pairs)
            if fixed != text:
                (folder / rel).write_text(fixed)


def _run_kind(job: Job, inputs: dict[str, Path], outdir: Path) -> dict[str, Any]:
    """Call the adapter function of ``job.kind`` with outputs into ``outdir``; return the summary row."""
    p = job.params
    if job.kind == "run":
        pose = p.get("initial_pose")
        r = adapter.localize_log(inputs["log"], outdir, inputs.get("map"), list(pose) if pose else None,
                                 inputs.get("config"), p.get("backend", "smoother"), p.get("frontend", "native"),
                                 p.get("scan_topic"), p.get("odom_topic"), p.get("imu_topic"))
        row = {"duration_s": r.log_s, "poses": r.poses, "x_real_time": _ratio(r.log_s, r.wall_s),
               "lost_time_s": r.lost_s if r.mode == "map" else None, "rmse_m": r.position_rmse_m,
               "heading_rmse_deg": r.heading_rmse_deg, "mode": r.mode,
               "note": "; ".join(x for x in (r.note, *r.warnings) if x) or None}  # as `fgloc run` warns
        if r.failure:
            # what makes `fgloc run` exit 3 (the outputs are written); a lost run with poses may be
            # accepted (--allow-lost: Job.accept_lost, judged by the summary), a run without any not
            row["failure"] = f"{job.inputs['log']}: {r.failure}"
            row["acceptable"] = r.poses > 0
        return row
    if job.kind == "map":
        m = adapter.map_log(inputs["log"], outdir, float(p.get("resolution", 0.05)), inputs.get("config"),
                            p.get("start"), p.get("end"), p.get("scan_topic", "/scan"), p.get("odom_topic", "/odom"))
        row = {"duration_s": m.duration_s, "poses": m.scans, "x_real_time": _ratio(m.duration_s, m.wall_s),
               "lost_time_s": None, "rmse_m": m.position_rmse_m, "heading_rmse_deg": m.heading_rmse_deg,
               "mode": f"{m.keyframes} keyframes, {m.loops} loops", "note": None}
        return row
    if job.kind == "bench-paper":
        variants = [tuple(v) for v in p["variants"]]
        s = adapter.bench_paper_seed(int(p["seed"]), variants, inputs.get("config"), outdir,  # type: ignore[arg-type]
                                     bool(p.get("keep", False)))
        main = main_variant([v[0] for v in variants])
        wall = sum(s.wall_s[lab] for lab in {(v[1], v[2]): v[0] for v in variants}.values())
        mm = s.metrics[main]
        row = {"duration_s": s.duration_s, "poses": s.poses[main], "x_real_time": _ratio(s.duration_s, wall),
               "lost_time_s": None, "rmse_m": mm["position_rmse_m"], "heading_rmse_deg": mm["heading_rmse_deg"],
               "mode": main, "note": None}
        return row
    raise FglocError(f"unknown batch job kind '{job.kind}' (one of {', '.join(KINDS)})")


def main_variant(labels: list[str]) -> str:
    """The benchmark column a seed's summary row shows: the fixed-lag smoother when present."""
    return "smoother fixed-lag" if "smoother fixed-lag" in labels else labels[0]


def _ratio(a: float, b: float) -> float | None:
    return a / b if b > 0 else None
