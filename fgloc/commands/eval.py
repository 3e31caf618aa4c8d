"""``fgloc eval``: error metrics of estimated trajectories against a reference, or relation errors;
``fgloc export``: a log's topic (or any trajectory fgloc reads) as a TUM file.

Every trajectory argument is a TUM file, a log with a topic (``run.mcap:/fused_pose``,
``robot.bag:/odom``; without one the log's /fused_pose, /ground_truth or only pose topic) or a
CARMEN log (its laser lines' poses): :mod:`fgloc.eval.trajectories`.

    fgloc eval EST.tum GT.tum [--plots DIR] [--json]
    fgloc eval out/run.mcap sim/log.mcap                    # /fused_pose against /ground_truth
    fgloc eval out/trajectory.tum robot.bag:/odometry/filtered
    fgloc export robot.bag:/odom -o odom.tum
    fgloc eval EKF.tum SMOOTHER.tum GT.tum --plots DIR      # several estimates, one reference (last)
    fgloc eval --relations FILE TRAJ.tum                    # Kuemmerle et al. relations metric
    fgloc eval --reference REF.tum TRAJ.tum                 # relations built from a reference trajectory
    fgloc eval EST.tum GT.tum --t-offset -1000.0            # estimate stamps shifted before association
    fgloc eval out/trajectory.tum GT.tum --nees             # + the NEES against out/trajectory_status.csv
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Any

import typer

from fgloc.errors import ConfigError, FglocError, LogError

# (Metrics key, label, unit, format) in display order; None key = section break
_TABLE_ROWS: list[tuple[str, str, str, str] | None] = [
    ("n", "associated poses", "", "d"),
    ("n_unassociated", "unassociated poses", "", "d"),
    ("duration_s", "time span", "s", ".2f"),
    ("path_length_m", "reference path length", "m", ".2f"),
    None,
    ("position_rmse_m", "position RMSE (eq. 11)", "m", ".4f"),
    ("heading_rmse_deg", "heading RMSE (eq. 12)", "deg", ".4f"),
    ("max_abs_x_m", "max |x error|", "m", ".4f"),
    ("max_abs_y_m", "max |y error|", "m", ".4f"),
    ("max_abs_heading_deg", "max |heading error|", "deg", ".3f"),
    ("position_p95_m", "position error p95", "m", ".4f"),
    ("heading_p95_deg", "|heading error| p95", "deg", ".3f"),
    None,
    ("along_rms_m", "along-track RMS", "m", ".4f"),
    ("along_mean_abs_m", "along-track mean |.|", "m", ".4f"),
    ("along_max_abs_m", "along-track max |.|", "m", ".4f"),
    ("cross_rms_m", "cross-track RMS", "m", ".4f"),
    ("cross_mean_abs_m", "cross-track mean |.|", "m", ".4f"),
    ("cross_max_abs_m", "cross-track max |.|", "m", ".4f"),
    None,
    ("ape_rmse_m", "APE rmse", "m", ".4f"),
    ("ape_mean_m", "APE mean", "m", ".4f"),
    ("ape_median_m", "APE median", "m", ".4f"),
    ("ape_std_m", "APE std", "m", ".4f"),
    ("ape_min_m", "APE min", "m", ".4f"),
    ("ape_max_m", "APE max", "m", ".4f"),
    None,
    ("rpe_dist_pairs", "RPE per {rpe_dist_delta_m:g} m: pairs", "", "d"),
    ("rpe_dist_trans_rmse_m", "RPE per {rpe_dist_delta_m:g} m: trans. RMSE", "m", ".4f"),
    ("rpe_dist_trans_max_m", "RPE per {rpe_dist_delta_m:g} m: trans. max", "m", ".4f"),
    ("rpe_dist_rot_rmse_deg", "RPE per {rpe_dist_delta_m:g} m: rot. RMSE", "deg", ".3f"),
    ("rpe_dist_rot_max_deg", "RPE per {rpe_dist_delta_m:g} m: rot. max", "deg", ".3f"),
    ("rpe_time_pairs", "RPE per {rpe_time_delta_s:g} s: pairs", "", "d"),
    ("rpe_time_trans_rmse_m", "RPE per {rpe_time_delta_s:g} s: trans. RMSE", "m", ".4f"),
    ("rpe_time_trans_max_m", "RPE per {rpe_time_delta_s:g} s: trans. max", "m", ".4f"),
    ("rpe_time_rot_rmse_deg", "RPE per {rpe_time_delta_s:g} s: rot. RMSE", "deg", ".3f"),
    ("rpe_time_rot_max_deg", "RPE per {rpe_time_delta_s:g} s: rot. max", "deg", ".3f"),
]


def _fmt(v: Any, fmt: str) -> str:
    if v is None:
        return "-"
    if isinstance(v, float) and v != v:  # NaN
        return "-"
    return format(v, fmt)


def _labels(paths: list[Path]) -> list[str]:
    stems = [p.stem for p in paths]
    if len(set(stems)) == len(stems):
        return stems
    return [f"{p.parent.name}/{p.stem}" if p.parent.name else str(p) for p in paths]


def _metrics_table(results: dict[str, Any], ref_name: str, paper: bool):
    from rich.table import Table

    from fgloc.eval import paper as P

    paper_vals = {r.key: r.paper for r in P.PAPER_ROWS}
    first = next(iter(results.values()))
    table = Table(title=f"Errors against {ref_name} (estimate - reference, no alignment)"
                  if not first.aligned else f"Errors against {ref_name} (after SE(2) alignment)")
    table.add_column("metric")
    table.add_column("unit")
    if paper:
        table.add_column("paper", justify="right")
    for name in results:
        table.add_column(name, justify="right", no_wrap=True)
    ctx = first.to_dict()
    rows = _TABLE_ROWS
    for i, row in enumerate(rows):
        if row is None:
            continue
        key, label, unit, fmt = row
        cells = [label.format(**ctx), unit]
        if paper:
            pv = paper_vals.get(key)
            cells.append("-" if pv is None else f"{pv:g}")
        cells += [_fmt(getattr(m, key), fmt) for m in results.values()]
        end = i + 1 < len(rows) and rows[i + 1] is None
        table.add_row(*cells, end_section=end)
    return table


# (NeesMetrics key, label, what it is when the covariances are honest, format)
_NEES_ROWS: list[tuple[str, str, str, str]] = [
    ("n", "poses with a covariance", "", "d"),
    ("n_without_cov", "poses without one", "", "d"),
    ("nees_mean", "NEES mean", "3", ".2f"),
    ("nees_median", "NEES median", "2.37", ".2f"),
    ("inside_95", "share inside the 95 % bound (7.81)", "0.95", ".3f"),
    ("nees_x", "x: mean e^2 / P_xx", "1", ".2f"),
    ("nees_y", "y: mean e^2 / P_yy", "1", ".2f"),
    ("nees_yaw", "yaw: mean e^2 / P_yawyaw", "1", ".2f"),
    ("worst_share", "share of the sum in the worst 5 %", "0.17", ".2f"),
    ("nees_trimmed", "NEES mean of the other 95 %", "2.63", ".2f"),
    ("sigma_xy_med_m", "median sigma x/y (m)", "", ".4f"),
    ("sigma_yaw_med_deg", "median sigma yaw (deg)", "", ".3f"),
]


def _nees_results(ests: dict[str, Any], read: list[Any], gt: Any, gt_label: str, cov: Path | None,
                  max_gap: float, pairs: dict[str, Any]) -> dict[str, Any]:
    """Each estimate's :class:`~fgloc.eval.nees.NeesMetrics`: its poses' covariances from ``cov``, else
    the ``trajectory_status.csv`` beside a TUM file, else the log topic's own."""
    from fgloc.eval.metrics import AssociationError
    from fgloc.eval.nees import evaluate_nees
    from fgloc.eval.trajectories import STATUS_FILE, covariances_at, read_status_covariances

    out = {}
    for (lab, est), (tr, src) in zip(ests.items(), read, strict=True):
        status = cov if cov is not None else src.path.parent / STATUS_FILE if src.kind == "tum" else None
        if status is not None and (cov is not None or status.is_file()):
            covs = covariances_at(tr, *read_status_covariances(status))
        elif tr.covs is not None:
            covs = tr.covs
        else:
            raise LogError(f"{src.label}: no per-pose covariance for --nees (a TUM file needs {STATUS_FILE} beside "
                           "it or --cov FILE; a log topic its messages' covariance)")
        try:
            out[lab] = evaluate_nees(est, gt, covs, max_gap=max_gap, association=pairs[lab])
        except AssociationError as e:
            raise LogError(f"{src.label} vs {gt_label}: {e}") from None
    return out


