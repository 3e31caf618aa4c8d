"""``fgloc replay LOG --ros2``: publish a log onto a ROS 2 graph over DDS (see fgloc.ros2.replay)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer


def register(app: typer.Typer) -> None:
    @app.command("replay")
    def replay_cmd(
        log: Annotated[Path, typer.Argument(help="MCAP, rosbag2 folder, ROS 1 bag or CARMEN log")],
        ros2: Annotated[bool, typer.Option("--ros2", help="publish on ROS 2 (DDS, Cyclone DDS); the only "
                                           "transport so far")] = False,
        rate: Annotated[float, typer.Option("--rate", help="x real time (0: as fast as subscribers take it)",
                                            min=0.0)] = 1.0,
        clock: Annotated[bool, typer.Option("--clock", help="also publish /clock (rosgraph_msgs/Clock) "
                                            "for nodes with use_sim_time")] = False,
        clock_hz: Annotated[float, typer.Option("--clock-hz", help="/clock messages per second of log time",
                                                min=0.1)] = 40.0,
        now: Annotated[bool, typer.Option("--now", help="header stamps moved onto the wall clock (the "
                                          "first message's is the moment it is published), as a robot's "
                                          "drivers stamp them: for nodes without use_sim_time")] = False,
        map_yaml: Annotated[Path | None, typer.Option("--map", help="map_server MAP.yaml to publish on /map "
                                                      "(transient local, as map_server)")] = None,
        domain: Annotated[int | None, typer.Option("--domain", help="DDS domain (default $ROS_DOMAIN_ID, "
                                                   "else 0)")] = None,
        interface: Annotated[str | None, typer.Option("--interface", help="network interface (name or "
                                                      "address) DDS uses (e.g. lo to stay on this machine)")
                             ] = None,
        wait: Annotated[float, typer.Option("--wait", help="wait up to S seconds for subscribers to match "
                                            "before the first message", min=0.0)] = 0.0,
        start_offset: Annotated[float, typer.Option("--start-offset", help="start S seconds into the log "
                                                    "(ros2 bag play's --start-offset; its static transforms before "
                                                    "are published still)", min=0.0)] = 0.0,
        duration: Annotated[float | None, typer.Option("--duration", help="publish S seconds of log from "
                                                       "there, then end (ros2 bag play's --playback-duration)",
                                                       min=0.0)] = None,
        quiet: Annotated[bool, typer.Option("--quiet", help="no progress bar")] = False,
    ) -> None:
        """Publish a log on DDS with ROS 2's names, types and QoS (a ROS-free `ros2 bag play`)."""
        import sys
        import threading

        from fgloc.errors import ConfigError

        if not ros2:
            raise ConfigError("fgloc replay: give --ros2 (publish on ROS 2 over DDS)")
        from fgloc.maps import load_map
        from fgloc.ros2.replay import replay
        from fgloc.ros2.transport import CycloneTransport

        occ = load_map(map_yaml) if map_yaml is not None else None
        transport = CycloneTransport(domain, interface, node_name="fgloc_replay")
        stop = threading.Event()
        progress = None
        if not quiet and sys.stderr.isatty():
            from tqdm import tqdm

            def progress(total: int):  # noqa: ANN202
                return tqdm(total=total, unit="msg", desc=f"replay {log.name}", file=sys.stderr)
        from fgloc.io import stop as stopping

        # SIGINT / SIGTERM: the first ends the replay after the message being published, a second exits
        try:
            with stopping.cooperative(on_stop=stop.set):
                stats = replay(log, transport, rate=rate, clock=clock, clock_hz=clock_hz, occ_map=occ,
                               stop=stop.is_set, progress=progress, wait_for_subscribers_s=wait, now=now,
                               start_offset_s=start_offset, duration_s=duration)
        finally:
            transport.close()
        parts = ", ".join(f"{t} {n}" for t, n in sorted(stats.published.items()))
        print(f"{log}: published {stats.messages} messages of {stats.log_s:.1f} s in {stats.wall_s:.1f} s on "
              f"domain {transport.domain_id} ({parts})" + (f"; {stats.dropped} dropped" if stats.dropped else ""))
        for t, why in sorted(stats.skipped.items()):
            print(f"  not published: {t} ({why})")
        if stop.is_set():
            raise typer.Exit(130)
