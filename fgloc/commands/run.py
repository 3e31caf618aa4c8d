"""``fgloc run``: localize a log.

The CLI only parses and prints: the work is :func:`fgloc.app.run.run_log`.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import typer

from fgloc.app import mounts
from fgloc.app.run import RunRequest, RunResult
from fgloc.app.run import run_log as run_request
from fgloc.app.units import pose_arg, pose_value

__all__ = ["register"]


def progress_bar(quiet: bool, stream: Any = None):
    """A tqdm bar factory over the messages read, or None: with --quiet, and when stderr is not a
    terminal (a log file gets no carriage-return lines, and a batch or a benchmark does not pay
    tqdm's import, ~0.02 s of CPU)."""
    if quiet:
        return None
    out = sys.stderr if stream is None else stream
    isatty = getattr(out, "isatty", None)
    if not (callable(isatty) and isatty()):
        return None
    from tqdm import tqdm

    def bar(total: int | None) -> Any:
        return tqdm(total=total, desc="localizing", unit="msg", leave=False, mininterval=0.5, file=out)

    return bar


EXIT_LOST = 3  # fgloc run: the run finished but its result is not usable (lost, or no pose)


def _announce(line: str) -> None:
    print(f"fgloc: {line}", file=sys.stderr, flush=True)


def _styled(text: str, sgr: str, tty: bool) -> str:
    """``text`` in an ANSI style (``sgr``: "1" bold, "1;31" bold red, "33" yellow) on a terminal."""
    return f"\033[{sgr}m{text}\033[0m" if tty else text


def _print_run_summary(r: RunResult) -> None:
    """The run's summary on stdout, plain lines (bold / colour on a terminal only).

    Plain ``print``: rich's console cost every run ~0.03 s of CPU to import and lay out a few
    lines (and wrapped them at 80 columns in a pipe)."""
    print("\n".join(run_summary_lines(r, tty=sys.stdout.isatty())), flush=True)


def run_summary_lines(r: RunResult, tty: bool = False) -> list[str]:
    """``fgloc run``'s summary as lines; ``tty``: bold / colour escapes.  The comparison table is the
    cells of :func:`fgloc.eval.paper.comparison_cells`, as ``fgloc bench paper`` prints them."""
    lines: list[str] = []
    say = lines.append
    st = r.stats
    speed = r.log_s / r.wall_s if r.wall_s > 0 else float("inf")
    say(f"{_styled('fgloc run', '1', tty)}: {r.backend} back-end, {r.frontend} front-end, "
        f"{r.mode} frame; {r.poses} poses over {r.log_s:.1f} s in {r.wall_s:.1f} s ({speed:.0f}x real time)")
    heading = "imu" if any(d.kind == "imu" for d in st.sources.values()) else "compass"  # the heading source's kind
    say(f"  scans {st.scans}, fixes {st.fixes}, no fix {st.no_fix}, rejected {st.rejected}, "
        f"odometry {st.odometry}, {heading} {st.compass}, skipped {st.skipped}, "
        f"relocalizations {st.relocalizations}")
    if r.mode == "map":
        say(f"  lost {r.lost_s:.1f} s ({100 * r.lost_share:.0f} % of the run, {st.lost_events} "
            f"time(s) after tracking){', ' + _styled('lost at the end', '1;31', tty) if r.ended_lost else ''}")
    status = r.status or {}
    counts = status.get("counts") or {}
    if counts:  # every pose's status (fgloc.localization.monitor), and what made the run suspect
        n = max(sum(counts.values()), 1)
        say("  pose status: " + ", ".join(f"{k} {v} ({100 * v / n:.0f} %)" for k, v in counts.items()))
    for v in status.get("verdicts") or ():
        say(f"  {_styled('integrity:', '1;31' if v['unusable'] else '33', tty)} {v['message']}")
    from dataclasses import replace

    from fgloc.localization.sources import summary_lines

    # the motion model and each input source's health; a default source the log has nothing for: one quiet line
    shown = replace(st, sources={k: d for k, d in st.sources.items() if k not in r.absent}) if r.absent else st
    for line in summary_lines(shown):
        say(f"  {line}")
    for name, why in r.absent.items():
        say(f"  {name}: {why}")
    be = st.backend
    if be.get("solver_failures"):  # the smoother restarted from its prediction: the estimate is not smoothed there
        say(f"  {_styled('back-end:', '33', tty)} {be['solver_failures']} solver failure(s), each a restart from "
            "the odometry prediction (an input that leaves a variable unconstrained, e.g. no heading source)")
    if be.get("compass_recoveries"):
        say(f"  back-end: heading re-opened to the compass {be['compass_recoveries']} time(s)")
    for title, reasons in (("skipped", st.skipped_reasons), ("no fix", st.no_fix_reasons)):
        if reasons:  # grouped by kind (fgloc.localization.localizer.reason_kind): a few lines at most
            say(f"  {title}, by reason:")
            for why, n in reasons.items():
                say(f"    {n:6d}  {why}")
    for w in r.warnings:
        say(f"  {_styled('warning:', '33', tty)} {w}")
    if r.truncated:
        say(f"  {_styled('log truncated:', '33', tty)} {r.truncated}")
    if r.damage:
        say(f"  {_styled('log damaged:', '33', tty)} {r.damage}")
    if r.timings:  # one line (fgloc bench speed reads it)
        tm = r.timings
        say(f"  time: {tm['total_s']:.2f} s = setup {tm['setup_s']:.2f} + reading {tm['read_s']:.2f} + "
            f"localizing {tm['localize_s']:.2f} + writing {tm['write_s']:.2f} + view channels "
            f"{tm['view_s']:.2f} + final smoothing {tm['finish_s']:.2f} + outputs {tm['outputs_s']:.2f} s")
    lines += truth_lines(r)
    if r.eval_error:
        say(f"  evaluation skipped: {r.eval_error}")
    say(f"  wrote {r.outdir}/: {', '.join(r.written)}")
    return lines


def truth_lines(r: RunResult) -> list[str]:
    """The summary's errors against the log's ``/ground_truth``: a table over the poses the run vouches for
    (``ok`` or ``degraded``, :data:`fgloc.eval.metrics.VOUCHED_STATUSES`), each other pose counted by status
    with its error beside it; over every pose when the run vouches for fewer than 2."""
    if r.metrics is None:
        return []
    from fgloc.eval.metrics import VOUCHED_STATUSES
    from fgloc.eval.paper import comparison_cells, justified

    cols = [(f"{r.backend} (final)", r.metrics, r.by_status)]
    if r.metrics_online is not None:
        cols.append((f"{r.backend} (online)", r.metrics_online, r.by_status_online))
    split = all(sp is not None and sp.metrics is not None for _, _, sp in cols) and any(
        sp.n_left_out for _, _, sp in cols)
    where = " (SE(2)-aligned, odom frame)" if r.mode == "odom" else ""
    out = []
    if split:
        sp0 = cols[0][2]
        out.append(f"  vs /ground_truth{where}, over the poses the run vouches for ({' or '.join(VOUCHED_STATUSES)}: "
                   f"{sp0.n_vouched} of {sp0.n_vouched + sp0.n_left_out} final):")
    else:  # nothing left out, or too few vouched poses in a column to make one: every pose, said so
        few = [f"{lab}: {sp.n_vouched} of {sp.n_vouched + sp.n_left_out} ({sp.left_out_counts()})"
               for lab, _m, sp in cols if sp is not None and sp.metrics is None]
        out.append(f"  vs /ground_truth{where}" + (f", over every pose (the run vouches for fewer than 2; "
                                                   f"{' or '.join(VOUCHED_STATUSES)}: {'; '.join(few)})"
                                                   if few else "") + ":")
    rows = {lab: [sp.metrics if split else m] for lab, m, sp in cols}
    # no paper column: its numbers are the paper's robot's, not a reference for this log
    # (fgloc eval --paper and fgloc bench paper put them beside a run of the paper's experiment)
    header, body = comparison_cells(rows, extra=False, paper_column=False)
    out += ["    " + "  ".join(cells).rstrip() for cells in justified([header, *body])]
    for lab, _m, sp in cols if split else ():  # the poses not in the table, beside it
        if sp is not None and sp.n_left_out:
            out.append(f"    left out of {lab}: {sp.left_out_errors()})")
    return out


# ---------------------------------------------------------------------- CLI
def register(app: typer.Typer) -> None:
    @app.command("run")
    def run_cmd(
        log: Path = typer.Argument(..., help="the log: ROS 2 MCAP, rosbag2 folder, ROS 1 .bag or CARMEN .clf/.log"),
        map_yaml: Path | None = typer.Option(None, "--map", help="map_server YAML; without it: odom-frame fusion"),
        backend: str = typer.Option("smoother", "--backend", help="ekf | smoother | batch"),
        frontend: str = typer.Option("native", "--frontend", help="amcl | kiss | native"),
        initial_pose: tuple[float, float, float] | None = typer.Option(
            None, "--initial-pose", parser=pose_value,
            help="X Y YAW in the map: m, m and rad, or the yaw with its unit (90deg); "
            "without it: global localization"),
        config: Path | None = typer.Option(None, "--config", help="YAML overlaid on the defaults "
                                                       "(`fgloc config init` writes one)"),
        scan_topic: str | None = typer.Option(None, "--scan-topic", help="sensor_msgs/LaserScan topic "
                                              "(scan is /scan) [default: /scan, else the log's only LaserScan topic; "
                                              "a name given must exist; \"\": none]"),
        odom_topic: str | None = typer.Option(None, "--odom-topic", help="nav_msgs/Odometry topic [/odom, else "
                                              "the log's only Odometry topic; \"\": none]; with a config's "
                                              "sources.inputs: its odometry source reads it"),
        imu_topic: str | None = typer.Option(None, "--imu-topic", help="sensor_msgs/Imu (compass) topic [/imu, "
                                             "else the log's only Imu topic; \"\": none]; with a config's "
                                             "sources.inputs: its IMU source reads it"),
        static_transform: tuple[str, str, float, float, float, float, float, float] | None = typer.Option(
            None, "--static-transform", help=mounts.RPY_HELP + "; more in the config's sources.static_transforms"),
        static_transform_xyzw: tuple[str, str, float, float, float, float, float, float, float] | None = typer.Option(
            None, "--static-transform-xyzw", help=mounts.XYZW_HELP),
        outdir: Path = typer.Option(..., "-o", "--output", help="output folder (never an input's folder "
                                    "file: run.mcap, config.yaml ... are refused if they are inputs)"),
        force: bool = typer.Option(False, "--force", help="overwrite output files that fgloc run did not write"),
        allow_lost: bool = typer.Option(False, "--allow-lost", help="exit 0 even when the result is unusable "
                                        "(exit 3: lost at the end or longer than pipeline.max_lost_share, poses "
                                        "suspect or lost, no fix, a diverging fusion)"),
        quiet: bool = typer.Option(False, "--quiet", "-q", help="no progress bar"),
        view: str | None = typer.Option(None, "--view", help="[HOST:]PORT: serve a Foxglove WebSocket view "
                                        "(127.0.0.1 unless a host is given; layout: `fgloc view layout`)"),
        realtime: float | None = typer.Option(None, "--realtime", help="replay at R x real time "
                                              "(default: as fast as possible)"),
    ) -> None:
        """Localize a log: trajectory.tum, fixes.tum, run.mcap (/fused_pose + the view's channels), config.yaml."""
        from fgloc.app.startup import pause_gc, resume_gc

        pause_gc()  # until run_log's set-up is done (imports, map, localizer): fgloc.app.startup
        try:
            from fgloc.app.run import OUTPUT_FILES
            from fgloc.backends import check_backend
            from fgloc.io.outputs import refuse_file_name

            refuse_file_name(outdir, OUTPUT_FILES, "run")
            req = RunRequest(log=log, outdir=outdir, map_yaml=map_yaml, backend=check_backend(backend),
                             frontend=frontend,
                             initial_pose=pose_arg(initial_pose),
                             config=config,
                             scan_topic=scan_topic, odom_topic=odom_topic, imu_topic=imu_topic,
                             view=view, realtime=realtime, force=force,
                             static_transforms=mounts.static_transform_entries(static_transform,
                                                                               static_transform_xyzw))
            r = run_request(req, progress=progress_bar(quiet), announce=_announce)
        finally:
            resume_gc()  # an error before the set-up was done: an in-process caller keeps its collector
        _print_run_summary(r)
        failed = r.failure()
        if failed and (r.poses == 0 or not allow_lost):
            print(f"fgloc: lost: {r.log}: {failed}" if r.poses else f"fgloc: error: {r.log}: {failed}",
                  file=sys.stderr)
            raise SystemExit(EXIT_LOST)
