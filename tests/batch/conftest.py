"""Four short simulated logs (three good, one corrupt) and their single-run references."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

import numpy as np
import pytest

from .helpers import CORRUPT, ROUTES, START


@pytest.fixture(scope="session")
def batch_logs(tmp_path_factory) -> dict:
    """``logs/`` with alpha/bravo/charlie.mcap (seeds 0-2) and a corrupt delta.mcap; one map."""
    from fgloc.sim import simulate_paper, write_sim

    root = tmp_path_factory.mktemp("batch")
    logs = root / "logs"
    logs.mkdir()
    gts = {}
    for seed, (name, route) in enumerate(ROUTES.items()):
        sim = simulate_paper(seed=seed, route=route)
        d = write_sim(sim, root / "sim" / name)
        shutil.copy(d / "log.mcap", logs / f"{name}.mcap")
        gts[name] = sim.ground_truth
    shutil.copy(root / "sim" / "alpha" / "map.yaml", root / "map.yaml")
    shutil.copy(root / "sim" / "alpha" / "map.pgm", root / "map.pgm")
    good = (logs / "alpha.mcap").read_bytes()
    rng = np.random.default_rng(7)
    (logs / f"{CORRUPT}.mcap").write_bytes(good[:200] + rng.integers(0, 256, 50_000, dtype=np.uint8).tobytes())
    return {"root": root, "logs": logs, "map": root / "map.yaml", "gt": gts, "names": [*ROUTES, CORRUPT]}


REFERENCE_SCRIPT = """
import contextlib, io, json, sys
from fgloc.cli import main
root, logs, map_yaml, pose, names = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4].split(","), sys.argv[5:]
errors = {}
for name in names:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        rc = main(["run", f"{logs}/{name}.mcap", "--map", map_yaml, "--initial-pose", *pose,
                   "-o", f"{root}/{name}", "-q"])
    if rc:
        errors[name] = err.getvalue().strip().removeprefix("fgloc: error: ")
print(json.dumps(errors))
"""


def _single_runs(batch_logs, ref) -> dict:
    p = subprocess.run([sys.executable, "-c", REFERENCE_SCRIPT, str(ref), str(batch_logs["logs"].resolve()),
                        str(batch_logs["map"].resolve()), ",".join(map(str, START)), *batch_logs["names"]],
                       capture_output=True, text=True, timeout=300, check=True)
    return json.loads(p.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="session")
def references(batch_logs) -> dict:
    """``fgloc run`` on each log alone (absolute paths, as the batch passes them), in a fresh
    process like the batch's workers (so both run the code as it is on disk now).

    ``refresh()`` makes them again: a test whose batch differs from them compares once more
    with single runs made after its batch (the source tree may have changed in between when
    others work in it; in a fixed checkout the first comparison decides)."""
    ref = batch_logs["root"] / "ref"
    out: dict = {"dir": ref, "errors": _single_runs(batch_logs, ref)}

    def refresh() -> None:
        out["errors"] = _single_runs(batch_logs, ref)

    out["refresh"] = refresh
    return out
