"""Helpers of the batch tests: the four logs' names, the CLI in-process, byte comparison."""

from __future__ import annotations

from pathlib import Path

from fgloc.testing.cli import run_cli as fgloc_cli

#: short legs along the paper route's first side, all starting at (2.5, 3.0) heading east
ROUTES = {"alpha": [[2.5, 3.0], [7.5, 3.0]], "bravo": [[2.5, 3.0], [8.5, 3.0]], "charlie": [[2.5, 3.0], [6.5, 3.0]]}
START = (2.5, 3.0, 0.0)
CORRUPT = "delta"
OUTPUTS = ("trajectory.tum", "online.tum", "fixes.tum", "run.mcap", "config.yaml")



def _differences(outdir: Path, ref: Path, names) -> list[str]:
    return [f"{name}/{f}" for name in names for f in OUTPUTS
            if (outdir / name / f).read_bytes() != (ref / name / f).read_bytes()]


def assert_identical(outdir: Path, ref, names) -> None:
    """Every output file of the batch equals the single run's, byte for byte.

    ``ref``: a folder, or the ``references`` fixture (then single runs made after the batch
    decide when the session's first ones differ: see ``references.refresh``)."""
    if isinstance(ref, dict):
        if _differences(outdir, ref["dir"], names):
            ref["refresh"]()
        ref = ref["dir"]
    diff = _differences(outdir, ref, names)
    assert not diff, f"{diff} differ from the single runs"


def crash_or_count(job, blobs):
    """A worker function for the engine tests: the job named ``boom`` kills its own process
    (as a segfault or the OOM killer would); the others report how many bytes were shipped and
    their process's niceness."""
    import os
    import signal

    from fgloc.batch import JobResult

    if job.name == "boom":
        os.kill(os.getpid(), signal.SIGKILL)
    size = sum(len(b) for files in (blobs or {}).values() for _, b in files)
    return JobResult(job.name, True, row={"poses": size, "nice": os.nice(0)}, host=str(os.getpid()))


def single_run_here(log: Path, map_yaml: Path, outdir: Path) -> Path:
    """``fgloc run`` in this process (the code the in-process engine runs), absolute paths."""
    rc, _, err = fgloc_cli("run", log.resolve(), "--map", map_yaml.resolve(), "--initial-pose", *map(str, START),
                           "-o", outdir, "-q")
    assert rc == 0, err
    return outdir
