"""``fgloc import`` (ROS 1 bag / ROS 2 bag / CARMEN / another MCAP -> fgloc's MCAP) and ``fgloc info``
(what a log holds)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer


def _fmt_time(t: float | None) -> str:
    return "-" if t is None else f"{t:.3f}"


def register(app: typer.Typer) -> None:
    @app.command("import")
    def import_cmd(
        src: Annotated[Path, typer.Argument(
            help="ROS 1 .bag, ROS 2 bag folder (.db3 or split .mcap), an MCAP (ROS 1 or ROS 2 encoded) or "
                 "CARMEN .clf/.log (also .gz/.bz2)")],
        output: Annotated[Path, typer.Option("-o", "--output", help="MCAP log to write")],
        scan_topic: Annotated[str, typer.Option(help="LaserScan topic in a bag")] = "/scan",
        odom_topic: Annotated[str, typer.Option(help="Odometry topic in a bag")] = "/odom",
        imu_topic: Annotated[str, typer.Option(help="Imu (compass) topic in a bag")] = "/imu",
        tf_static_topic: Annotated[str, typer.Option(help="static tf topic in a bag")] = "/tf_static",
        tf_topic: Annotated[str, typer.Option(help="tf topic in a bag")] = "/tf",
        ground_truth_topic: Annotated[str, typer.Option(help="ground-truth Odometry topic in a bag")] = (
            "/ground_truth"),
        max_range: Annotated[float | None, typer.Option(
            help="CARMEN: readings at or beyond this (m) are 'no return' (default: detected)")] = None,
        force: Annotated[bool, typer.Option("--force", help="overwrite an existing output not written by fgloc")
                         ] = False,
    ) -> None:
        """Convert a ROS 1 bag, a ROS 2 bag folder, an MCAP or a CARMEN log into fgloc's ROS 2 MCAP
        form (fgloc run / map / info also read them directly)."""
        from fgloc.io.convert import import_log
        from fgloc.io.topics import Topics

        topics = Topics(scan=scan_topic, odom=odom_topic, imu=imu_topic, tf_static=tf_static_topic,
                        tf=tf_topic, ground_truth=ground_truth_topic)
        res = import_log(src, output, topics, max_range_m=max_range, force=force)
        parts = ", ".join(f"{t}: {n}" for t, n in sorted(res.counts.items()))
        print(f"{res.dst}: imported {res.format} {res.src.name} in {res.seconds:.1f} s ({parts})")
        if res.skipped:
            print("  skipped: " + ", ".join(f"{k} {n}" for k, n in sorted(res.skipped.items())))

    @app.command("info")
    def info_cmd(
        log_path: Annotated[Path, typer.Argument(help="MCAP log, ROS 1 bag, ROS 2 bag folder or CARMEN log")],
    ) -> None:
        """Per-topic message counts and types, time span, and what is damaged: where a truncated
        log broke, damaged chunks, skipped lines."""
        from fgloc.io import open_log

        r = open_log(log_path)
        r.verify()
        s = r.summary()
        print(f"{s['path']}: {s['format']}, {s['messages']} messages, {s['duration']:.3f} s "
              f"({_fmt_time(s['start'])} .. {_fmt_time(s['end'])}), "
              f"{'indexed' if s['indexed'] else 'not indexed'}")
        width = max((len(t) for t in s["topics"]), default=5)
        for topic, ti in s["topics"].items():
            print(f"  {topic:<{width}}  {ti['count']:>8}  {ti['type']}")
        if s["truncated"]:
            print(f"TRUNCATED: {s['truncated']}")
        damage = r.damage()
        if damage:
            print(f"DAMAGED: {damage}")
        if s["skipped"]:
            print("SKIPPED: " + ", ".join(f"{k} {n}" for k, n in sorted(s["skipped"].items())))
