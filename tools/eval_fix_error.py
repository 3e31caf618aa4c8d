#!/usr/bin/env python3
"""What a front-end's fix error is made of, on the simulated scenes (the same-AMCL bench's runs).

    python tools/eval_fix_error.py [--scenes paper willow obstacles] [--seeds 3] [--frontend amcl]
                                   [--backend smoother] [--config C.yaml] [--scene-set KEY=YAML ...]

Per scene and seed it localizes the simulated run (``tools/eval_amcl_ratio.py``'s ``simulate``),
takes the fixes the back-end accepted and splits each one's error against the truth in the true
robot frame: along-track (ahead +), cross-track (left +) and heading.  It prints, per run and
pooled over the runs:

* the RMSE of each part and its mean (bias);
* the autocorrelation at lags of 1 / 5 / 25 fixes, and the share of the position error's variance
  left after a centred moving average of 2 / 8 s (the slow part no averaging over that long removes);
* the correlation of the position error's size with the speed, the turn rate, the odometry's slip
  (the wheels' increment since the last fix against the truth's) and the fix's own sigma (AMCL's
  refined fit / particle cloud: ``sqrt(trace)`` of the position block);
* the heading-coupled part: the position error explained by the heading error through the
  covariance's own regression (``cov_xy_yaw / cov_yaw_yaw``, the shift the fix itself says goes with
  a heading error) and by a least-squares fit;
* place: the correlation of the errors of fix pairs taken at nearly the same pose (< 5 cm, < 3 deg)
  but more than 10 s apart (a map-fixed error repeats there, a slowly drifting one does not);
* the back-end's output against the truth, and against the fixes' error averaged over 2 / 8 s: how
  much of its residual is the fixes' slow error (what no weighting of these fixes removes).

``--scene-set`` overrides scenario keys (e.g. ``map_changes=[]``, ``map_resolution_m=0.025``): which
part of the error the furniture moved since mapping and the map's raster make.  A table of the runs
closes the output.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

LAGS = (1, 5, 25)
WINDOWS_S = (2.0, 8.0)


def moving_average(t: np.ndarray, x: np.ndarray, width_s: float) -> np.ndarray:
    """Centred moving average of ``x`` (rows at times ``t``) over ``width_s``."""
    out = np.empty_like(x)
    lo = np.searchsorted(t, t - width_s / 2, "left")
    hi = np.searchsorted(t, t + width_s / 2, "right")
    c = np.vstack([np.zeros((1, x.shape[1])), np.cumsum(x, axis=0)])
    for i in range(len(t)):
        out[i] = (c[hi[i]] - c[lo[i]]) / (hi[i] - lo[i])
    return out


def autocorr(x: np.ndarray, lag: int) -> float:
    x = x - x.mean()
    if len(x) <= lag or not np.any(x):
        return float("nan")
    return float(np.sum(x[:-lag] * x[lag:]) / np.sum(x * x))


def corr(a: np.ndarray, b: np.ndarray) -> float:
    if np.std(a) == 0 or np.std(b) == 0:
        return float("nan")
    return float(np.corrcoef(a, b)[0, 1])


def rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def info_weighted_rmse(t: np.ndarray, e: np.ndarray, cov: np.ndarray, width_s: float) -> float:
    """RMSE of the fixes' errors averaged over a centred ``width_s`` window, each weighted by its
    inverse covariance (what a back-end weighing independent fixes by their covariance reaches
    over that horizon)."""
    info = np.linalg.inv(cov)
    ie = np.einsum("nij,nj->ni", info, e)
    lo = np.searchsorted(t, t - width_s / 2, "left")
    hi = np.searchsorted(t, t + width_s / 2, "right")
    ci = np.concatenate([np.zeros((1, 2, 2)), np.cumsum(info, axis=0)])
    cb = np.vstack([np.zeros((1, 2)), np.cumsum(ie, axis=0)])
    avg = np.array([np.linalg.solve(ci[h] - ci[lo_], cb[h] - cb[lo_]) for lo_, h in zip(lo, hi, strict=True)])
    return rms(np.hypot(avg[:, 0], avg[:, 1]))


def decompose(sim: Any, loc: Any, final: Any) -> dict[str, Any]:
    """Per-fix error parts and their statistics for one run (see the module's doc)."""
    from fgloc.eval.metrics import track_errors
    from fgloc.geometry import wrap_angle

    gt = sim.ground_truth
    fx = [f for f in loc.fixes if gt.stamps[0] <= f.stamp <= gt.stamps[-1]]
    t = np.array([f.stamp for f in fx])
    p = np.array([np.asarray(f.pose, dtype=float) for f in fx])
    cov = np.array([np.asarray(f.cov, dtype=float) for f in fx])
    g = gt.interpolate(t)
    along, cross, e = track_errors(p, g)
    dt = 0.05
    ga, gb = gt.interpolate(t - dt), gt.interpolate(t + dt)
    speed = np.hypot(gb[:, 0] - ga[:, 0], gb[:, 1] - ga[:, 1]) / (2 * dt)
    turn = np.abs(wrap_angle(gb[:, 2] - ga[:, 2])) / (2 * dt)
    # the wheels' increment since the previous fix against the truth's (in the robot frame)
    od = np.array([(m.stamp, *np.asarray(m.pose, dtype=float)) for tp, m in sim.messages
                   if tp == "/odom" and getattr(m, "pose", None) is not None])
    from fgloc.geometry import between1 as relative

    def at(tt: np.ndarray) -> np.ndarray:
        yaw = np.unwrap(od[:, 3])
        return np.column_stack([np.interp(tt, od[:, 0], od[:, 1]), np.interp(tt, od[:, 0], od[:, 2]),
                                np.interp(tt, od[:, 0], yaw)])

    o = at(t)
    slip = np.zeros(len(t))
    for i in range(1, len(t)):
        d_odo = relative(o[i - 1], o[i])
        d_gt = relative(g[i - 1], g[i])
        slip[i] = float(np.hypot(d_odo[0] - d_gt[0], d_odo[1] - d_gt[1]))
    sig = np.sqrt(cov[:, 0, 0] + cov[:, 1, 1])
    pos = np.hypot(along, cross)
    # heading-coupled: the covariance's regression of position on heading, in the map frame
    k_cov = cov[:, :2, 2] / np.maximum(cov[:, 2:3, 2], 1e-18)
    coupled = k_cov * e[:, 2:3]
    resid = e[:, :2] - coupled
    ab_along = float(np.sum(e[:, 2] * along) / max(np.sum(e[:, 2] ** 2), 1e-18))
    ab_cross = float(np.sum(e[:, 2] * cross) / max(np.sum(e[:, 2] ** 2), 1e-18))
    # place: pairs of fixes at nearly the same pose more than 10 s apart
    pairs = []
    for i in range(len(t)):
        j = np.nonzero((t > t[i] + 10.0) & (np.hypot(g[:, 0] - g[i, 0], g[:, 1] - g[i, 1]) < 0.05)
                       & (np.abs(wrap_angle(g[:, 2] - g[i, 2])) < np.radians(3.0)))[0]
        pairs.extend((i, int(jj)) for jj in j[:3])
    place = float("nan")
    if len(pairs) >= 10:
        pi = np.array(pairs)
        place = corr(np.concatenate([along[pi[:, 0]], cross[pi[:, 0]]]),
                     np.concatenate([along[pi[:, 1]], cross[pi[:, 1]]]))
    # the back-end's output at the fixes' stamps, and the fixes' slow error
    ft = np.asarray(final.stamps, dtype=float)
    inside = (t >= ft[0]) & (t <= ft[-1])
    fo = final.interpolate(t[inside]) - g[inside]
    fo[:, 2] = wrap_angle(fo[:, 2])
    slow = {w: moving_average(t, e[:, :2], w) for w in WINDOWS_S}
    # by the fix's own sigma (thirds): RMSE and the position NEES (2 when the covariance is honest)
    q = np.quantile(sig, [1 / 3, 2 / 3])
    terciles = []
    for lo, hi in ((-np.inf, q[0]), (q[0], q[1]), (q[1], np.inf)):
        m = (sig >= lo) & (sig < hi)
        n2 = np.mean([ee @ np.linalg.solve(cc[:2, :2], ee) for ee, cc in zip(e[m, :2], cov[m], strict=True)])
        terciles.append((float(np.median(sig[m])), rms(pos[m]), float(n2)))
    out: dict[str, Any] = {
        "terciles": terciles,
        "weighted_slow8": info_weighted_rmse(t, e[:, :2], cov[:, :2, :2], 8.0),
        "n": len(t), "along": along, "cross": cross, "yaw": e[:, 2], "pos": pos, "t": t,
        "speed": speed, "turn": turn, "slip": slip, "sig": sig, "pairs": len(pairs), "place": place,
        "coupled_rmse": float(np.sqrt(np.mean(np.sum(coupled**2, axis=1)))),
        "resid_rmse": float(np.sqrt(np.mean(np.sum(resid**2, axis=1)))),
        "ls_m_per_rad": (ab_along, ab_cross),
        "ls_rmse": float(np.sqrt(np.mean((along - ab_along * e[:, 2]) ** 2 + (cross - ab_cross * e[:, 2]) ** 2))),
        "nees": float(np.mean([ee @ np.linalg.solve(cc, ee) for ee, cc in zip(e, cov, strict=True)])),
        "out_rmse": float(np.sqrt(np.mean(np.sum(fo[:, :2] ** 2, axis=1)))),
    }
    for w, sl in slow.items():
        out[f"slow{w:g}_rmse"] = float(np.sqrt(np.mean(np.sum(sl**2, axis=1))))
        out[f"out_minus_slow{w:g}"] = float(np.sqrt(np.mean(np.sum((fo[:, :2] - sl[inside]) ** 2, axis=1))))
        out[f"out_corr_slow{w:g}"] = corr(fo[:, :2].ravel(), sl[inside].ravel())
    return out


def report(label: str, r: dict[str, Any]) -> list[str]:
    a, cr, y, pos = r["along"], r["cross"], r["yaw"], r["pos"]
    lines = [f"{label}: {r['n']} fixes, position RMSE {1000 * rms(pos):.2f} mm, heading {np.degrees(rms(y)):.3f} deg, "
             f"NEES {r['nees']:.2f}"]
    lines.append(f"  along mean {1000 * a.mean():+.2f} rms {1000 * rms(a):.2f} mm | cross mean {1000 * cr.mean():+.2f} "
                 f"rms {1000 * rms(cr):.2f} mm | heading mean {np.degrees(y.mean()):+.4f} deg")
    lines.append("  autocorrelation at " + " / ".join(str(k) for k in LAGS) + " fixes: along "
                 + " / ".join(f"{autocorr(a, k):.2f}" for k in LAGS) + ", cross "
                 + " / ".join(f"{autocorr(cr, k):.2f}" for k in LAGS) + ", heading "
                 + " / ".join(f"{autocorr(y, k):.2f}" for k in LAGS))
    lines.append("  corr of |position error| with speed {:.2f}, turn rate {:.2f}, odometry slip {:.2f}, "
                 "fix sigma {:.2f}; |along| with speed {:.2f}; |cross| with turn {:.2f}".format(
                     corr(pos, r["speed"]), corr(pos, r["turn"]), corr(pos, r["slip"]), corr(pos, r["sig"]),
                     corr(np.abs(a), r["speed"]), corr(np.abs(cr), r["turn"])))
    lines.append(f"  heading-coupled (the fix covariance's regression): {1000 * r['coupled_rmse']:.2f} mm, rest "
                 f"{1000 * r['resid_rmse']:.2f} mm; least squares along / cross {r['ls_m_per_rad'][0]:+.3f} / "
                 f"{r['ls_m_per_rad'][1]:+.3f} m/rad, rest {1000 * r['ls_rmse']:.2f} mm")
    lines.append("  by the fix's sigma (thirds): median sigma / RMSE / position NEES (2 honest): " + ", ".join(
        f"{1000 * sg:.1f} / {1000 * er:.2f} mm / {n2:.2f}" for sg, er, n2 in r["terciles"]))
    lines.append(f"  same place > 10 s apart: {r['pairs']} pairs, error correlation {r['place']:.2f}")
    lines.append("  slow part (centred mean over " + " / ".join(f"{w:g}" for w in WINDOWS_S) + " s): "
                 + " / ".join(f"{1000 * r[f'slow{w:g}_rmse']:.2f}" for w in WINDOWS_S)
                 + f" mm (8 s weighted by the fixes' covariance: {1000 * r['weighted_slow8']:.2f} mm); back-end output "
                 f"{1000 * r['out_rmse']:.2f} mm, output minus slow part "
                 + " / ".join(f"{1000 * r[f'out_minus_slow{w:g}']:.2f}" for w in WINDOWS_S) + " mm, correlation "
                 + " / ".join(f"{r[f'out_corr_slow{w:g}']:.2f}" for w in WINDOWS_S))
    return lines


def simulate_with(scene: str, seed: int, overrides: dict[str, Any]) -> Any:
    """``eval_amcl_ratio.simulate`` with scenario keys overridden."""
    from eval_amcl_ratio import simulate

    if not overrides:
        return simulate(scene, seed)
    import yaml

    from fgloc.config import scenario_path
    from fgloc.sim.simulate import run_scenario

    sc: dict[str, Any] = {}
    if scene != "paper":
        sc = yaml.safe_load(scenario_path(scene).read_text())
    sc.update(overrides)
    return run_scenario(sc, seed=seed)


def table_row(scene: str, seed: int, r: dict[str, Any]) -> str:
    a, cr, y, pos = r["along"], r["cross"], r["yaw"], r["pos"]
    return (f"| {scene} | {seed} | {r['n']} | {1000 * rms(pos):.2f} | {1000 * a.mean():+.2f} / {1000 * rms(a):.2f} | "
            f"{1000 * cr.mean():+.2f} / {1000 * rms(cr):.2f} | {np.degrees(rms(y)):.3f} | "
            + " / ".join(f"{autocorr(cr, k):.2f}" for k in LAGS) + " | "
            + f"{corr(pos, r['speed']):.2f} / {corr(pos, r['turn']):.2f} / {corr(pos, r['slip']):.2f} / "
            f"{corr(pos, r['sig']):.2f} | {1000 * r['coupled_rmse']:.2f} | "
            + " / ".join(f"{1000 * r[f'slow{w:g}_rmse']:.2f}" for w in WINDOWS_S)
            + f" | {1000 * r['out_rmse']:.2f} | {1000 * r[f'out_minus_slow{WINDOWS_S[0]:g}']:.2f} |")


def main(argv: list[str] | None = None) -> int:
    import yaml
    from eval_amcl_ratio import SCENES

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", nargs="+", default=list(SCENES))
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--frontend", default="amcl", choices=["amcl", "native"])
    ap.add_argument("--backend", default="smoother", choices=["smoother", "ekf", "batch"])
    ap.add_argument("--config", type=Path, default=None, help="YAML overlaid on the defaults")
    ap.add_argument("--scene-set", nargs="*", default=[], metavar="KEY=YAML", help="scenario keys overridden")
    a = ap.parse_args(argv)
    overrides: dict[str, Any] = {}
    for kv in a.scene_set:
        key, sep, val = kv.partition("=")
        if not sep:
            ap.error(f"--scene-set {kv}: expected KEY=YAML")
        overrides[key] = yaml.safe_load(val)
    from tqdm import tqdm

    from fgloc.bench.common import localize_sim
    from fgloc.config import load_config

    cfg = load_config(a.config)
    t0 = time.perf_counter()
    runs = []
    for scene, seed in tqdm([(s, k) for s in a.scenes for k in range(a.seeds)], desc="runs", file=sys.stderr):
        sim = simulate_with(scene, seed, overrides)
        final, _online, loc, _wall = localize_sim(sim, a.backend, a.frontend, cfg)
        r = decompose(sim, loc, final)
        runs.append((scene, seed, r))
        print("\n".join(report(f"{scene} seed {seed}", r)), flush=True)
    print("\n| scene | seed | fixes | pos RMSE mm | along mean / rms mm | cross mean / rms mm | hdg RMSE deg | "
          "cross autocorr 1 / 5 / 25 | corr of size with speed / turn / slip / sigma | hdg-coupled mm | "
          "slow part 2 / 8 s mm | output mm | output - 2 s slow mm |")
    print("|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|")
    for scene, seed, r in runs:
        print(table_row(scene, seed, r))
    print(f"\n{len(runs)} runs ({a.backend} + {a.frontend}) in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
