#!/usr/bin/env python3
"""How honest the output covariance is: the NEES of each back-end's output poses, simulator and Radish.

    python tools/eval_nees.py [--backends smoother ekf] [--sim map odom blackout] [--seeds 0]
                              [--logs fr079 intel aces mit-csail] [--scans 800] [--cache DIR]
                              [--map-accuracy measured|none] [--skip-sim] [--skip-real] [--png nees.png]
                              [--set SECTION.KEY=VALUE ...]

For each run it gives the NEES (:func:`fgloc.eval.nees.nees_metrics`: ``e^T P^-1 e`` over (x, y,
yaw), 3 when the covariance is honest, 95 % of the poses inside 7.81) of three views of the output:

* ``output``: ``trajectory.tum``'s poses (the final, smoothed trajectory) with the covariance
  ``trajectory_status.csv`` gives them (the online covariance of the nearest online pose), as
  ``fgloc eval OUT/trajectory.tum GT --nees`` measures a ``fgloc run`` output;
* ``online``: the online estimate at each keyframe with its covariance, as it was known then;
* ``fused``: the poses the session publishes (``/fused_pose``: at each scan, and every 0.1 s of dead
  reckoning while the laser is silent), with their covariance.

The runs are built as ``fgloc run`` builds them (a session with a sink, so the fused pose's
covariance is refreshed every ``covariance_period_s``).  Simulator (``fgloc simulate paper``, default
front-end): ``map`` on its map from the true start; ``odom`` without a map (the estimate and its
covariance put on the truth's start pose: dead reckoning from a known start); ``blackout`` the
paper run with the laser silent for 30 s from t = 10 s (only the poses inside the silence are
counted for ``fused``: the dead-reckoning stretch).  Radish (``../shared/data/radish``): the
segments and maps of ``tools/eval_frontends_real.py`` (SLAM cached under ``--cache``), errors
against the SLAM trajectory (a reference, not ground truth: its own ~3 cm / 0.5 deg count too); each
map declares the accuracy ``fgloc map`` measures for its log (``--map-accuracy none``: undeclared).
"""

from __future__ import annotations

import argparse
import pickle
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tools"))

BLACKOUT = (10.0, 30.0)  # the silent laser's start and duration (s)
VIEWS = ("output", "online", "fused")


class FusedPoses:
    """A session sink keeping what ``/fused_pose`` carries: ``(stamp, pose, cov)`` at each scan and each
    dead-reckoned pose."""

    wants_fused = True
    wants_messages = False

    def __init__(self) -> None:
        self.rows: list[tuple[float, np.ndarray, np.ndarray]] = []

    def on_message(self, topic: str, msg: object) -> None:
        pass

    def on_scan(self, stamp: float, scan: Any, fix_or_reason: Any, fused: Any) -> None:
        if fused is not None:
            self.rows.append((float(fused.stamp), np.asarray(fused.pose, float), np.asarray(fused.cov, float)))

    def on_pose(self, stamp: float, fused: Any) -> None:
        self.rows.append((float(fused.stamp), np.asarray(fused.pose, float), np.asarray(fused.cov, float)))

    def close(self) -> None:
        pass

    def trajectory(self) -> Any:
        from fgloc.types import Trajectory

        rows: dict[float, tuple[np.ndarray, np.ndarray]] = {}
        for t, p, c in self.rows:
            rows[t] = (p, c)  # the last at a stamp
        ts = np.array(sorted(rows))
        return Trajectory(ts, np.array([rows[t][0] for t in ts]).reshape(-1, 3), covs=np.array(
            [rows[t][1] for t in ts]).reshape(-1, 3, 3))


def views(loc: Any, final: Any, sink: FusedPoses) -> dict[str, Any]:
    """The three trajectories with their covariances (see the module doc)."""
    from fgloc.localization.monitor import status_rows
    from fgloc.types import Trajectory

    online = loc.online_trajectory()
    rows = status_rows(final, online, loc.monitor)
    covs = np.array([[[r[5], r[6], r[7]], [r[6], r[8], r[9]], [r[7], r[9], r[10]]] for r in rows]).reshape(-1, 3, 3)
    return {"output": Trajectory(final.stamps, final.poses, covs=covs), "online": online, "fused": sink.trajectory()}


def on_start(tr: Any, gt: Any) -> Any:
    """``tr`` (odom frame, with covariances) put on the truth's pose at its first stamp."""
    from fgloc.geometry import compose, inverse
    from fgloc.types import Trajectory

    g0 = gt.interpolate(np.array([tr.stamps[0]]))[0]
    T = compose(g0, inverse(tr.poses[0]))
    c, s = np.cos(T[2]), np.sin(T[2])
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    covs = None if tr.covs is None else R @ np.asarray(tr.covs) @ R.T
    return Trajectory(tr.stamps, compose(T, tr.poses), covs=covs)


