"""``fgloc replay LOG --ros2``: a log published on DDS as the robot that recorded it would.

Every topic of a type fgloc reads (:data:`fgloc.io.topics.READ_TYPES`) is published with its ROS 2
type at the log's pace (``rate`` x real time; 0: as fast as the subscribers take it): a ROS 2
input's CDR bytes as they were recorded, the other formats' messages (ROS 1, CARMEN) encoded by
fgloc's codecs.  QoS as ``ros2 bag play`` offers it by default (reliable, volatile, depth 10);
``/tf`` as tf2's broadcaster, ``/tf_static`` as tf2's static broadcaster (transient local: a
subscriber that starts later still gets it), with every static transform of the log merged into
the one message, as ``static_transform_publisher`` nodes leave it.  A log without ``/tf_static``
gets the laser mount the log reader finds (``fgloc run``'s) published there.  With a map
(``--map``) it is published once on ``/map`` as map_server does (transient local).  ``clock``:
``/clock`` (``rosgraph_msgs/Clock``) at ``clock_hz`` of log time, for nodes with use_sim_time.
``now``: every header stamp moved onto the wall clock (the first message's log time is the moment it
is published, later ones at the replay's rate), as a robot's drivers stamp them: for nodes on the
system clock (tf2 drops transforms older than its buffer) and to measure latencies as on a robot.
``start_offset_s`` / ``duration_s``: only that window of the log, from its first message (``ros2 bag
play``'s ``--start-offset`` / ``--playback-duration``); the static transforms before it are published
still (merged, as they would stand then), the pace anchored at the window's first message.

Topics of other types are not published (named in :attr:`ReplayStats.skipped`).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fgloc.io.topics import READ_TYPES, TF_MESSAGE, normalize_type
from fgloc.ros2 import codec, qos
from fgloc.ros2.transport import Transport
from fgloc.types import StaticTransform

TF_STATIC = "/tf_static"


@dataclass
class ReplayStats:
    published: dict[str, int] = field(default_factory=dict)
    skipped: dict[str, str] = field(default_factory=dict)  # topic -> why it is not published
    dropped: int = 0
    messages: int = 0
    log_s: float = 0.0
    wall_s: float = 0.0
    late_s: float = 0.0  # the most the publishing fell behind the log's pace


def _merge_static(merged: dict[str, StaticTransform], tfs: list[StaticTransform]) -> list[StaticTransform]:
    for t in tfs:
        merged[t.child.lstrip("/")] = t
    return list(merged.values())


def _wall_clock(log0_ns: int, wall0_ns: int, scale: float) -> Callable[[int], int]:
    """Log time (ns) -> wall clock (ns): ``log0_ns`` is ``wall0_ns``, the rest ``scale`` x as far apart."""
    return lambda t_ns: wall0_ns + round((t_ns - log0_ns) * scale)


def replay(log: str | Path, transport: Transport, rate: float = 1.0, clock: bool = False, clock_hz: float = 40.0,
           occ_map: Any = None, map_topic: str = "/map", map_frame: str = "map",
           stop: Callable[[], bool] | None = None, progress: Callable[[int], Any] | None = None,
           wait_for_subscribers_s: float = 0.0, now: bool = False, start_offset_s: float = 0.0,
           duration_s: float | None = None) -> ReplayStats:
    """Publish ``log`` (see the module docstring); returns what was published.  ``progress(total)``
    makes a progress bar (``update(n)``); ``wait_for_subscribers_s``: wait up to this long, before the
    first message, for subscribers (a node started before the replay): until every topic that discovery
    shows a subscriber of is matched."""
    from fgloc.io import open_log

    reader = open_log(Path(log))
    summ = reader.summary()
    stats = ReplayStats()
    types = {t: normalize_type(v["type"]) for t, v in summ["topics"].items() if v["count"]}
    topics = {t: ty for t, ty in types.items() if ty in READ_TYPES}
    for t, ty in types.items():
        if t not in topics:
            stats.skipped[t] = f"{ty}: not a type fgloc reads"
    pubs: dict[str, Any] = {}
    for t, ty in sorted(topics.items()):
        prof = qos.TF_STATIC_PUB if t == TF_STATIC else qos.TF if t == "/tf" else qos.DEFAULT
        pubs[t] = transport.publisher(t, ty, prof)
    static_pub = pubs.get(TF_STATIC)
    mount_pub = None
    if static_pub is None and any(ty == "sensor_msgs/msg/LaserScan" for ty in topics.values()):
        static_pub = mount_pub = transport.publisher(TF_STATIC, TF_MESSAGE, qos.TF_STATIC_PUB)
        if not now:  # else once the wall clock's offset is known, before the first message
            mount_pub.write(codec.encode([reader.laser_mount()], float(summ.get("start") or 0.0))[1])
            mount_pub = None
        stats.published[TF_STATIC] = 1
    clock_pub = transport.publisher("/clock", codec.CLOCK, qos.CLOCK) if clock else None
    if occ_map is not None:
        map_pub = transport.publisher(map_topic, codec.OCCUPANCY_GRID, qos.LATCHED_PUB)
        map_pub.write(codec.encode_map(occ_map, float(summ.get("start") or 0.0), map_frame))
        stats.published[map_topic] = 1
    transport.start()
    if wait_for_subscribers_s > 0:
        # until some subscriber is there and every topic that discovery shows a subscriber of is matched
        t_end = time.monotonic() + wait_for_subscribers_s

        def ready() -> bool:
            wanted = [p for t, p in pubs.items() if transport.remote_endpoints(t, "sub")]
            return bool(wanted) and all(p.health.matched for p in wanted)

        while time.monotonic() < t_end and not ready():
            time.sleep(0.05)
        time.sleep(0.2)
    merged: dict[str, StaticTransform] = {}
    total = sum(summ["topics"][t]["count"] for t in topics)
    bar = progress(total) if progress is not None else None
    t0_wall = time.monotonic()
    t0_log: float | None = None
    next_clock = -1.0
    pending = 0
    scale = 1.0 / rate if rate > 0 else 1.0
    to_wall: Callable[[int], int] = lambda t_ns: t_ns  # noqa: E731
    first_ns: int | None = None
    begin_ns = end_ns = 0
    try:
        for rec in reader.records(set(topics)):
            if stop is not None and stop():
                break
            if first_ns is None:
                first_ns = rec.log_time_ns
                begin_ns = first_ns + round(start_offset_s * 1e9)
                end_ns = begin_ns + round(duration_s * 1e9) if duration_s is not None else 0
            if duration_s is not None and rec.log_time_ns > end_ns:
                break
            if rec.log_time_ns < begin_ns:
                if rec.topic == TF_STATIC:
                    tfs = codec.decode_tf(rec.data)[0] if rec.data is not None else list(rec.msg)  # type: ignore[call-overload]
                    _merge_static(merged, tfs)
                continue
            t_log = rec.log_time_ns * 1e-9
            if t0_log is None:  # the log's pace (and --now's stamps) from the first message on
                t0_log, t0_wall = t_log, time.monotonic()
                if now:
                    to_wall = _wall_clock(rec.log_time_ns, time.time_ns(), scale)
                    if mount_pub is not None:
                        mount_pub.write(codec.encode([reader.laser_mount()], time.time())[1])
                if merged and static_pub is not None and rec.topic != TF_STATIC:  # those before the window
                    at = to_wall(rec.log_time_ns) * 1e-9 if now else t_log
                    if static_pub.write(codec.encode(list(merged.values()), at)[1]):
                        stats.published[TF_STATIC] = stats.published.get(TF_STATIC, 0) + 1
            if rate > 0:
                due = t0_wall + (t_log - t0_log) / rate
                wait = due - time.monotonic()
                if wait > 0:
                    time.sleep(wait)
                else:
                    stats.late_s = max(stats.late_s, -wait)
            if clock_pub is not None and t_log >= next_clock:
                clock_pub.write(codec.encode_clock(to_wall(rec.log_time_ns) * 1e-9 if now else t_log))
                next_clock = t_log + 1.0 / clock_hz
            topic = rec.topic
            if topic == TF_STATIC:
                tfs = codec.decode_tf(rec.data)[0] if rec.data is not None else list(rec.msg)  # type: ignore[call-overload]
                data = codec.encode(_merge_static(merged, tfs), t_log)[1]
            elif rec.data is not None and rec.channel is not None and codec.known(rec.channel.type):
                data = rec.data
            else:
                stamp = getattr(rec.msg, "stamp", None)
                data = codec.encode(rec.msg, t_log if stamp is None else None)[1]
            if now:
                try:
                    data = codec.restamp(topics[topic], data, to_wall)
                except codec.Undecodable:
                    stats.dropped += 1
                    continue
            if pubs[topic].write(data):
                stats.published[topic] = stats.published.get(topic, 0) + 1
            else:
                stats.dropped += 1
            stats.messages += 1
            pending += 1
            if bar is not None and pending >= 64:
                bar.update(pending)
                pending = 0
        if t0_log is not None:
            stats.log_s = t_log - t0_log
    finally:
        if bar is not None:
            bar.update(pending)
            if hasattr(bar, "close"):
                bar.close()
        stats.wall_s = time.monotonic() - t0_wall
    return stats
