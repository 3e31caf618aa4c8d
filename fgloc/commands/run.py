"""``fgloc run`` (localize a log), ``fgloc bench`` (paper / faults benchmarks), ``fgloc demo``."""

from __future__ import annotations

import math
import time
from importlib.resources import as_file
from pathlib import Path
from typing import Any

import numpy as np
import typer

from fgloc.errors import ConfigError, LogError
from fgloc.io.yamlio import write_yaml, yaml_ready


def _progress(total: int | None, desc: str, disable: bool = False):
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="msg", disable=disable, leave=False, mininterval=0.5)


def _check_inputs(reader: Any, log: Path, roles: tuple[tuple[str, str], ...]) -> None:
    """One-line errors for inputs that cannot be localized with: a role's topic of another type
    (it would be skipped and the run would 'succeed' empty) or topics stamped by different clocks."""
    types = reader.topic_types()
    for topic, want in roles:
        have = types.get(topic)
        if have is not None and reader.has(topic) and have != want:
            raise LogError(f"{log}: topic '{topic}' has type {have}, expected {want} (rename with --*-topic)")
    skew = reader.clock_skew([t for t, _ in roles])
    if skew is not None:
        raise LogError(f"{log}: {skew}")


def run_log(log: Path, outdir: Path, map_yaml: Path | None = None, backend: str = "smoother",
            frontend: str = "native", initial_pose: list[float] | None = None,
            config_path: Path | None = None, scan_topic: str = "/scan", odom_topic: str = "/odom",
            imu_topic: str = "/imu", quiet: bool = False) -> dict[str, Any]:
    """Localize ``log`` and write OUTDIR/{trajectory,online,fixes}.tum, run.mcap, config.yaml.

    Returns a summary dict (also what the CLI prints).
    """
    from fgloc.io.log import IMU, LASER_SCAN, ODOMETRY, LogReader, LogWriter, Topics
    from fgloc.io.tum import write_tum
    from fgloc.maps import OccupancyMap
    from fgloc.pipeline import Localizer, load_config, run_messages

    config = load_config(config_path)
    topics = Topics(scan=scan_topic, odom=odom_topic, imu=imu_topic)
    reader = LogReader(log, topics)
    summ = reader.summary()
    counts = {t: v["count"] for t, v in summ["topics"].items()}
    n_scan, n_odom, n_imu = counts.get(scan_topic, 0), counts.get(odom_topic, 0), counts.get(imu_topic, 0)
    if n_odom == 0 and n_imu == 0 and n_scan == 0:
        raise LogError(f"{log}: no {scan_topic}, {odom_topic} or {imu_topic} messages to localize with")
    _check_inputs(reader, log, ((scan_topic, LASER_SCAN), (odom_topic, ODOMETRY), (imu_topic, IMU)))
    occ_map = OccupancyMap.load(map_yaml) if map_yaml is not None else None
    mode = "map"
    if occ_map is None or n_scan == 0:
        occ_map = None
        mode = "odom"
    pose0 = np.asarray(initial_pose, dtype=float) if initial_pose is not None else None
    if pose0 is not None and (pose0.shape != (3,) or not np.all(np.isfinite(pose0))):
        raise ConfigError("--initial-pose needs three finite numbers X Y YAW")
    laser_mount = reader.laser_mount()
    loc = Localizer(occ_map, laser_mount, backend=backend, frontend=frontend, initial_pose=pose0,
                    config=config)
    outdir.mkdir(parents=True, exist_ok=True)
    want = {t for t in (scan_topic, odom_topic, imu_topic, topics.tf_static) if reader.has(t)}
    total = sum(counts.get(t, 0) for t in want)
    t_wall = time.perf_counter()
    with LogWriter(outdir / "run.mcap") as writer, _progress(total, "localizing", quiet) as bar:
        def on_message(topic: str, msg: object) -> None:
            bar.update(1)
            try:
                writer.write(topic, msg)
            except (TypeError, ValueError):
                pass

        def on_fused(fused, fix) -> None:
            writer.write(topics.fused, fused)

        final = run_messages(loc, reader.messages(want), topics, on_message, on_fused)
    wall = time.perf_counter() - t_wall
    online = loc.online_trajectory()
    fixes = loc.fixes_trajectory()
    frame = "odom" if mode == "odom" else "map"
    written = []
    if len(final):
        written.append(write_tum(outdir / "trajectory.tum", final))
    if len(online):
        written.append(write_tum(outdir / "online.tum", online))
    if len(fixes):
        written.append(write_tum(outdir / "fixes.tum", fixes))
    from fgloc.config.schema import to_dict

    effective = to_dict(config)
    effective["run"] = {
        "log": str(log), "map": str(map_yaml) if map_yaml else None, "mode": mode, "backend": backend,
        "frontend": loc.frontend_name, "initial_pose": None if pose0 is None else pose0.tolist(),
        "topics": {"scan": scan_topic, "odom": odom_topic, "imu": imu_topic},
    }
    write_yaml(outdir / "config.yaml", effective)
    sim_s = float(final.duration) if len(final) else float(summ.get("duration") or 0.0)
    result: dict[str, Any] = {
        "mode": mode, "frame": frame, "backend": backend, "frontend": loc.frontend_name,
        "poses": len(final), "online_poses": len(online), "fixes": len(fixes),
        "stats": yaml_ready(loc.stats), "wall_s": wall, "log_s": sim_s,
        "truncated": reader.truncated, "outdir": str(outdir),
        "written": [p.name for p in written] + ["run.mcap", "config.yaml"],
    }
    gt = reader.ground_truth() if reader.has(topics.ground_truth) else None
    if gt is not None and len(final) > 1:
        from fgloc.eval.metrics import evaluate

        try:
            result["metrics"] = evaluate(final, gt, align=(mode == "odom"))
            result["metrics_online"] = evaluate(online, gt, align=(mode == "odom")) if len(online) > 1 else None
        except LogError as e:
            result["eval_error"] = str(e)
    return result