def _nees_table(results: dict[str, Any]):
    from rich.table import Table

    table = Table(title="NEES: the errors against each pose's covariance, e^T P^-1 e over (x, y, yaw)")
    table.add_column("metric")
    table.add_column("honest", justify="right")
    for name in results:
        table.add_column(name, justify="right", no_wrap=True)
    for key, label, honest, fmt in _NEES_ROWS:
        table.add_row(label, honest, *(_fmt(getattr(m, key), fmt) for m in results.values()))
    return table


def _statuses(tr: Any, src: Any, given: Path | None) -> tuple[Path, list[str]] | None:
    """The status file for an estimate and one status per pose of ``tr`` (the estimate as read): ``given``
    (--status; a file of another trajectory is a one-line error), else the ``trajectory_status.csv`` beside
    a TUM estimate when it has every one of its stamps (``fgloc run``'s; online.tum's poses are not in it),
    or for ``run.mcap:/fused_pose`` the status the run published with each pose (``/fgloc/pose/status``)."""
    from fgloc.eval.trajectories import RUN_STATUS_TOPIC, STATUS_FILE, read_run_statuses, read_statuses, statuses_at

    if given is None and src.kind == "mcap" and src.topic == "/fused_pose":  # fgloc run's run.mcap
        found = read_run_statuses(src.path)
        known = None if found is None else statuses_at(tr, *found)
        return None if known is None else (Path(f"{src.path}:{RUN_STATUS_TOPIC}"), known)
    path = given if given is not None else src.path.parent / STATUS_FILE if src.kind == "tum" else None
    if path is None or (given is None and not path.is_file()):
        return None
    known = statuses_at(tr, *read_statuses(path))
    if known is None and given is not None:
        raise LogError(f"{given}: not the status file of {src.label} (a pose of it has no row at its stamp)")
    return None if known is None else (path, known)


