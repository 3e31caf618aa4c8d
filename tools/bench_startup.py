#!/usr/bin/env python
"""Where ``fgloc run``'s start-up CPU goes: child processes, each one step more, medians of N.

Each row is a fresh Python process (``wait4``: user + system CPU), timed ``--repeats`` times in
turn (the machine's load drifts), Python's bytecode cache on as in an installed fgloc (in
``WORKDIR/pycache``); the "step" column is the row's median minus the previous row's, the cost
of what it adds:

* ``python -c pass``: the interpreter and site;
* ``import fgloc.cli``: typer and the command modules (every command, ``--help`` included);
* ``fgloc run`` parsed: its arguments through typer (the plain values without typer's pydantic
  coercion: ``fgloc.cli.PlainCoercion``), up to the command's first line;
* ``+ import numpy``, ``+ numba``, ``+ gtsam``, ``+ fgloc.localization`` (the localizer's
  modules, the back-ends, the map, the front-ends' numba functions defined);
* ``+ numba's first cached function``: a cached ``@njit`` function called once (numba's target
  set-up on first use: its registries, NRT, and scipy.linalg for its BLAS check);
* ``+ scipy.linalg`` (alone, after numba: what that BLAS check pulls in);
* ``fgloc run`` on the 2 s office log: the whole command (map, the matcher's distance field,
  the first global localization, outputs, summary).

    python tools/bench_startup.py -w WORKDIR [--repeats 5]

``WORKDIR`` holds the speed bench's logs (``fgloc bench speed -w WORKDIR`` makes them; made here
if missing), and the one-function numba module the first-use row calls (``WORKDIR/startup-numba``).
Nothing here asserts a speed.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
from pathlib import Path

STOP_AT_RUN = (  # fgloc run parsed by typer, stopped at the command's first line (pause_gc)
    "import sys\n"
    "import fgloc.app.startup as s\n"
    "def stop(*a, **k):\n"
    "    raise SystemExit(0)\n"
    "s.pause_gc = stop\n"
    "from fgloc.cli import main\n"
    "sys.exit(main(sys.argv[1:]))\n"
)

#: as fgloc.cli.main: no last cyclic collection over everything loaded at exit (a bare process's
#: exit would charge each row for collecting what it imported)
EXIT_AS_FGLOC = "import atexit, gc; atexit.register(gc.freeze)"

NUMBA_MODULE = "import numba\n@numba.njit(cache=True)\ndef f(x):\n    return x + 1.0\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("-w", "--workdir", type=Path, default=Path("fgloc-bench-speed"))
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args(argv)

    from fgloc.bench import speed

    work = args.workdir.resolve()
    work.mkdir(parents=True, exist_ok=True)
    speed.PYCACHE_PREFIX = work / "pycache"
    tiny = speed.make_logs(work, paper=False)["tiny"]
    env = speed.tree_env(None)
    nb = work / "startup-numba"  # the cached njit function's module (and numba's cache of it)
    nb.mkdir(exist_ok=True)
    (nb / "nbmod.py").write_text(NUMBA_MODULE)
    env_nb = dict(env, PYTHONPATH=str(nb) + os.pathsep + env.get("PYTHONPATH", ""))
    def py(c: str) -> list[str]:  # fgloc's exit (no final collection) before the row's own code
        return [sys.executable, "-c", f"{EXIT_AS_FGLOC}\n{c}"]

    run_args = ["run", str(tiny.log), "--map", str(tiny.map_yaml), "-o", str(work / "runs" / "startup"), "-q",
                "--force"]
    imports = "import fgloc.cli, numpy, numba, gtsam, fgloc.localization"
    rows: list[tuple[str, list[str], dict[str, str]]] = [
        ("python -c pass", py("pass"), env),
        ("import fgloc.cli", py("import fgloc.cli"), env),
        ("fgloc run parsed (typer)", py(STOP_AT_RUN) + run_args, env),
        ("+ import numpy", py("import fgloc.cli, numpy"), env),
        ("+ import numba", py("import fgloc.cli, numpy, numba"), env),
        ("+ import gtsam", py("import fgloc.cli, numpy, numba, gtsam"), env),
        ("+ import fgloc.localization", py(imports), env),
        ("+ numba's first cached function", py(f"{imports}, nbmod; nbmod.f(1.0)"), env_nb),
        ("  of which scipy.linalg", py(f"{imports}, scipy.linalg"), env),
        (f"fgloc run, {tiny.duration_s:.0f} s log (all of it)", speed.fgloc_argv() + run_args, env),
    ]
    speed.run_process(rows[7][1], env_nb)  # numba compiles nbmod.f into its cache once
    speed.run_process(rows[-1][1], env)  # numba's cache of fgloc's functions, the bytecode cache
    cpu: dict[str, list[float]] = {name: [] for name, _, _ in rows}
    load = [os.getloadavg()[0]]
    for _ in range(args.repeats):
        for name, argv_, env_ in rows:
            p = speed.run_process(argv_, env_)
            if p.returncode != 0:
                print(f"{name}: exit {p.returncode}: {p.err.strip()[-300:]}", file=sys.stderr)
                return 1
            cpu[name].append(p.cpu_s)
        load.append(os.getloadavg()[0])
    print("| start-up step | CPU (s), median [min-max] | step (s) |")
    print("|---|---|---|")
    prev = None
    for name, _, _ in rows:
        v = cpu[name]
        med = statistics.median(v)
        base = {"  of which scipy.linalg": "+ import fgloc.localization",
                "+ import numpy": "import fgloc.cli"}.get(name)
        ref = statistics.median(cpu[base]) if base else prev
        step = "" if ref is None or name.startswith("fgloc run, ") else f"{med - ref:+.3f}"
        print(f"| {name} | {med:.3f} [{min(v):.3f}-{max(v):.3f}] | {step} |")
        if not name.startswith("  "):
            prev = med
    print(f"\n{args.repeats} repeats; load average (1 min) {', '.join(f'{x:.1f}' for x in load)}; "
          f"{os.cpu_count()} CPUs")
    return 0


if __name__ == "__main__":
    sys.exit(main())
