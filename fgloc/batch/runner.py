"""Run a list of jobs on an engine with resumption, failure isolation and a summary table.

* A finished job's folder gets a completion marker, ``batch-done.json``, written last (after
  every output file is in place); it holds the job's fingerprint (kind, options, inputs),
  its summary row and the sizes of its output files.  A later run skips a job whose marker
  is there, matches its fingerprint and whose files are all present with those sizes;
  ``force`` runs everything again.  A job about to run loses its old marker first.
* A job that fails (a corrupt log, a missing map, a crashed worker) gets a row with its
  one-line error (and ``error.txt`` with the traceback for unexpected errors); the others go on.
* Ctrl-C or SIGTERM stops the engine (running jobs are abandoned, without markers, their folders
  as they were: :func:`fgloc.batch.jobs.job_outputs`), keeps every finished job and writes the
  summary of what finished: running the same command again picks up the rest.  A second signal
  ends the batch at once (the workers are killed; finished jobs are kept all the same).
* Before anything runs, each job's folder is checked (:meth:`fgloc.io.outputs.Outputs.check`):
  a folder that holds files fgloc did not write is that job's error row unless ``force``.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable
from contextlib import closing
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fgloc.batch.jobs import Job, JobResult, execute, job_outputs
from fgloc.batch.summary import COLUMNS, SummaryRow, write_summary_csv

if TYPE_CHECKING:
    from fgloc.io.outputs import Outputs

MARKER = "batch-done.json"
MARKER_VERSION = 1


@dataclass
class BatchReport:
    """The outcome of one batch invocation (rows in job order)."""

    rows: list[SummaryRow]
    summary_csv: Path
    engine: str
    wall_s: float
    interrupted: bool = False
    ran: int = 0
    skipped: int = 0
    failed: int = 0
    results: dict[str, JobResult] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return not self.interrupted and self.failed == 0


def marker_path(job: Job) -> Path:
    return Path(job.outdir) / MARKER


def read_marker(job: Job) -> dict[str, Any] | None:
    """The job's completion marker if its outputs are complete and its fingerprint matches."""
    p = marker_path(job)
    try:
        doc = json.loads(p.read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(doc, dict) or doc.get("version") != MARKER_VERSION or doc.get("name") != job.name:
        return None
    if doc.get("fingerprint") != job.fingerprint():
        return None
    for rel, size in (doc.get("files") or {}).items():
        f = Path(job.outdir) / rel
        try:
            if f.stat().st_size != size:
                return None
        except OSError:
            return None
    return doc


def write_marker(job: Job, res: JobResult) -> None:
    """Written after every output file (atomically: a half-written marker never exists)."""
    out = Path(job.outdir)
    files = {rel: (out / rel).stat().st_size for rel in res.written if (out / rel).is_file()}
    doc = {"version": MARKER_VERSION, "name": job.name, "kind": job.kind, "fingerprint": job.fingerprint(),
           "row": res.row, "files": files, "host": res.host, "wall_s": res.wall_s,
           "finished": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
    tmp = out / (MARKER + ".tmp")
    tmp.write_text(json.dumps(doc, indent=1) + "\n")
    os.replace(tmp, marker_path(job))


def clear_marker(job: Job) -> None:
    """Before a job runs: its old marker and error go."""
    for p in (marker_path(job), Path(job.outdir) / "error.txt"):
        try:
            p.unlink()
        except FileNotFoundError:
            pass


def _store(job: Job, res: JobResult) -> JobResult:
    """Driver side: shipped outputs into the job's folder (published whole), then the marker (or error.txt)."""
    from fgloc.io.outputs import OutputError, OutputFile

    out = Path(job.outdir)
    try:
        if res.ok and res.files is not None:
            with job_outputs(job) as outs:
                for rel, data in res.files.items():
                    outs.path(rel).write_bytes(data)
            res.files = None
        if res.ok:
            write_marker(job, res)
        elif res.traceback and not out.is_symlink():  # never written through a link out of OUTDIR
            out.mkdir(parents=True, exist_ok=True)
            with OutputFile(out / "error.txt", command="batch", force=True, what="error") as f:
                f.path.write_text(res.traceback)
    except OutputError as e:
        return JobResult(job.name, False, error=str(e), host=res.host)
    except OSError as e:
        return JobResult(job.name, False, error=f"{out}: cannot write outputs ({e.strerror or e})", host=res.host)
    return res


def _refused(job: Job) -> JobResult | None:
    """The job's error row when its folder cannot take its outputs (checked before it runs)."""
    from fgloc.io.outputs import OutputError

    try:
        job_outputs(job).check()
    except OutputError as e:
        return JobResult(job.name, False, error=str(e))
    return None


def _summary_outputs(path: Path, force: bool) -> Outputs:
    """summary.csv, replaced whole: never a file of that name that a batch did not write (unless ``force``)."""
    from fgloc.io.outputs import Outputs

    def earlier(folder: Path) -> list[str]:
        try:
            with (folder / path.name).open() as fh:
                return [path.name] if fh.readline().strip() == ",".join(COLUMNS) else []
        except (OSError, UnicodeDecodeError):
            return []

    return Outputs(path.parent, [path.name], command="batch", force=force, legacy=earlier)


def _summary(path: Path, rows: list[SummaryRow], force: bool) -> Path:
    with _summary_outputs(path, force) as outs:
        write_summary_csv(outs.path(path.name), rows)
    return path


def run_batch(jobs: list[Job], outdir: Path, engine: Any, ship: bool = False, force: bool = False,
              progress: bool = True, desc: str = "logs", fn: Callable[..., JobResult] = execute,
              on_result: Callable[[Job, JobResult], None] | None = None) -> BatchReport:
    """Run ``jobs`` on ``engine`` and write ``outdir/summary.csv``; never raises for a failing job.

    ``fn`` is what the workers run (:func:`fgloc.batch.jobs.execute`); ``on_result`` is called in
    the driver for every finished job (after its outputs and marker are written).
    """
    from tqdm import tqdm

    t0 = time.perf_counter()
    summary_csv = outdir / "summary.csv"
    _summary_outputs(summary_csv, force).check()  # before any work: a user's summary.csv stays
    outdir.mkdir(parents=True, exist_ok=True)
    rows: dict[str, SummaryRow] = {}
    results: dict[str, JobResult] = {}
    todo: list[Job] = []
    for job in jobs:
        job.force = force
        doc = None if force else read_marker(job)
        if doc is not None:
            rows[job.name] = SummaryRow.from_marker(job.name, doc, job.accept_lost)
            continue
        refused = _refused(job)
        if refused is not None:
            results[job.name] = refused
            rows[job.name] = SummaryRow.from_result(refused, job.accept_lost)
            continue
        clear_marker(job)
        todo.append(job)
    skipped = len(jobs) - len(todo) - len(results)
    interrupted = False
    failed = 0
    bar = tqdm(total=len(jobs), initial=skipped, desc=desc, unit="log", disable=not progress, leave=False,
               dynamic_ncols=True)
    from fgloc.io import stop

    try:  # a signal stops the driver at once (it only waits for its workers: fgloc.io.stop)
        with stop.immediate(), closing(engine.run(fn, todo, ship)) as it:
            for i, res in it:
                job = todo[i]
                res = _store(job, res)
                results[job.name] = res
                rows[job.name] = SummaryRow.from_result(res, job.accept_lost)
                failed += rows[job.name].status in ("error", "lost")
                bar.update(1)
                if failed:
                    bar.set_postfix(failed=failed)
                if on_result is not None:
                    on_result(job, res)
    except KeyboardInterrupt:
        interrupted = True
    finally:
        bar.close()
    ordered = [rows.get(j.name) or SummaryRow.not_run(j.name) for j in jobs]
    failed = sum(r.status in ("error", "lost") for r in ordered)
    csv_path = _summary(summary_csv, ordered, force)
    return BatchReport(ordered, csv_path, engine.describe(), time.perf_counter() - t0, interrupted,
                       ran=len(results), skipped=skipped, failed=failed, results=results)