def _print_run_summary(r: dict[str, Any]) -> None:
    from rich.console import Console

    con = Console()
    st = r["stats"]
    speed = r["log_s"] / r["wall_s"] if r["wall_s"] > 0 else float("inf")
    con.print(f"[bold]fgloc run[/bold]: {r['backend']} back-end, {r['frontend']} front-end, "
              f"{r['mode']} frame; {r['poses']} poses over {r['log_s']:.1f} s in {r['wall_s']:.1f} s "
              f"({speed:.0f}x real time)")
    con.print(f"  scans {st['scans']}, fixes {st['fixes']}, no fix {st['no_fix']}, rejected {st['rejected']}, "
              f"odometry {st['odometry']}, compass {st['compass']}, skipped {st['skipped']} "
              f"{st['skipped_reasons'] or ''}, relocalizations {st['relocalizations']}")
    if st.get("no_fix_reasons"):
        con.print(f"  no-fix reasons: {st['no_fix_reasons']}")
    if r.get("truncated"):
        con.print(f"  [yellow]log truncated:[/yellow] {r['truncated']}")
    m = r.get("metrics")
    if m is not None:
        from fgloc.eval.paper import comparison_table

        rows = {f"{r['backend']} (final)": [m]}
        if r.get("metrics_online") is not None:
            rows[f"{r['backend']} (online)"] = [r["metrics_online"]]
        con.print(comparison_table(rows, title="vs /ground_truth" + (" (SE(2)-aligned, odom frame)"
                                                                    if r["mode"] == "odom" else ""), extra=False))
    if r.get("eval_error"):
        con.print(f"  evaluation skipped: {r['eval_error']}")
    con.print(f"  wrote {r['outdir']}/: {', '.join(r['written'])}")


# ---------------------------------------------------------------------- bench helpers
def localize_sim(sim: Any, backend: str, frontend: str, config: Any = None,
                 initial_pose: np.ndarray | None = None, use_initial: bool = True) -> tuple[Any, Any, Any, float]:
    """Run one back-end/front-end on a simulated run; returns (final, online, localizer, wall_s)."""
    from fgloc.pipeline import Localizer, run_messages

    pose0 = initial_pose
    if pose0 is None and use_initial:
        pose0 = sim.ground_truth.poses[0]
    loc = Localizer(sim.map, sim.laser_mount, backend=backend, frontend=frontend, initial_pose=pose0,
                    config=config)
    t0 = time.perf_counter()
    final = run_messages(loc, sim.messages)
    wall = time.perf_counter() - t0
    return final, loc.online_trajectory(), loc, wall


PAPER_VARIANTS = (
    # (column label, backend, frontend, which trajectory)
    ("EKF+AMCL (paper)", "ekf", "amcl", "final"),
    ("EKF+native", "ekf", "native", "final"),
    ("smoother online", "smoother", "native", "online"),
    ("smoother fixed-lag", "smoother", "native", "final"),
    ("batch", "batch", "native", "final"),
)