def _first_true(mask: Any) -> int:
    """The index of the first true entry of ``mask`` (0 when None or none is)."""
    import numpy as np

    if mask is None or not np.any(mask):
        return 0
    return int(np.argmax(mask))


def status_note(label: str, path: Path, sp: Any) -> str:
    """One line on what a :class:`~fgloc.eval.metrics.StatusSplit` left out of the table, or that it left
    none (``path``: the status file)."""
    from fgloc.eval.metrics import VOUCHED_STATUSES

    vouched = " or ".join(VOUCHED_STATUSES)
    if not sp.n_left_out:
        return f"{label}: every paired pose is {vouched} ({path})"
    if sp.metrics is None:
        return (f"{label}: {path} calls fewer than 2 paired poses {vouched} ({sp.left_out_counts()}): the table is "
                f"over every pose, {sp.all_rmse_m:.4f} m RMSE")
    return (f"{label}: over the {sp.n_vouched} poses {path} calls {vouched}; left out {sp.left_out_errors()}; "
            "--all-poses for the table over every pose)")


def _relations_cmd(
    traj_path: Path, relations: Path | None, reference: Path | None, max_assoc_dt: float, as_json: bool,
    min_dt: float = 1.0, max_dt: float = 2.0,
) -> None:
    import importlib

    try:
        R = importlib.import_module("fgloc.eval.relations")
    except ModuleNotFoundError as e:
        if e.name in ("fgloc.eval.relations",):
            raise FglocError("relations evaluator not available (fgloc.eval.relations is missing)") from None
        raise
    from fgloc.eval.trajectories import read_trajectory

    traj, _ = read_trajectory(traj_path)
    if relations is not None:
        if not relations.is_file():
            raise LogError(f"{relations}: relations file not found")
        rels = R.read_relations(relations)
        source = {"relations": str(relations)}
    else:
        assert reference is not None
        ref, _ = read_trajectory(reference)
        rels = R.relations_from_reference(ref, min_dt=min_dt, max_dt=max_dt)
        source = {"reference": str(reference)}
    if not rels:
        raise LogError(f"{relations or reference}: no relations to evaluate")
    res = dict(R.evaluate_relations(traj, rels, max_assoc_dt=max_assoc_dt))
    if not res.get("n"):
        raise LogError(
            f"{traj_path}: none of the {len(rels)} relations matched a pose within {max_assoc_dt:g} s"
        )
    if as_json:
        print(json.dumps({"trajectory": str(traj_path), **source, **res}, indent=2, default=float))
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"Relation errors of {traj_path.name} ({next(iter(source.values()))})")
    table.add_column("metric")
    table.add_column("value", justify="right")
    table.add_row("relations used", str(res.get("n")))
    table.add_row("unmatched relations", str(res.get("unmatched", "-")))
    table.add_row("translation error (m)", f"{res['trans_mean']:.4f} ± {res['trans_std']:.4f}")
    table.add_row("rotation error (deg)", f"{res['rot_mean_deg']:.3f} ± {res['rot_std_deg']:.3f}")
    if "trans_max" in res:
        table.add_row("max translation error (m)", _fmt(res.get("trans_max"), ".4f"))
    if "rot_max_deg" in res:
        table.add_row("max rotation error (deg)", _fmt(res.get("rot_max_deg"), ".3f"))
    Console().print(table)


