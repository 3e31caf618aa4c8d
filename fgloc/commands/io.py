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
        topic: Annotated[list[str] | None, typer.Option("--topic", help="import only this topic (repeatable; "
                                                        "default: every topic)")] = None,
        rename: Annotated[list[str] | None, typer.Option("--rename", help="OLD=NEW: write topic OLD as NEW "
                                                         "(repeatable; default: every topic keeps its name)")] = None,
        scan_topic: Annotated[str | None, typer.Option(hidden=True, help="renamed to /scan")] = None,
        odom_topic: Annotated[str | None, typer.Option(hidden=True, help="renamed to /odom")] = None,
        imu_topic: Annotated[str | None, typer.Option(hidden=True, help="renamed to /imu")] = None,
        tf_static_topic: Annotated[str | None, typer.Option(hidden=True, help="renamed to /tf_static")] = None,
        tf_topic: Annotated[str | None, typer.Option(hidden=True, help="renamed to /tf")] = None,
        ground_truth_topic: Annotated[str | None, typer.Option(hidden=True, help="renamed to /ground_truth")] = None,
        max_range: Annotated[float | None, typer.Option(
            help="CARMEN: readings at or beyond this (m) are 'no return' (default: detected)")] = None,
        force: Annotated[bool, typer.Option("--force", help="overwrite an existing output not written by fgloc")
                         ] = False,
    ) -> None:
        """Convert a ROS 1 bag, a ROS 2 bag folder, an MCAP or a CARMEN log into ROS 2 MCAP: every
        topic under its own name, every message kept or counted with the reason (fgloc run / map /
        info also read the logs directly)."""
        from fgloc.errors import ConfigError
        from fgloc.io.convert import import_log
        from fgloc.io.topics import Topics, resolve_name

        given = {"scan": scan_topic, "odom": odom_topic, "imu": imu_topic, "tf_static": tf_static_topic,
                 "tf": tf_topic, "ground_truth": ground_truth_topic}
        topics = Topics(**{k: resolve_name(v) for k, v in given.items() if v})
        pairs: dict[str, str] = {}
        for r in rename or []:
            a, sep, b = r.partition("=")
            if not sep or not a.strip() or not b.strip():
                raise ConfigError(f"--rename {r}: give OLD=NEW, e.g. --rename /imu/data=/imu")
            pairs[a] = b
        res = import_log(src, output, topics, max_range_m=max_range, force=force, only=topic or None, rename=pairs)
        parts = ", ".join(f"{t}: {n}" for t, n in sorted(res.counts.items()))
        print(f"{res.dst}: imported {res.format} {res.src.name} in {res.seconds:.1f} s ({parts})")
        for a, b in sorted(res.renamed.items()):
            print(f"  renamed: {a} -> {b}")
        for t, (n, why) in sorted(res.dropped.items()):
            print(f"  dropped: {t}: {n} message(s), {why}")
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
        from fgloc.app.logmap import grid_topics

        for topic in grid_topics({t: ti["type"] for t, ti in s["topics"].items() if ti["count"]}):
            print(f"map: {topic} carries a map; as a map_server map: fgloc export {log_path}:{topic} -o map.yaml")
        if s["truncated"]:
            print(f"TRUNCATED: {s['truncated']}")
        damage = r.damage()
        if damage:
            print(f"DAMAGED: {damage}")
        if s["skipped"]:
            print("SKIPPED: " + ", ".join(f"{k} {n}" for k, n in sorted(s["skipped"].items())))