def _bench_one_seed(args: tuple[int, list[tuple[str, str, str, str]], dict, bool]) -> dict[str, Any]:
    from fgloc.eval.metrics import evaluate
    from fgloc.sim import simulate_paper

    seed, variants, config, keep = args
    sim = simulate_paper(seed=seed)
    out: dict[str, Any] = {"seed": seed, "metrics": {}, "wall": {}, "traj": {}}
    cache: dict[tuple[str, str], Any] = {}
    for label, backend, frontend, which in variants:
        key = (backend, frontend)
        if key not in cache:
            cache[key] = localize_sim(sim, backend, frontend, config)
        final, online, _loc, wall = cache[key]
        tr = online if which == "online" else final
        out["metrics"][label] = evaluate(tr, sim.ground_truth)
        out["wall"][label] = wall
        if keep:
            out["traj"][label] = tr
    if keep:
        out["gt"] = sim.ground_truth
        out["map"] = sim.map
    return out


def bench_paper(seeds: int, outdir: Path | None, variants=PAPER_VARIANTS, config_path: Path | None = None,
                jobs: int = 1, quiet: bool = False) -> dict[str, Any]:
    """Simulate the paper run ``seeds`` times, localize with each variant, compare with the paper."""
    from fgloc.pipeline import load_config

    config = load_config(config_path)
    tasks = [(s, list(variants), config, s == 0 and outdir is not None) for s in range(seeds)]
    results: list[dict[str, Any]] = []
    from tqdm import tqdm

    if jobs > 1 and seeds > 1:
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(max_workers=jobs) as ex:
            for r in tqdm(ex.map(_bench_one_seed, tasks), total=seeds, desc="seeds", disable=quiet, leave=False):
                results.append(r)
    else:
        for t in tqdm(tasks, desc="seeds", disable=quiet, leave=False):
            results.append(_bench_one_seed(t))
    rows = {label: [r["metrics"][label] for r in results] for label, *_ in variants}
    walls = {label: float(np.mean([r["wall"][label] for r in results])) for label, *_ in variants}
    files: list[Path] = []
    if outdir is not None:
        from fgloc.eval.paper import comparison_text
        from fgloc.eval.plots import plot_all

        outdir.mkdir(parents=True, exist_ok=True)
        r0 = results[0]
        files = plot_all(r0["traj"], r0["gt"], outdir, occ_map=r0["map"], title="paper replica, seed 0")
        (outdir / "table.md").write_text(comparison_text(rows, title=f"paper replica, {seeds} seeds") + "\n")
        summary = {label: {k: [m.to_dict()[k] for m in ms] for k in ("position_rmse_m", "heading_rmse_deg")}
                   for label, ms in rows.items()}
        write_yaml(outdir / "metrics.yaml", summary)
    return {"rows": rows, "walls": walls, "files": files, "seeds": seeds}


def _claims(rows: dict[str, list[Any]]) -> list[str]:
    def mean(label: str, key: str) -> float:
        return float(np.mean([getattr(m, key) for m in rows[label]]))

    out = []
    if "smoother fixed-lag" in rows:
        p, h = mean("smoother fixed-lag", "position_rmse_m"), mean("smoother fixed-lag", "heading_rmse_deg")
        out.append(f"smoother fixed-lag: position RMSE {p:.4f} m (target <= 0.010), "
                   f"heading RMSE {h:.3f} deg (target <= 0.30)")
        for ekf in ("EKF+AMCL (paper)", "EKF+native"):
            if ekf in rows:
                e = mean(ekf, "position_rmse_m")
                out.append(f"smoother vs {ekf}: {100 * (1 - p / e):.0f} % lower position RMSE (target >= 30 %)")
        if "batch" in rows:
            b = mean("batch", "position_rmse_m")
            out.append(f"fixed-lag / batch position RMSE: {p / b:.2f}x (target <= 1.2x)")
    return out


def _frontend_available(name: str) -> bool:
    import importlib

    try:
        importlib.import_module(f"fgloc.frontends.{name}")
    except ImportError:
        return False
    return True


FAULTS = ("compass_disturbance", "wheel_slip", "kidnap")


