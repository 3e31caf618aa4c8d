"""A map carried in a log, for ``fgloc export LOG[:TOPIC] -o map.yaml``.

Recordings made with a map running (``ros2 bag record -a`` beside nav2 or a SLAM node, a ROS 1 bag
with map_server's latched ``/map``) hold the map as ``nav_msgs/OccupancyGrid`` messages.  The last
message of the topic is the map (a SLAM node republishes its growing map; map_server latches one),
written as a map_server YAML and image that ``fgloc run --map``, ``map-check`` and nav2 read.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from pathlib import Path

from fgloc.errors import LogError
from fgloc.maps import OccupancyMap

OCCUPANCY_GRID = "nav_msgs/msg/OccupancyGrid"
#: undecodable last messages tolerated: the map is the last one that decodes among this many
KEEP_LAST = 4


@dataclass
class LogMap:
    """The map of a log's OccupancyGrid topic: the last message of ``count`` that decoded."""

    map: OccupancyMap
    topic: str
    count: int
    stamp_s: float  # log time of the message taken


def grid_topics(types: dict[str, str]) -> list[str]:
    """The topics of ``{topic: type}`` (any spelling of the type) that carry maps."""
    from fgloc.io.topics import normalize_type

    return sorted(t for t, ty in types.items() if normalize_type(ty) == OCCUPANCY_GRID)


def log_topic_type(path: str | Path, topic: str) -> str | None:
    """The normalized type of ``topic`` in the log at ``path`` (None: no such topic, or not a ROS log)."""
    from fgloc.io import open_log
    from fgloc.io.formats import detect_format
    from fgloc.io.topics import normalize_type

    kind, _ = detect_format(Path(path))
    if kind == "carmen":
        return None
    ty = open_log(path).topic_types().get(topic)
    return None if ty is None else normalize_type(ty)


def read_log_map(path: str | Path, topic: str | None = None) -> LogMap:
    """The map the log at ``path`` carries on ``topic`` (None: its only OccupancyGrid topic).
    One-line :class:`LogError` s: no such topic, not a map topic, several map topics, nothing decodable."""
    from fgloc.io import open_log
    from fgloc.io.formats import detect_format
    from fgloc.ros2.codec import Undecodable, decode

    path = Path(path)
    kind, _ = detect_format(path)
    if kind == "carmen":
        raise LogError(f"{path}: a CARMEN log carries no map (nav_msgs/OccupancyGrid)")
    src = open_log(path)
    every = src.topic_types()
    types = {t: ty for t, ty in every.items() if src.has(t)}
    grids = grid_topics(types)
    listing = ", ".join(grids) or "none"
    if topic is None:
        if len(grids) != 1:
            raise LogError(f"{path}: which map? name its topic as {path}:TOPIC (its map topics: {listing})"
                           if grids else f"{path}: no nav_msgs/OccupancyGrid topic with messages to read a map from")
        topic = grids[0]
    elif topic in every and topic not in types:
        raise LogError(f"{path}: {topic} has no messages (the recording holds its type only; its map topics: "
                       f"{listing})")
    elif topic not in types:
        raise LogError(f"{path}: no topic {topic} (its map topics: {listing})")
    elif topic not in grids:
        raise LogError(f"{path}: {topic} is {types[topic]}, not nav_msgs/OccupancyGrid (its map topics: {listing})")
    src.keep_other_types = True  # the readers hand over a type fgloc does not read as its CDR bytes
    last: deque[tuple[bytes, int]] = deque(maxlen=KEEP_LAST)
    count = 0
    for rec in src.records([topic]):
        count += 1
        if rec.data is not None:
            last.append((rec.data, rec.log_time_ns))
    problem = "no message could be read"
    for data, t_ns in reversed(last):
        try:
            m = decode(OCCUPANCY_GRID, data)
        except Undecodable as e:
            problem = str(e)
            continue
        if isinstance(m, OccupancyMap):
            return LogMap(m, topic, count, t_ns * 1e-9)
    raise LogError(f"{path}: {topic}: none of its last {len(last)} of {count} map message(s) decodes ({problem})")
