"""Start-up cost: the CLI must not import the heavy libraries before a command needs them.

`import fgloc.cli` took 0.76 s of CPU when one top-level import in a command module pulled in
numba and scipy (fixed in 27da586; 0.13-0.17 s without them). Every fgloc command, --help
included, pays that import, so it is checked here in a fresh interpreter; numpy too (0.07 s of
CPU, pulled in by the bench functions `fgloc bench` and `fgloc demo` call, until they were
imported inside those commands).  And `fgloc run` itself imports nothing it does not use.
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

HEAVY = ("numpy", "numba", "scipy", "gtsam", "open3d", "kiss_icp", "ray", "matplotlib", "foxglove", "mcap_ros2")


def test_cli_import_pulls_in_no_heavy_library() -> None:
    code = (
        "import json, sys\n"
        "import fgloc.cli  # noqa: F401\n"
        f"print(json.dumps([m for m in {HEAVY!r} if m in sys.modules]))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    loaded = json.loads(out.stdout.strip().splitlines()[-1])
    assert loaded == [], f"import fgloc.cli imported {loaded}: import them inside the command that needs them"


# what `fgloc run` (smoother + native) has no use for: plots, other front-ends' libraries, the
# cluster engine, tqdm when stderr is not a terminal (the bar is drawn on a terminal only: tqdm
# cost ~0.02 s of CPU to import), rich (its summary is plain lines: rich's
# console and table cost 0.030-0.038 s of CPU per run), the generic CDR codec (every input here has
# the fixed layouts of fgloc.io.fastcdr, the ground truth included)
# the live localizer (its config sections live in fgloc.live.config: composing the config imported
# the serial link, its protocol and threads, 0.012 s of CPU), the mcap package's record classes (the
# summary's chunk indexes and statistics are read with struct: 0.005 s), pydantic (typer's option coercion:
# fgloc.cli.PlainCoercion parses a command line's plain values)
NOT_FOR_RUN = ("matplotlib", "open3d", "kiss_icp", "ray", "tqdm", "rich", "mcap_ros2", "fgloc.live.app", "pydantic",
               "fgloc.live.serial_link", "mcap.records")


@pytest.mark.parametrize("quiet", [True, False], ids=["quiet", "progress"])
def test_fgloc_run_imports_only_what_it_uses(tmp_path, quiet: bool) -> None:
    from fgloc.sim import run_scenario, write_sim

    sim = run_scenario({"route": [[2.5, 3.0], [3.5, 3.0]], "laser": {"rate_hz": 10.0}}, seed=0)
    write_sim(sim, tmp_path / "log")
    code = (
        "import atexit, json, sys\n"
        f"atexit.register(lambda: print('LOADED ' + json.dumps([m for m in {NOT_FOR_RUN!r} if m in sys.modules])))\n"
        "from fgloc.cli import main\n"
        "sys.exit(main())\n"
    )
    log = tmp_path / "log"
    out = subprocess.run([sys.executable, "-c", code, "run", str(log / "log.mcap"), "--map", str(log / "map.yaml"),
                          "-o", str(tmp_path / "out"), *(["-q"] if quiet else [])], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    line = next(ln for ln in out.stdout.splitlines() if ln.startswith("LOADED "))
    assert json.loads(line[7:]) == [], f"fgloc run imported {line[7:]}: import them where they are used"
    assert (tmp_path / "out" / "trajectory.tum").exists()


def test_the_collector_paused_for_the_setup_only_in_a_command_process() -> None:
    import gc

    from fgloc.app.startup import pause_gc, resume_gc, setup_done

    frozen = gc.get_freeze_count()
    setup_done()  # a library caller: nothing was paused, nothing happens
    assert gc.isenabled() and gc.get_freeze_count() == frozen
    pause_gc()
    try:
        assert not gc.isenabled()
        keep = [[i] for i in range(100)]  # alive at the end of the set-up: frozen
        setup_done()
        assert gc.isenabled() and gc.get_freeze_count() >= frozen + len(keep)
        setup_done()  # once only
        assert gc.isenabled()
        pause_gc()
        resume_gc()  # the set-up failed: collection resumes, nothing more is frozen
        assert gc.isenabled() and gc.get_freeze_count() >= frozen + len(keep)
    finally:
        gc.enable()
        gc.unfreeze()
