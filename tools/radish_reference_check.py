"""How much of the relation error against the GMapping-corrected Radish references is the reference's?

    python tools/radish_reference_check.py EVALDIR [--datasets fr079 intel]

EVALDIR is an ``eval_radish.py --out`` directory (``<name>/trajectory.tum`` and
``<name>/reference.tum``).  For every relation (the same ones as eval_radish) it prints the
relation errors of our trajectory split into local and loop-closure relations, those of the raw
wheel odometry, and a third opinion: a direct scan-to-scan match of the relation's two raw scans
(1 cm distance field, every return, Gauss-Newton started at the *reference's* delta, so any bias
favours the reference; kept when >= 80 % of the points are inliers in both directions).  The
forward/backward inconsistency of that match bounds its own noise.  The ten worst relations are
listed with what odometry and the scan-to-scan match say about them.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import eval_radish as er  # noqa: E402

from fgloc.eval.relations import relation_errors, relations_from_reference  # noqa: E402
from fgloc.geometry import between, transform_points, wrap_angle  # noqa: E402
from fgloc.io.tum import read_tum  # noqa: E402
from fgloc.mapping.build import load_records  # noqa: E402
from fgloc.mapping.occupancy import scan_endpoints  # noqa: E402
from fgloc.mapping.scanmatch import build_distance_grid, refine  # noqa: E402
from fgloc.types import Trajectory  # noqa: E402


def _stats(label: str, t: np.ndarray, r: np.ndarray) -> None:
    rd = np.degrees(r)
    print(f"  {label:16s} n={len(t):5d}  {t.mean():.3f} +- {t.std():.3f} m (median {np.median(t):.3f})  "
          f"{rd.mean():.2f} +- {rd.std():.2f} deg (median {np.median(rd):.2f}, p90 {np.percentile(rd, 90):.2f},"
          f" max {rd.max():.2f})")


def check(name: str, evaldir: Path) -> None:
    recs, mount = load_records(er.LOGS[name])
    est = read_tum(evaldir / name / "trajectory.tum")
    ref = read_tum(evaldir / name / "reference.tum")
    rels = relations_from_reference(ref, *er.REL_DT[name])
    st = np.array([r.stamp for r in recs])
    odo = Trajectory.from_unsorted(st, np.array([r.odom for r in recs]))
    loop = np.array([r.t2 - r.t1 > er.REL_DT[name][1] + 1e-6 for r in rels])
    te, re_, _ = relation_errors(est, rels)
    to, ro, _ = relation_errors(odo, rels)
    print(f"{name}: relation errors vs the reference")
    _stats("ours, all", te, re_)
    _stats("ours, local", te[~loop], re_[~loop])
    _stats("ours, loop", te[loop], re_[loop])
    _stats("odometry, local", to[~loop], ro[~loop])
    mnt = np.asarray(mount.pose, dtype=float)

    def pts(i: int) -> np.ndarray:
        sc = recs[i].scan
        p, hit = scan_endpoints(sc.ranges, sc.angles, sc.range_min, sc.range_max, 25.0, 8.0)
        return transform_points(mnt, p[hit])

    def near(q: float) -> int:
        return int(np.argmin(np.abs(st - q)))

    def s2s(k: int) -> tuple[np.ndarray, float, float]:
        a, b = near(rels[k].t1), near(rels[k].t2)
        fw = refine(build_distance_grid(pts(a), 0.01, 0.2, 0.5), pts(b), rels[k].delta, 0.02, 30)
        bw = refine(build_distance_grid(pts(b), 0.01, 0.2, 0.5), pts(a), between(fw.pose, np.zeros(3)), 0.02, 30)
        return fw.pose, min(fw.inlier_frac, bw.inlier_frac), float(abs(wrap_angle(fw.pose[2] + bw.pose[2])))

    def d_est(k: int) -> np.ndarray:
        return between(est.interpolate(rels[k].t1)[0], est.interpolate(rels[k].t2)[0])

    for label, sel in (("local", np.nonzero(~loop)[0][:: max(1, int((~loop).sum()) // 600)]),
                       ("loop", np.nonzero(loop)[0])):
        rows = []
        for k in sel:
            pose, inl, incons = s2s(int(k))
            if inl < 0.8:
                continue
            rows.append((abs(wrap_angle(pose[2] - rels[k].delta[2])), abs(wrap_angle(pose[2] - d_est(int(k))[2])),
                         incons))
        if not rows:
            continue
        a = np.degrees(np.array(rows))
        print(f"  scan-to-scan, {label} ({len(rows)} relations): |ref - s2s| yaw mean {a[:, 0].mean():.2f} "
              f"median {np.median(a[:, 0]):.2f} deg; |ours - s2s| mean {a[:, 1].mean():.2f} median "
              f"{np.median(a[:, 1]):.2f} deg; s2s forward/backward inconsistency {a[:, 2].mean():.2f} deg")
    print("  worst relations (yaw, deg):")
    for k in np.argsort(-re_)[:10]:
        r = rels[int(k)]
        a, b = near(r.t1), near(r.t2)
        pose, inl, _ = s2s(int(k))
        print(f"    t1 {r.t1:.2f} dt {r.t2 - r.t1:5.1f} s: ref {np.degrees(r.delta[2]):7.2f} ours "
              f"{np.degrees(d_est(int(k))[2]):7.2f} odometry {np.degrees(between(recs[a].odom, recs[b].odom)[2]):7.2f}"
              f" s2s(from ref) {np.degrees(pose[2]):7.2f} (inliers {inl:.2f})")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("evaldir", type=Path)
    ap.add_argument("--datasets", nargs="+", default=["fr079", "intel"])
    args = ap.parse_args()
    for name in args.datasets:
        check(name, args.evaldir)
    return 0


if __name__ == "__main__":
    sys.exit(main())
