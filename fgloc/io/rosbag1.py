"""ROS 1 ``.bag`` files, read with ``rosbags`` (:class:`Rosbag1Source`).

Messages come in record-time order; the conversion rules are those of :mod:`fgloc.io.ros`
(ROS 1 and ROS 2 messages of these types have the same fields but for the header's ``seq``).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

from fgloc.errors import LogError
from fgloc.io.bags import BagSource
from fgloc.io.topics import Topics

ROSBAG1_MAGIC = b"#ROSBAG V2.0"


def is_rosbag1(path: str | Path) -> bool:
    try:
        with Path(path).open("rb") as f:
            return f.read(len(ROSBAG1_MAGIC)) == ROSBAG1_MAGIC
    except OSError:
        return False


class Rosbag1Source(BagSource):
    """A ROS 1 bag as a :class:`~fgloc.io.source.LogSource`."""

    format = "rosbag1"
    ros2 = False
    what = "ROS 1 bag"

    def __init__(self, path: str | Path, topics: Topics | None = None) -> None:
        if not Path(path).exists():
            raise LogError(f"{path}: bag file not found")
        super().__init__(path, topics)

    def _reader(self) -> Any:
        from rosbags.rosbag1 import Reader

        return Reader(self.path)

    def _reader_errors(self) -> tuple[type[Exception], ...]:
        from rosbags.rosbag1 import ReaderError

        return (ReaderError,)


def iter_rosbag1(path: str | Path, topics: Topics | None = None) -> Iterator[tuple[str, object]]:
    """``(topic, message)`` of a ROS 1 bag's role topics in record-time order."""
    return Rosbag1Source(path, topics).messages()