def measure(trs: dict[str, Any], gt: Any, window: tuple[float, float] | None = None) -> dict[str, Any]:
    """Each view's :class:`~fgloc.eval.nees.NeesMetrics` (``window``: ``fused`` only inside it) and the
    per-pose NEES of ``fused`` over time (for the figure)."""
    from fgloc.eval.nees import nees_metrics, pose_errors, pose_nees
    from fgloc.types import Trajectory

    out: dict[str, Any] = {}
    for name, tr in trs.items():
        if name == "fused" and window is not None:
            m = (tr.stamps > window[0]) & (tr.stamps < window[1])
            tr = Trajectory(tr.stamps[m], tr.poses[m], covs=tr.covs[m])
        if len(tr) == 0 or tr.covs is None:
            continue
        e, idx = pose_errors(tr, gt)
        c = np.asarray(tr.covs)[idx]
        out[name] = nees_metrics(e, c)
        if name == "fused":
            out["trace"] = (tr.stamps[idx], pose_nees(e, c))
    return out


def sim_run(case: str, backend: str, seed: int, config: Any) -> dict[str, Any]:
    from fgloc.localization import build_session
    from fgloc.sim import run_scenario, simulate_paper

    if case == "blackout":
        sim = run_scenario({"faults": {"laser_blackout": {"start": BLACKOUT[0], "duration": BLACKOUT[1]}}}, seed=seed)
    else:
        sim = simulate_paper(seed=seed)
    gt = sim.ground_truth
    msgs = [(t, m) for t, m in sim.messages if t != "/ground_truth"]
    sink = FusedPoses()
    occ = None if case == "odom" else sim.map
    pose0 = None if case == "odom" else gt.poses[0]
    session = build_session(occ, sim.laser_mount, backend=backend, initial_pose=pose0, config=config, sinks=[sink])
    tw = time.perf_counter()
    final = session.run(msgs)
    wall = time.perf_counter() - tw
    trs = views(session.loc, final, sink)
    if case == "odom":
        trs = {k: on_start(v, gt) for k, v in trs.items() if len(v)}
    window = (BLACKOUT[0] + 1.0, BLACKOUT[0] + BLACKOUT[1]) if case == "blackout" else None
    res = measure(trs, gt, window)
    res.update(run=f"sim {case} seed {seed}", backend=backend, wall_s=wall)
    return res


def real_run(name: str, backend: str, cache: Path, n_scans: int, config: Any, accuracy: str) -> dict[str, Any]:
    """One Radish segment on the map of the keyframes outside it (``tools/eval_frontends_real.py``), the
    map declaring ``accuracy``: ``measured`` (what ``fgloc map`` writes for the whole log) or ``none``."""
    import eval_frontends_real as efr  # type: ignore[import-not-found]

    from fgloc.io import open_log
    from fgloc.localization import Localizer, Session
    from fgloc.mapping.source import open_log_scan_stamps
    from fgloc.types import Trajectory

    recs, mount, slam = efr.slam_of(name, cache)
    key = cache / f"{name}_{n_scans}_map.pkl"
    if key.exists():
        s0, s1, cov, occ = pickle.loads(key.read_bytes())
    else:
        s0, s1, cov, occ = efr.segment_and_map(recs, mount, slam, n_scans)
        key.write_bytes(pickle.dumps((s0, s1, cov, occ)))
    occ.accuracy_m = efr.measured_accuracy(name, cache) if accuracy == "measured" else None
    t0, t1 = recs[s0].stamp, recs[s1].stamp
    msgs = [(topic, m) for topic, m in open_log(efr.LOGS[name]).messages(["/odom", "/scan"])
            if t0 - 1e-6 <= m.stamp <= t1 + 1e-6]  # type: ignore[attr-defined]
    own = np.array([r.stamp for r in recs])
    scan_t = open_log_scan_stamps(efr.LOGS[name], recs)
    ref = Trajectory.from_unsorted(scan_t, slam.scan_trajectory.interpolate(own))
    p0 = ref.interpolate(np.array([t0]))[0]
    loc = Localizer(occ, mount, backend, "native", initial_pose=p0, config=config)
    sink = FusedPoses()
    tw = time.perf_counter()
    final = Session(loc, sinks=[sink]).run(msgs)
    wall = time.perf_counter() - tw
    res = measure(views(loc, final, sink), ref)
    acc = "" if occ.accuracy_m is None else f", accuracy {occ.accuracy_m:g} m"
    res.update(run=f"{name} {s0}-{s1} ({100 * cov:.0f} % mapped{acc})", backend=backend, wall_s=wall)
    return res


def cell(m: Any) -> str:
    if m is None or not m.n:
        return "-"
    return (f"{m.nees_mean:.2f} ({m.nees_median:.2f}) {100 * m.inside_95:.0f} % | "
            f"{m.nees_x:.2f} / {m.nees_y:.2f} / {m.nees_yaw:.2f}")


