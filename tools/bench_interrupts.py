"""Ctrl-C at random points of a command, many times: how each run ended.

    python tools/bench_interrupts.py LOG [--runs 41] [--command map|run] [--max-delay 12] [--fgloc PATH]

Starts ``fgloc map LOG -o TMP`` (or ``fgloc run LOG -o TMP``) ``--runs`` times, sends one SIGINT
after a uniform random delay in [0.5, --max-delay] s (seeded: the same delays each time), and
prints one line per run (exit code, the last stderr line) and the counts by outcome: ``130``
(a clean interrupted exit), ``0`` (finished first), or what went wrong (a traceback, a
SystemError, a signal death).  ``--fgloc``: another installation's ``fgloc`` (e.g. an older
commit's, to compare).
"""

from __future__ import annotations

import argparse
import collections
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def outcome(rc: int, err: str) -> str:
    if "Traceback" in err or "SystemError" in err:
        kind = "SystemError" if "SystemError" in err else err.strip().splitlines()[-1].split(":")[0]
        return f"rc {rc}, traceback ({kind})"
    if rc < 0:
        return f"killed by {signal.Signals(-rc).name}"
    return f"rc {rc}"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("log")
    ap.add_argument("--runs", type=int, default=41)
    ap.add_argument("--command", choices=("map", "run"), default="map")
    ap.add_argument("--max-delay", type=float, default=12.0)
    ap.add_argument("--fgloc", default=str(Path(sys.executable).parent / "fgloc"))
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    rng = random.Random(a.seed)
    counts: collections.Counter[str] = collections.Counter()
    work = Path(tempfile.mkdtemp(prefix="fgloc-interrupts-"))
    try:
        for i in range(a.runs):
            out = work / f"out{i}"
            p = subprocess.Popen([a.fgloc, a.command, a.log, "-o", str(out)], stdout=subprocess.DEVNULL,
                                 stderr=subprocess.PIPE, text=True,
                                 preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
            delay = rng.uniform(0.5, a.max_delay)
            time.sleep(delay)
            p.send_signal(signal.SIGINT)
            _, err = p.communicate()
            kind = outcome(p.returncode, err)
            counts[kind] += 1
            last = err.strip().splitlines()[-1][:120] if err.strip() else ""
            print(f"{i:3d}  {delay:5.1f} s  {kind:32s}  {last}", flush=True)
            shutil.rmtree(out, ignore_errors=True)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    print(f"{a.runs} runs: " + ", ".join(f"{k}: {n}" for k, n in counts.most_common()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
