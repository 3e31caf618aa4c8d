#!/usr/bin/env python
"""``fgloc map-check`` (localization mode) on real logs that match their maps: what a good run gives.

Each Radish log is mapped by ``fgloc map`` (once, kept under ``--out``) and checked against that map
with the mapping run's own trajectory; ``--log LOG MAP TRAJ`` adds any other run (e.g. a TurtleBot4
rosbag2, its floor map and the trajectory ``fgloc run`` wrote).  One line per log: the verdict, the
change regions (how many minor), the largest share of returns of a region and where it is.

    python tools/eval_map_check.py [--out eval_map_check] [--datasets intel fr079 aces mit-csail]
                                   [--log LOG MAP.yaml TRAJ.tum ...]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from fgloc.io.tum import read_tum
from fgloc.mapping.build import build_map, load_records
from fgloc.mapping.selfcheck import CheckConfig, check_against_map
from fgloc.mapping.slam import MapperConfig
from fgloc.maps import OccupancyMap

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "radish"


def check(name: str, log: Path, map_yaml: Path, traj: Path) -> str:
    recs, mount = load_records(log)
    res = check_against_map(recs, np.asarray(mount.pose), read_tum(traj), OccupancyMap.load(map_yaml), CheckConfig())
    top = max(res.changes, key=lambda c: c.share, default=None)
    where = "" if top is None else (f"; largest {100 * top.share:.1f} % ({top.kind} at ({top.center[0]:.1f}, "
                                    f"{top.center[1]:.1f}) m)")
    n_minor = sum(not c.major for c in res.changes)
    return f"{name:12s} {'pass' if res.passed else 'FAIL'}  {len(res.changes)} regions, {n_minor} minor{where}"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=Path("eval_map_check"))
    ap.add_argument("--datasets", nargs="*", default=["intel", "fr079", "aces", "mit-csail"])
    ap.add_argument("--log", nargs=3, action="append", default=[], metavar=("LOG", "MAP", "TRAJ"))
    args = ap.parse_args()
    for name in args.datasets:
        log = DATA / f"{name}.clf.bz2"
        if not log.is_file():
            print(f"{name:12s} skipped: {log} not found")
            continue
        out = args.out / name
        if not (out / "map.yaml").is_file():
            build_map(log, out, MapperConfig(), self_check=False)
        print(check(name, log, out / "map.yaml", out / "trajectory.tum"), flush=True)
    for log, map_yaml, traj in args.log:
        print(check(Path(log).name, Path(log), Path(map_yaml), Path(traj)), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