def bench_faults(backend: str = "smoother", frontend: str = "native", seeds: int = 1,
                 config_path: Path | None = None, quiet: bool = False) -> list[dict[str, Any]]:
    """Fault scenarios vs the fault-free paper run: position RMSE increase, kidnap recovery time."""
    from fgloc.eval.metrics import evaluate
    from fgloc.pipeline import load_config
    from fgloc.sim import run_scenario, simulate_paper

    config = load_config(config_path)
    from fgloc.config import scenario_path
    out = []
    for seed in range(seeds):
        base = simulate_paper(seed=seed)
        f0, *_ = localize_sim(base, backend, frontend, config)
        rmse0 = evaluate(f0, base.ground_truth).position_rmse_m
        for name in FAULTS:
            res = scenario_path(name)
            if not res.is_file():
                out.append({"seed": seed, "scenario": name, "error": f"scenario {name} not shipped"})
                continue
            with as_file(res) as path:
                sim = run_scenario(path, seed=seed)
            final, online, loc, _ = localize_sim(sim, backend, frontend, config)
            m = evaluate(final, sim.ground_truth)
            row: dict[str, Any] = {"seed": seed, "scenario": name, "rmse0": rmse0, "rmse": m.position_rmse_m,
                                   "delta": m.position_rmse_m - rmse0, "relocalizations":
                                   loc.stats["relocalizations"]}
            if name == "kidnap":
                row.update(kidnap_recovery(sim, online))
            out.append(row)
    return out


def kidnap_recovery(sim: Any, online: Any, tol: float = 0.2) -> dict[str, Any]:
    """Time from the teleport (largest ground-truth jump) until the online error stays < ``tol``."""
    gt = sim.ground_truth
    steps = np.linalg.norm(np.diff(gt.poses[:, :2], axis=0), axis=1)
    i = int(np.argmax(steps))
    t_kid = float(gt.stamps[i + 1])
    if steps[i] < 0.5:
        return {"kidnap_t": None, "recovery_s": None}
    mask = online.stamps >= t_kid
    ts = online.stamps[mask]
    err = np.linalg.norm(online.poses[mask, :2] - gt.interpolate(ts)[:, :2], axis=1)
    bad = np.nonzero(err >= tol)[0]
    if len(ts) == 0:
        return {"kidnap_t": t_kid, "recovery_s": None}
    if len(bad) == 0:
        rec = float(ts[0] - t_kid)
    elif bad[-1] + 1 < len(ts):
        rec = float(ts[bad[-1] + 1] - t_kid)
    else:
        rec = math.inf
    return {"kidnap_t": t_kid, "recovery_s": rec, "jump_m": float(steps[i])}


