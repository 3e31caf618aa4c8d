"""rosbag2 folders (``metadata.yaml`` with SQLite ``.db3`` or MCAP files, split bags too), read
with ``rosbags`` (:class:`Rosbag2Source`): the default storage of ROS 2 Humble (sqlite3) needs
no ROS install.  A folder holding a single uncompressed ``.mcap`` is read by
:class:`~fgloc.io.mcap_reader.McapSource` instead (see :func:`fgloc.io.formats.open_log`).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

from fgloc.errors import LogError
from fgloc.io.bags import BagSource
from fgloc.io.topics import Topics

SQLITE_MAGIC = b"SQLite format 3\x00"


class Rosbag2Source(BagSource):
    """A rosbag2 folder (or one of its ``.db3`` files) as a :class:`~fgloc.io.source.LogSource`."""

    format = "rosbag2"
    ros2 = True
    what = "ROS 2 bag"

    def __init__(self, path: str | Path, topics: Topics | None = None) -> None:
        p = Path(path)
        if p.is_file() and (p.parent / "metadata.yaml").is_file():  # a file inside the folder: the bag is the folder
            p = p.parent
        if not p.exists():
            raise LogError(f"{p}: bag folder not found")
        super().__init__(p, topics)

    def _reader(self) -> Any:
        from rosbags.rosbag2 import Reader

        return Reader(self.path)

    def _reader_errors(self) -> tuple[type[Exception], ...]:
        from rosbags.rosbag2.errors import ReaderError

        return (ReaderError,)


def iter_rosbag2(path: str | Path, topics: Topics | None = None) -> Iterator[tuple[str, object]]:
    """``(topic, message)`` of a rosbag2 folder's role topics in record-time order."""
    return Rosbag2Source(path, topics).messages()
