"""ROS 1 ``.bag`` files (read with ``rosbags``) as a stream of fgloc messages.

Topics of the types fgloc reads are converted with the same rules as the MCAP reader
(:mod:`fgloc.io.log`): ``sensor_msgs/LaserScan``, ``nav_msgs/Odometry`` (odometry and
ground truth), ``sensor_msgs/Imu`` (compass), ``tf2_msgs/TFMessage`` (``/tf``,
``/tf_static``) and ``geometry_msgs/PoseWithCovarianceStamped``.

Source topic names come from :class:`Topics` (the ``--*-topic`` options of ``fgloc import``);
when a role's topic is not in the bag but exactly one topic of that role's type is (other
than the ones already chosen), that one is used and logged.  Output names are always
fgloc's defaults (``/scan``, ``/odom``, ...), so imported logs need no renaming later.
Messages come in bag order (record time); their stamps are the header stamps.
A scanner mounted upside down (a transform on its tf chain turns the z axis down) cannot be
expressed by the 2-D transforms written out, so its scans are written mirrored (angles
negated), as the upright scanner in the same place would see them (as :class:`LogReader`
does for MCAP logs).
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from dataclasses import fields
from pathlib import Path
from typing import Any

from fgloc.errors import LogError
from fgloc.io.log import FROM_ROS, ROLE_TYPES, Topics, _mirror_scan, _tf_flips
from fgloc.types import LaserScan

log = logging.getLogger(__name__)

ROSBAG1_MAGIC = b"#ROSBAG V2.0"


def is_rosbag1(path: str | Path) -> bool:
    try:
        with Path(path).open("rb") as f:
            return f.read(len(ROSBAG1_MAGIC)) == ROSBAG1_MAGIC
    except OSError:
        return False


def _choose_topics(available: dict[str, str], topics: Topics, path: Path) -> dict[str, str]:
    """``{source topic: role}`` for the roles whose topic (or a unique same-type topic) exists.

    A topic named explicitly (not the default) that is not in the bag is an error.
    """
    chosen: dict[str, str] = {}
    default = Topics()
    for f in fields(Topics):
        role, name = f.name, getattr(topics, f.name)
        want = ROLE_TYPES[role]
        if available.get(name) == want:
            chosen[name] = role
            continue
        if name in available:
            log.warning("topic %s has type %s, expected %s for %s; skipped", name, available[name], want, role)
            continue
        if name != getattr(default, role):
            have = ", ".join(sorted(available)) or "none"
            raise LogError(f"{path}: {role} topic '{name}' not in bag (topics: {have})")
        if role in ("tf", "tf_static", "ground_truth", "fused"):
            continue  # never guessed
        same = [t for t, ty in available.items() if ty == want and t not in chosen and t not in
                {getattr(topics, g.name) for g in fields(Topics)}]
        if len(same) == 1:
            log.info("using %s (%s) as the %s topic", same[0], want, role)
            chosen[same[0]] = role
    return chosen


def iter_rosbag1(path: str | Path, topics: Topics | None = None,
                 counter: list[int] | None = None) -> Iterator[tuple[str, object]]:
    """``(output topic, message)`` of a ROS 1 bag, lazily, in bag order.

    ``counter`` (optional one-element list) gets the total message count of the chosen
    topics before the first message, for a progress bar.
    """
    from rosbags.rosbag1 import Reader, ReaderError

    path = Path(path)
    if not path.exists():
        raise LogError(f"{path}: bag file not found")
    try:
        reader = Reader(path)
        reader.open()
    except (ReaderError, OSError, ValueError) as e:
        raise LogError(f"{path}: cannot read ROS 1 bag ({e})") from None
    yield from _iter_bag(path, reader, ReaderError, False, topics, counter)


def iter_rosbag2(path: str | Path, topics: Topics | None = None,
                 counter: list[int] | None = None) -> Iterator[tuple[str, object]]:
    """``(output topic, message)`` of a ROS 2 bag folder (``metadata.yaml`` with SQLite ``.db3``
    or MCAP files, split bags too), read with ``rosbags``: the default storage of ROS 2 Humble
    (sqlite3) needs no ROS install to import."""
    from rosbags.rosbag2 import Reader
    from rosbags.rosbag2.errors import ReaderError

    path = Path(path)
    if path.is_file():  # a .db3 / .mcap inside the folder: the bag is the folder
        path = path.parent
    if not path.exists():
        raise LogError(f"{path}: bag folder not found")
    try:
        reader = Reader(path)
        reader.open()
    except (ReaderError, OSError, ValueError) as e:
        raise LogError(f"{path}: cannot read ROS 2 bag ({e})") from None
    yield from _iter_bag(path, reader, ReaderError, True, topics, counter)


def _iter_bag(path: Path, reader: Any, reader_error: type[Exception], ros2: bool, topics: Topics | None,
              counter: list[int] | None) -> Iterator[tuple[str, object]]:
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    topics = topics or Topics()
    out_names = {f.name: getattr(Topics(), f.name) for f in fields(Topics)}
    try:
        store = get_typestore(Stores.ROS2_HUMBLE if ros2 else Stores.ROS1_NOETIC)
        available = {c.topic: c.msgtype for c in reader.connections}
        chosen = _choose_topics(available, topics, path)
        if not chosen:
            have = ", ".join(f"{t} ({ty})" for t, ty in sorted(available.items())) or "none"
            raise LogError(f"{path}: no scan, odometry, IMU or tf topic to import (topics: {have})")
        conns = [c for c in reader.connections if c.topic in chosen]
        for c in conns:  # types the store lacks come with the bag's own definitions
            msgdef = getattr(getattr(c, "msgdef", None), "data", "")
            if c.msgtype not in store.fielddefs and msgdef:
                store.register(get_types_from_msg(msgdef, c.msgtype))
        deserialize = store.deserialize_cdr if ros2 else store.deserialize_ros1
        if counter is not None:
            counter.append(sum(c.msgcount for c in conns))
        convs: dict[str, Any] = {t: FROM_ROS[ROLE_TYPES[r]] for t, r in chosen.items()}
        parent_of: dict[str, str] = {}    # tf child frame -> parent frame
        flipped: dict[str, bool] = {}     # tf child frame -> its transform turns z down

        def mirrored(frame: str) -> bool:
            odd, cur = False, frame
            for _ in range(32):
                if cur not in parent_of:
                    break
                odd ^= flipped.get(cur, False)
                cur = parent_of[cur]
            return odd

        try:
            bad: set[str] = set()
            for conn, _t, raw in reader.messages(connections=conns):
                try:
                    msg = deserialize(raw, conn.msgtype)
                except Exception as e:  # noqa: BLE001 - an undecodable message is skipped
                    if conn.topic not in bad:
                        bad.add(conn.topic)
                        log.warning("%s: cannot decode %s (%s): %s; skipping such messages",
                                    path, conn.topic, conn.msgtype, e)
                    continue
                role = chosen[conn.topic]
                out = convs[conn.topic](msg, out_names[role])
                if role in ("tf", "tf_static"):
                    for tr, flip in zip(out, _tf_flips(msg), strict=True):
                        parent_of[tr.child] = tr.parent
                        flipped[tr.child] = flip
                elif isinstance(out, LaserScan) and mirrored(out.frame_id.lstrip("/")):
                    out = _mirror_scan(out)
                yield out_names[role], out
        except reader_error as e:
            log.warning("%s: bag data unreadable (%s); stopping there", path, e)
    finally:
        reader.close()