# ---------------------------------------------------------------------- CLI
def register(app: typer.Typer) -> None:
    @app.command("run")
    def run_cmd(
        log: Path = typer.Argument(..., help="ROS 2 MCAP log (see `fgloc import` for bags / CARMEN)"),
        map_yaml: Path | None = typer.Option(None, "--map", help="map_server YAML; without it: odom-frame fusion"),
        backend: str = typer.Option("smoother", "--backend", help="ekf | smoother | batch"),
        frontend: str = typer.Option("native", "--frontend", help="amcl | kiss | native"),
        initial_pose: tuple[float, float, float] | None = typer.Option(
            None, "--initial-pose", help="X Y YAW (m, m, rad) in the map; without it: global localization"),
        config: Path | None = typer.Option(None, "--config", help="YAML overriding config/fgloc.yaml"),
        scan_topic: str = typer.Option("/scan", "--scan-topic"),
        odom_topic: str = typer.Option("/odom", "--odom-topic"),
        imu_topic: str = typer.Option("/imu", "--imu-topic"),
        outdir: Path = typer.Option(..., "-o", "--output", help="output folder"),
        quiet: bool = typer.Option(False, "--quiet", "-q", help="no progress bar"),
    ) -> None:
        """Localize a log: trajectory.tum, fixes.tum, run.mcap (/fused_pose), config.yaml."""
        if backend not in ("ekf", "smoother", "batch"):
            raise ConfigError(f"unknown back-end '{backend}' (choose ekf, smoother or batch)")
        r = run_log(log, outdir, map_yaml, backend, frontend, list(initial_pose) if initial_pose else None,
                    config, scan_topic, odom_topic, imu_topic, quiet)
        _print_run_summary(r)

    bench = typer.Typer(help="Benchmarks: the paper replica, fault scenarios.", no_args_is_help=True)
    app.add_typer(bench, name="bench")

    @bench.command("paper")
    def bench_paper_cmd(
        seeds: int = typer.Option(5, "--seeds", help="simulated runs (seeds 0..N-1)"),
        outdir: Path | None = typer.Option(None, "-o", "--output", help="write plots, table.md, metrics.yaml"),
        config: Path | None = typer.Option(None, "--config"),
        jobs: int = typer.Option(2, "--jobs", "-j", help="parallel processes"),
        no_amcl: bool = typer.Option(False, "--no-amcl", help="skip the EKF+AMCL column"),
    ) -> None:
        """The paper experiment over N seeds: the paper's numbers beside EKF, smoother and batch."""
        from rich.console import Console

        from fgloc.eval.paper import comparison_text

        if seeds < 1:
            raise ConfigError("--seeds must be at least 1")
        con = Console()
        have_amcl = _frontend_available("amcl")
        if not have_amcl and not no_amcl:
            con.print("[yellow]AMCL front-end not available: the EKF+AMCL column is left out[/yellow]")
        variants = tuple(v for v in PAPER_VARIANTS if not ((no_amcl or not have_amcl) and v[2] == "amcl"))
        res = bench_paper(seeds, outdir, variants, config, jobs)
        # plain Markdown (pasteable into the README), never truncated by the terminal width
        print(comparison_text(res["rows"], title=f"paper replica: {seeds} seed(s), mean ± std over seeds"))
        for line in _claims(res["rows"]):
            con.print("  " + line)
        con.print("  wall time per run: " + ", ".join(f"{k} {v:.1f} s" for k, v in res["walls"].items()))
        if outdir is not None:
            con.print(f"  wrote {outdir}/table.md, metrics.yaml and {len(res['files'])} plots")

    @bench.command("faults")
    def bench_faults_cmd(
        backend: str = typer.Option("smoother", "--backend"),
        frontend: str = typer.Option("native", "--frontend"),
        seeds: int = typer.Option(1, "--seeds"),
        config: Path | None = typer.Option(None, "--config"),
    ) -> None:
        """Compass disturbance, wheel slip and kidnapping vs the fault-free paper run."""
        from rich.console import Console
        from rich.table import Table

        rows = bench_faults(backend, frontend, seeds, config)
        t = Table(title=f"fault scenarios ({backend} + {frontend})")
        for c in ("seed", "scenario", "RMSE fault-free (m)", "RMSE (m)", "increase (m)", "recovery (s)"):
            t.add_column(c, justify="right")
        for r in rows:
            if "error" in r:
                t.add_row(str(r["seed"]), r["scenario"], "-", "-", r["error"], "-")
                continue
            rec = r.get("recovery_s")
            t.add_row(str(r["seed"]), r["scenario"], f"{r['rmse0']:.4f}", f"{r['rmse']:.4f}",
                      f"{r['delta']:+.4f}", "-" if rec is None else f"{rec:.2f}")
        Console().print(t)

    @app.command("demo")
    def demo_cmd(
        outdir: Path = typer.Option(Path("fgloc-demo"), "-o", "--output", help="plots and trajectories"),
    ) -> None:
        """The paper experiment (seed 0) localized by the paper's EKF and the smoother; table and plots."""
        from rich.console import Console

        from fgloc.eval.metrics import evaluate
        from fgloc.eval.paper import comparison_text
        from fgloc.eval.plots import plot_all
        from fgloc.io.tum import write_tum
        from fgloc.pipeline import load_config
        from fgloc.sim import simulate_paper, write_sim

        con = Console()
        t0 = time.perf_counter()
        with con.status("simulating the paper experiment (seed 0)"):
            sim = simulate_paper(seed=0)
            write_sim(sim, outdir / "sim")
        config = load_config()
        trajs, rows = {}, {}
        ekf_fe = "amcl" if _frontend_available("amcl") else "native"
        for label, backend, frontend in ((f"EKF+{ekf_fe} (paper's filter)", "ekf", ekf_fe),
                                         ("smoother+native", "smoother", "native")):
            with con.status(f"localizing: {label}"):
                final, _online, _loc, _ = localize_sim(sim, backend, frontend, config)
            trajs[label] = final
            rows[label] = [evaluate(final, sim.ground_truth)]
            write_tum(outdir / f"{backend}.tum", final)
        print(comparison_text(rows, title="paper replica, seed 0: the paper's numbers vs fgloc"))
        files = plot_all(trajs, sim.ground_truth, outdir, occ_map=sim.map, title="paper replica, seed 0")
        con.print(f"wrote {len(files)} plots, ekf.tum, smoother.tum and the simulated log to {outdir} "
                  f"in {time.perf_counter() - t0:.0f} s")