def eval_cmd(
    files: Annotated[
        list[Path],
        typer.Argument(
            help="EST [EST2 ...] REF (the last is the reference), or one TRAJ with --relations / --reference; "
            "each a TUM file, a log[:TOPIC] (MCAP, rosbag2, ROS 1 bag: Odometry, PoseWithCovarianceStamped or "
            "PoseStamped poses; default /fused_pose, /ground_truth or the only such topic) or a CARMEN log",
            show_default=False,
            metavar="FILES",
        ),
    ],
    plots: Annotated[
        Path | None, typer.Option("--plots", help="Write PNG plots (paper figs. 6-10 + overview) here")
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON instead of a table")] = False,
    relations: Annotated[
        Path | None, typer.Option("--relations", help="Relations file 't1 t2 x y z roll pitch yaw'")
    ] = None,
    reference: Annotated[
        Path | None, typer.Option("--reference", help="Build relations from this reference trajectory (TUM)")
    ] = None,
    max_gap: Annotated[
        float, typer.Option("--max-gap", help="Do not interpolate the reference across gaps longer than this (s)")
    ] = 0.5,
    align: Annotated[
        bool, typer.Option("--align", help="Rigidly align (SE(2), Umeyama) before computing errors")
    ] = False,
    align_start: Annotated[
        bool, typer.Option("--align-start", help="Move each estimate so its first pose is the reference's there "
                           "(two odometry frames: a run without a map against robot_localization's output); "
                           "the end error is then the drift; with statuses (--status), its first pose called ok "
                           "or degraded")
    ] = False,
    rpe_delta: Annotated[float, typer.Option("--rpe-delta", help="RPE distance between poses (m)")] = 1.0,
    rpe_delta_s: Annotated[float, typer.Option("--rpe-delta-s", help="RPE time between poses (s)")] = 1.0,
    fixes: Annotated[
        Path | None, typer.Option("--fixes", help="Front-end fixes (TUM) drawn as dots on the path plot")
    ] = None,
    map_yaml: Annotated[
        Path | None, typer.Option("--map", help="map_server YAML drawn under the path plot")
    ] = None,
    t_offset: Annotated[
        float, typer.Option("--t-offset", help="Add this to the estimates' stamps before association (s)")
    ] = 0.0,
    paper: Annotated[bool, typer.Option("--paper", help="Show the paper's reported values beside ours")] = False,
    topic: Annotated[
        str | None, typer.Option("--topic", help="the topic of every log argument that names none (LOG:TOPIC)")
    ] = None,
    max_assoc_dt: Annotated[
        float, typer.Option("--max-assoc-dt", help="Relations: max stamp difference to a pose (s)")
    ] = 0.05,
    min_dt: Annotated[
        float, typer.Option("--min-dt", help="--reference: shortest time between the two poses of a relation (s)")
    ] = 1.0,
    max_dt: Annotated[
        float, typer.Option("--max-dt", help="--reference: longest time between the two poses of a relation (s)")
    ] = 2.0,
    force: Annotated[
        bool, typer.Option("--force", help="--plots: overwrite PNG files that fgloc did not write")
    ] = False,
    nees: Annotated[
        bool, typer.Option("--nees", help="Also the NEES of each estimate's poses against its per-pose covariance "
                           "(trajectory_status.csv beside a TUM file, --cov, or a log topic's covariance); over the "
                           "poses the table is over (ok or degraded when the statuses are known)")
    ] = False,
    cov: Annotated[
        Path | None, typer.Option("--cov", help="--nees: the estimate's per-pose covariances (a "
                                  "trajectory_status.csv; default: the one beside a TUM estimate)")
    ] = None,
    status: Annotated[
        Path | None, typer.Option("--status", help="the estimate's per-pose statuses (a trajectory_status.csv; "
                                  "default: the one beside a TUM estimate when it has its stamps; for "
                                  "run.mcap:/fused_pose its /fgloc/pose/status): the metrics over the poses called ok "
                                  "or degraded, the others counted with their errors")
    ] = None,
    all_poses: Annotated[
        bool, typer.Option("--all-poses", help="the metrics over every pose, whatever the statuses say")
    ] = False,
) -> None:
    """Evaluate trajectories: the paper's RMSE (eq. 11/12), max, along/cross-track, p95, APE, RPE; with
    --nees, how honest their per-pose covariances are (NEES).

    The reference is interpolated at each estimated stamp (linear in position, shortest
    arc in yaw), only inside its time span and not across gaps longer than --max-gap.
    """
    if relations is not None or reference is not None:
        if relations is not None and reference is not None:
            raise ConfigError("fgloc eval: give --relations or --reference, not both")
        if len(files) != 1:
            raise ConfigError(f"fgloc eval: with --relations / --reference give exactly one trajectory, got "
                              f"{len(files)}")
        _relations_cmd(files[0], relations, reference, max_assoc_dt, as_json, min_dt, max_dt)
        return
    if len(files) < 2:
        raise ConfigError(f"{files[0]}: fgloc eval needs an estimate and a reference (the reference last), e.g. "
                          "fgloc eval out/trajectory.tum GT.tum, or --relations / --reference with one trajectory")

    from fgloc.eval.checks import clock_note, end_error, frame_note, gap_note, heading_note, start_aligned
    from fgloc.eval.metrics import AssociationError, associate, association_metrics, split_by_status, vouched_pairs
    from fgloc.eval.trajectories import read_trajectory
    from fgloc.types import Trajectory

    gt_path, est_paths = files[-1], files[:-1]
    if nees and align:
        raise ConfigError("fgloc eval: --nees weighs the errors in the estimate's own frame: not with --align")
    if cov is not None and (not nees or len(est_paths) != 1):
        raise ConfigError("fgloc eval: --cov goes with --nees and one estimate")
    if status is not None and (all_poses or len(est_paths) != 1):
        raise ConfigError("fgloc eval: --status goes with one estimate, not with --all-poses")
    gt, gt_src = read_trajectory(gt_path, topic)
    read = [read_trajectory(p, topic) for p in est_paths]
    labels = [f"{lab}:{r[1].topic}" if r[1].topic else lab for lab, r in zip(_labels([r[1].path for r in read]), read,
                                                                              strict=True)]
    if len(set(labels)) < len(labels):
        labels = [str(p) for p in est_paths]
    ests = {lab: tr for lab, (tr, _src) in zip(labels, read, strict=True)}
    if t_offset:
        ests = {lab: Trajectory(tr.stamps + t_offset, tr.poses, tr.frame_id) for lab, tr in ests.items()}
    if align_start and align:
        raise ConfigError("fgloc eval: --align or --align-start, not both")
    results = {}
    pairs: dict[str, Any] = {}  # each estimate's association with the reference, made once
    ends: dict[str, float | None] = {}  # --align-start: the last paired pose's distance from the reference
    splits: dict[str, Any] = {}  # the metrics by the poses' statuses (a trajectory_status.csv)
    nees_pairs: dict[str, Any] = {}  # --nees: the pairs it weighs (the vouched ones, when the statuses are known)
    for (lab, est), p, (_tr, src) in zip(list(ests.items()), est_paths, read, strict=True):
        try:
            a = associate(est, gt, max_gap=max_gap)
        except AssociationError as e:
            hint = clock_note(est, src, gt, gt_src, t_offset) if "do not overlap" in str(e) else None
            raise LogError(f"{p}{': --align-start' if align_start else ' vs ' + gt_src.label}: {e}"
                           + (f"; {hint}" if hint else "")) from None
        known = None if all_poses else _statuses(_tr, src, status)
        vouched = None if known is None else vouched_pairs(a, known[1])
        if align_start:  # on the first pose the run vouches for (a lost pose is where the run says it is not)
            ests[lab], a = start_aligned(est, a, first=_first_true(vouched))
            ends[lab] = end_error(a)
        pairs[lab] = a
        results[lab] = association_metrics(a, align=align, rpe_delta_m=rpe_delta, rpe_delta_s=rpe_delta_s)
        if known is not None:
            sp = split_by_status(a, known[1], align=align, rpe_delta_m=rpe_delta, rpe_delta_s=rpe_delta_s)
            splits[lab] = sp
            typer.echo(f"note: {status_note(lab, known[0], sp)}", err=True)
            if sp.metrics is not None:
                results[lab] = sp.metrics
                if nees and vouched is not None:  # the NEES over the same poses as the table
                    nees_pairs[lab] = a.subset(vouched)
        frames = None if align or align_start else frame_note(lab, a)
        notes = [gap_note(lab, est.stamps, gt.stamps, max_gap), frames,
                 None if align_start or frames is not None else heading_note(lab, a, align)]
        for note in notes:
            if note is not None:
                typer.echo(f"note: {note}", err=True)
    nees_results = _nees_results(ests, read, gt, gt_src.label, cov, max_gap, {**pairs, **nees_pairs}) if nees else {}

    written: list[Path] = []
    if plots is not None:
        from fgloc.eval.plots import plot_all, plot_files
        from fgloc.io.outputs import Outputs

        fx = read_trajectory(fixes)[0] if fixes is not None else None
        occ = None
        if map_yaml is not None:
            from fgloc.maps import load_map

            occ = load_map(map_yaml)
        with Outputs(plots, plot_files(), command="eval", inputs=(*files, fixes, map_yaml), force=force,
                     option="--plots") as outs:
            staged = plot_all(ests, gt, outs.dir, fixes=fx, occ_map=occ, max_gap=max_gap)
        written = [outs.final(p.name) for p in staged]

    if as_json:
        docs: list[dict[str, Any]] = [
            {"label": lab, "estimate": str(p), "reference": gt_src.label, "metrics": m.to_dict()}
            for (lab, m), p in zip(results.items(), est_paths, strict=True)
        ]
        out: Any = docs[0] if len(docs) == 1 else docs
        if written:
            for d in docs:
                d["plots"] = [str(w) for w in written]
        for d in docs:
            if d["label"] in nees_results:
                d["nees"] = nees_results[str(d["label"])].to_dict()
            if d["label"] in ends:
                d["end_error_m"] = ends[str(d["label"])]
            if d["label"] in splits:
                d["by_status"] = splits[str(d["label"])].to_dict()
        print(json.dumps(out, indent=2))
        return

    from rich.console import Console

    console = Console()
    console.print(_metrics_table(results, gt_src.path.name + ("" if gt_src.topic is None else f":{gt_src.topic}"),
                                 paper))
    if nees_results:
        console.print(_nees_table(nees_results))
    for lab, end in ends.items():
        if end is not None:
            console.print(f"end error (aligned at the start): {lab} {end:.3f} m")
    if written:
        console.print(f"plots: {len(written)} PNG files in {plots}")


def export_cmd(
    src: Annotated[str, typer.Argument(help="a log[:TOPIC] (MCAP, rosbag2, ROS 1 bag), a CARMEN log or a TUM file",
                                       metavar="LOG[:TOPIC]")],
    output: Annotated[Path, typer.Option("-o", "--output", help="the TUM file to write, or a map's YAML (NAME.yaml: "
                                          "its image NAME.pgm beside it)")],
    topic: Annotated[str | None, typer.Option("--topic", help="the topic (instead of LOG:TOPIC)")] = None,
    force: Annotated[bool, typer.Option("--force", help="overwrite an existing file")] = False,
) -> None:
    """Write a log's Odometry / PoseWithCovarianceStamped / PoseStamped topic (or a CARMEN log's laser poses) as a
    TUM file, as evo reads it; or the map a log carries (nav_msgs/OccupancyGrid, its last message) as a
    map_server map."""
    from fgloc.eval.trajectories import read_trajectory, split_spec
    from fgloc.io.outputs import OutputFile
    from fgloc.io.tum import write_tum

    path, named = split_spec(src)
    if _exports_map(path, named or topic, output):
        _export_map(path, named or topic, output, force)
        return
    tr, where = read_trajectory(src, topic)
    with OutputFile(output, command="export", inputs=[where.path], force=force, what=".tum") as out:
        write_tum(out.path, tr)
    print(f"wrote {output}: {len(tr)} poses of {where.label} ({tr.frame_id} frame, {tr.duration:.1f} s)")


MAP_SUFFIXES = (".yaml", ".yml")


def _exports_map(path: Path, topic: str | None, output: Path) -> bool:
    """Whether ``fgloc export`` writes a map: the output is a YAML file, or the topic is a map topic
    (the YAML name the output needs is then a one-line error)."""
    from fgloc.app.logmap import OCCUPANCY_GRID, log_topic_type
    from fgloc.errors import LogError
    from fgloc.io.topics import resolve_name

    if output.suffix.lower() in MAP_SUFFIXES:
        return True
    if topic is None or log_topic_type(path, resolve_name(topic)) != OCCUPANCY_GRID:
        return False
    raise LogError(f"{path}:{resolve_name(topic)}: a map (nav_msgs/OccupancyGrid): write it as a map_server "
                   f"map, -o {output.with_suffix('.yaml').name}")


def _export_map(path: Path, topic: str | None, output: Path, force: bool) -> None:
    """The map the log carries as ``output`` (YAML) and its ``.pgm`` image beside it."""
    from fgloc.app.logmap import read_log_map
    from fgloc.io.outputs import OutputFile
    from fgloc.io.topics import resolve_name
    from fgloc.maps import write_map_files

    image = output.with_suffix(".pgm")
    outs = [OutputFile(output, command="export", inputs=[path], force=force, what="map YAML"),
            OutputFile(image, command="export", inputs=[path], force=force, what="map image")]
    for o in outs:
        o.check()  # both refusals before the log is read
    lm = read_log_map(path, None if topic is None else resolve_name(topic))
    with outs[0] as y, outs[1] as im:
        write_map_files(lm.map, y.path, im.path, image.name)
    m = lm.map
    xmin, xmax, ymin, ymax = m.extent
    print(f"wrote {output}, {image.name}: the map on {path}:{lm.topic} ({m.width} x {m.height} cells at "
          f"{m.resolution:g} m, {xmax - xmin:.1f} m x {ymax - ymin:.1f} m; the last of {lm.count} message(s), "
          f"log time {lm.stamp_s:.3f})")


def register(app: typer.Typer) -> None:
    app.command("eval")(eval_cmd)
    app.command("export")(export_cmd)