def table(rows: list[dict[str, Any]]) -> None:
    print("\nNEES mean (median) share inside 7.81 | per axis x / y / yaw (3 (2.37) 95 % | 1 / 1 / 1 when honest)\n")
    head = " | ".join(f"{v} NEES | {v} x / y / yaw" for v in VIEWS)
    print(f"| run | back-end | {head} | pos RMSE m / hdg deg (output) | sigma x/y m / yaw deg (median) |")
    print("|---|---|" + "--:|" * (2 * len(VIEWS) + 2))
    for r in rows:
        o = r.get("output")
        extra = (f"{o.position_rmse_m:.4f} / {o.heading_rmse_deg:.3f} | {o.sigma_xy_med_m:.4f} / "
                 f"{o.sigma_yaw_med_deg:.3f}") if o is not None and o.n else "- | -"
        print(f"| {r['run']} | {r['backend']} | " + " | ".join(cell(r.get(v)) for v in VIEWS) + f" | {extra} |")


def figure(rows: list[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fgloc.eval.nees import CHI2_3DOF_95

    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(11, 8))
    labels = [f"{r['run']}\n{r['backend']}" for r in rows]
    x = np.arange(len(rows))
    for k, (v, mk) in enumerate(zip(VIEWS, ("o", "s", "^"), strict=True)):
        y = [r[v].nees_mean if v in r and r[v].n else np.nan for r in rows]
        ax.scatter(x + 0.15 * (k - 1), y, marker=mk, label=v)
    ax.axhline(3.0, color="k", lw=1, label="3 (honest)")
    ax.axhspan(1.0, 9.0, color="g", alpha=0.08, label="band 1-9")
    ax.set_yscale("log")
    ax.set_xticks(x, labels, fontsize=7, rotation=30, ha="right")
    ax.set_ylabel("mean NEES")
    ax.legend(fontsize=8)
    ax.set_title("NEES of the output poses (x, y, yaw)")
    for r in rows:
        if "trace" in r and r["run"].startswith("sim blackout"):
            t, v = r["trace"]
            ax2.semilogy(t, v, lw=0.8, label=f"{r['backend']} ({r['run']})")
    ax2.axhline(CHI2_3DOF_95, color="k", lw=1, ls="--", label="chi-square 95 % (7.81)")
    ax2.set_xlabel("t (s)")
    ax2.set_ylabel("NEES of the published pose")
    ax2.set_title(f"laser silent {BLACKOUT[0]:.0f}-{sum(BLACKOUT):.0f} s: the dead-reckoned poses")
    ax2.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--backends", nargs="+", default=["smoother", "ekf"])
    ap.add_argument("--sim", nargs="+", default=["map", "odom", "blackout"], choices=["map", "odom", "blackout"])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--logs", nargs="+", default=["fr079", "intel", "aces", "mit-csail"])
    ap.add_argument("--scans", type=int, default=800, help="Radish segment length (scans)")
    ap.add_argument("--cache", type=Path, default=Path("eval_frontends_real"), help="SLAM results and maps")
    ap.add_argument("--map-accuracy", choices=["measured", "none"], default="measured",
                    help="the Radish maps' declared accuracy_m: as fgloc map writes it, or undeclared")
    ap.add_argument("--skip-sim", action="store_true")
    ap.add_argument("--skip-real", action="store_true")
    ap.add_argument("--png", type=Path, default=None, help="write the figure here")
    ap.add_argument("--set", nargs="*", default=[], metavar="SECTION.KEY=VALUE", help="configuration overrides")
    a = ap.parse_args(argv)
    import yaml
    from tqdm import tqdm

    from fgloc.config import load_config

    overrides: dict = {}
    for item in a.set:
        key, _, val = item.partition("=")
        sec, _, opt = key.partition(".")
        overrides.setdefault(sec, {})[opt] = yaml.safe_load(val)
    config = load_config(overrides=overrides or None)
    import eval_frontends_real as efr

    tasks: list[tuple[str, str, Any]] = []
    if not a.skip_sim:
        tasks += [("sim", be, (case, seed)) for case in a.sim for seed in a.seeds for be in a.backends]
    if not a.skip_real:
        a.cache.mkdir(parents=True, exist_ok=True)
        for name in a.logs:
            if name not in efr.LOGS or not efr.LOGS[name].exists():
                print(f"{name}: no such Radish log here, skipped", file=sys.stderr)
                continue
            tasks += [("real", be, name) for be in a.backends]
    rows = []
    t0 = time.perf_counter()
    for kind, be, what in tqdm(tasks, desc="runs", file=sys.stderr):
        rows.append(sim_run(what[0], be, what[1], config) if kind == "sim" else
                    real_run(what, be, a.cache, a.scans, config, a.map_accuracy))
    table(rows)
    print(f"\n{len(rows)} runs in {time.perf_counter() - t0:.0f} s")
    if a.png is not None:
        figure(rows, a.png)
        print(f"figure: {a.png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
