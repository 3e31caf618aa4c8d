"""Silent wrong answers: each simulated failure class localized by each back-end and front-end, its
poses' errors against their statuses; one table.

    python tools/eval_integrity.py [--scenarios wheel_slip compass_disturbance changed_world blackout kidnap]
        [--seeds 0] [--backends smoother ekf] [--frontends native amcl] [--global] [--off-m 0.25]
        [--off-deg 3] [--config FILE] [--set KEY=VALUE ...] [--map-variant {mirror,shift,scale,other}]
        [--map-shift-m 1.5] [--initial-offset DX DY DYAW_DEG]

Each run is the shipped scenario (fgloc/config/scenarios/) localized from its true start pose (``--global``:
without one) as ``fgloc run`` does (a ``Localizer`` in a ``Session``; ``changed_world`` on the old map).
Per run: position RMSE and max error of the final trajectory, the largest pose step (the change of the
error between consecutive poses), the poses by status, the largest error of an ``ok`` pose and how many
``ok`` poses are more than ``--off-m`` off (a silent wrong answer: each must be accurate or marked
non-ok), the same for the heading (``--off-deg``: a laser yawed on its bracket moves the position little and
turns the heading), whether ``fgloc run`` would exit 3 (a finding that makes the run unusable, or more than
``integrity.max_bad_share`` of the poses suspect or lost), and after a teleport (kidnap) how long until the
online pose stays within 0.2 m (``fgloc.bench.kidnap_recovery``), and the run's verdicts (``fgloc run``'s
one-line findings; ``*``: one that makes the run unusable).

A scenario is a shipped one's name or a YAML file; ``--set`` overlays scenario keys on each (dotted
keys, YAML values: ``--set speed_mps=1.5 laser.rate_hz=5 drive=diff``).  Wrong inputs: ``--map-variant``
localizes on a map that is not the building's (``mirror``: mirrored left-right; ``shift``: its origin
moved ``--map-shift-m`` along x and y; ``scale``: its cells read at twice their size; ``other``: the
Willow Garage map, another building) and ``--initial-offset`` starts the localizer that far from the
true start pose (metres, metres, degrees).
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np
from tqdm import tqdm

SCENARIOS = ["wheel_slip", "compass_disturbance", "changed_world", "blackout", "kidnap"]


def wrong_map(occ, variant: str | None, shift_m: float = 1.5):
    """The simulated building's map made wrong (see the module's docstring); ``None``: the map itself."""
    from dataclasses import replace

    from fgloc.config import resource
    from fgloc.maps import load_map

    if variant is None:
        return occ
    if variant == "mirror":
        return replace(occ, data=occ.data[:, ::-1].copy())
    if variant == "shift":
        return replace(occ, origin=occ.origin + np.array([shift_m, shift_m, 0.0]))
    if variant == "scale":
        return replace(occ, resolution=2.0 * occ.resolution)
    if variant == "other":
        return load_map(str(resource("maps", "willow-2010-02-18-0.10.yaml")))
    raise SystemExit(f"unknown map variant {variant!r}")


def scenario(name: str, sets: list[str]) -> dict:
    """A shipped scenario (by name) or a YAML file, with ``KEY=VALUE`` overlays (dotted keys, YAML values)."""
    from pathlib import Path

    import yaml

    from fgloc.config import scenario_path
    from fgloc.sim import load_scenario

    sc = load_scenario(Path(name) if Path(name).is_file() else scenario_path(name))
    for kv in sets:
        key, _, value = kv.partition("=")
        *parents, leaf = key.split(".")
        d = sc
        for k in parents:
            d = d.setdefault(k, {})
        d[leaf] = yaml.safe_load(value)
    return load_scenario(sc)


def localize(sim, backend: str, frontend: str, global_start: bool, off_m: float, config: str | None = None,
             map_variant: str | None = None, initial_offset: tuple[float, float, float] = (0.0, 0.0, 0.0),
             map_shift_m: float = 1.5, off_deg: float = 3.0) -> dict:
    from fgloc.bench import kidnap_recovery
    from fgloc.config import load_config
    from fgloc.eval.metrics import position_errors_and_steps
    from fgloc.geometry import wrap_angle
    from fgloc.localization import Localizer, Session

    cfg = load_config(config)
    msgs = [(t, m) for t, m in sim.messages if t != "/ground_truth"]
    p0 = np.asarray(sim.ground_truth.poses[0], dtype=float) + np.array(
        [initial_offset[0], initial_offset[1], np.deg2rad(initial_offset[2])])
    p0[2] = float(wrap_angle(p0[2]))
    loc = Localizer(wrong_map(sim.map, map_variant, map_shift_m), sim.laser_mount, backend, frontend,
                    initial_pose=None if global_start else p0, config=cfg)
    t0 = time.perf_counter()
    est = Session(loc).run(msgs)
    wall = time.perf_counter() - t0
    err, step = position_errors_and_steps(est, sim.ground_truth)
    yaw_err = np.degrees(np.abs(wrap_angle(est.poses[:, 2] - sim.ground_truth.interpolate(est.stamps)[:, 2])))
    status, _ = loc.monitor.at(est.stamps)
    ok = np.array([s == "ok" for s in status], dtype=bool)
    summary = loc.stats["status"]
    unusable = any(v["unusable"] for v in summary["verdicts"])
    recovery = kidnap_recovery(sim, loc.online_trajectory()).get("recovery_s")
    course = None if loc.fix_course is None else loc.fix_course.offset()
    return {"rmse": float(np.sqrt(np.mean(err**2))), "max": float(err.max()),
            "step": float(step.max()) if len(step) else 0.0, "counts": loc.monitor.counts(est.stamps),
            "ok_max": float(err[ok].max()) if ok.any() else float("nan"), "ok_off": int(np.sum(err[ok] > off_m)),
            "ok_max_deg": float(yaw_err[ok].max()) if ok.any() else float("nan"),
            "ok_off_deg": int(np.sum(yaw_err[ok] > off_deg)),
            "exit3": unusable or summary["bad_share"] > cfg.integrity.max_bad_share, "wall": wall,
            "recovery_s": recovery,
            "course": "-" if course is None else f"{np.degrees(course[0]):+.2f} ({course[1]})",
            "verdicts": ", ".join(v["kind"] + ("*" if v["unusable"] else "") for v in summary["verdicts"])}


def main() -> None:
    from fgloc.sim import run_scenario

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", nargs="+", default=SCENARIOS)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--backends", nargs="+", default=["smoother", "ekf"])
    ap.add_argument("--frontends", nargs="+", default=["native", "amcl"])
    ap.add_argument("--global", dest="global_start", action="store_true", help="no initial pose")
    ap.add_argument("--off-m", type=float, default=0.25, help="an ok pose further off than this is a silent error")
    ap.add_argument("--off-deg", type=float, default=3.0, help="an ok pose's heading further off than this (deg) is "
                    "a silent error")
    ap.add_argument("--config", help="a configuration file over the defaults (as fgloc run --config)")
    ap.add_argument("--set", dest="sets", nargs="+", default=[], metavar="KEY=VALUE",
                    help="scenario keys over each scenario (dotted, YAML values)")
    ap.add_argument("--map-variant", choices=["mirror", "shift", "scale", "other"], help="a wrong map")
    ap.add_argument("--map-shift-m", type=float, default=1.5, help="the shift of --map-variant shift (m)")
    ap.add_argument("--initial-offset", type=float, nargs=3, default=[0.0, 0.0, 0.0], metavar=("DX", "DY", "DYAW"),
                    help="the initial pose this far from the truth (m, m, deg)")
    args = ap.parse_args()
    runs = [(s, seed, b, f) for s in args.scenarios for seed in args.seeds for b in args.backends
            for f in args.frontends]
    print(f"| scenario | seed | back-end | front-end | RMSE m | max m | largest step m | poses ok / degraded / "
          f"suspect / lost | ok poses' max error m | ok poses > {args.off_m} m off | ok poses' max heading error deg "
          f"| ok poses > {args.off_deg} deg off | exit 3 | kidnap recovered s | fixes' course deg (stretches) "
          "| verdicts |")
    print("|---|--:|---|---|--:|--:|--:|--:|--:|--:|--:|--:|---|--:|--:|---|")
    sims: dict[tuple[str, int], object] = {}
    for name, seed, backend, frontend in tqdm(runs, file=sys.stderr, desc="runs"):
        if (name, seed) not in sims:
            sims.clear()
            sims[(name, seed)] = run_scenario(scenario(name, args.sets), seed=seed)
        r = localize(sims[(name, seed)], backend, frontend, args.global_start, args.off_m, args.config,
                     args.map_variant, tuple(args.initial_offset), args.map_shift_m, args.off_deg)
        c = r["counts"]
        rec = "-" if r["recovery_s"] is None else f"{r['recovery_s']:.2f}"
        tqdm.write(f"| {name} | {seed} | {backend} | {frontend} | {r['rmse']:.4f} | {r['max']:.3f} | {r['step']:.3f} | "
                   f"{c['ok']} / {c['degraded']} / {c['suspect']} / {c['lost']} | {r['ok_max']:.3f} | {r['ok_off']} | "
                   f"{r['ok_max_deg']:.2f} | {r['ok_off_deg']} | "
                   f"{'yes' if r['exit3'] else 'no'} | {rec} | {r['course']} | {r['verdicts']} |", file=sys.stdout)
        sys.stdout.flush()


if __name__ == "__main__":
    main()
