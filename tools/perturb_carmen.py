"""A perturbed copy of a CARMEN log, to see whether a mapper's result is fragile.

    python tools/perturb_carmen.py aces.clf.bz2 OUT.clf [--jitter-mm 1 --seed 8] [--drop K]
                                   [--sort-ipc] [--no-odom]

``--jitter-mm``: Gaussian noise on every FLASER range (written with 4 decimals; the no-return value
and ranges <= 0 kept); ``--drop K``: start at the K-th FLASER line; ``--sort-ipc``: lines sorted by
their ipc stamp (stable); ``--no-odom``: no ODOM lines (the odometry is then the FLASER lines'
poses).  Issue 13's ACES inconsistency (relations metres off between two passes) is one such
fragile outcome of the filing-day mapper: 4 of 36 jitter seeds of 1 mm (docs/results/radish_table.md).
"""

from __future__ import annotations

import argparse
import bz2
from pathlib import Path

import numpy as np

NO_RETURN_M = 50.0  # the Radish logs' max-range value, kept as it is


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("src", type=Path)
    ap.add_argument("dst", type=Path)
    ap.add_argument("--jitter-mm", type=float, default=0.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--drop", type=int, default=0, help="drop every line before the K-th FLASER line")
    ap.add_argument("--sort-ipc", action="store_true")
    ap.add_argument("--no-odom", action="store_true", help="drop ODOM lines (odometry from the FLASER poses)")
    a = ap.parse_args()
    if a.dst.resolve() == a.src.resolve():
        raise SystemExit(f"perturb_carmen: error: {a.dst}: the output would overwrite the input")
    rng = np.random.default_rng(a.seed)
    opener = bz2.open if a.src.suffix == ".bz2" else open
    with opener(a.src, "rt") as f:
        lines = f.read().splitlines()
    head = [ln for ln in lines if ln.startswith(("#", "PARAM"))]
    body = [ln for ln in lines if not ln.startswith(("#", "PARAM"))]
    if a.no_odom:
        body = [ln for ln in body if not ln.startswith("ODOM")]
    if a.drop:
        idx = [i for i, ln in enumerate(body) if ln.startswith("FLASER")]
        body = body[idx[a.drop]:]
    out = []
    for ln in body:
        t = ln.split()
        if t and t[0] == "FLASER" and a.jitter_mm > 0:
            n = int(t[1])
            r = np.array(t[2:2 + n], dtype=float)
            j = r + rng.normal(0.0, a.jitter_mm / 1000.0, n)
            keep = (r >= NO_RETURN_M) | (r <= 0)
            j[keep] = r[keep]
            t[2:2 + n] = [f"{v:.2f}" if k else f"{v:.4f}" for v, k in zip(j, keep, strict=True)]
            ln = " ".join(t)
        out.append(ln)
    if a.sort_ipc:
        out = sorted(out, key=lambda ln: float(ln.split()[-3]))
    a.dst.write_text("\n".join(head + out) + "\n")
    print(f"{a.dst}: {len(out)} lines")


if __name__ == "__main__":
    main()
