"""Readers and writers: logs of every format fgloc reads, ROS 2 MCAP output, TUM trajectories.

``open_log(path, topics)`` returns a :class:`~fgloc.io.source.LogSource` for an MCAP file, a
rosbag2 folder, a ROS 1 bag or a CARMEN log (chosen by content); :class:`LogWriter`
(:mod:`fgloc.io.mcap_writer`) writes ROS 2 MCAP.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from fgloc.io.source import LogSource
    from fgloc.io.topics import Topics


def open_log(path: str | Path, topics: Topics | None = None, max_range_m: float | None = None) -> LogSource:
    """See :func:`fgloc.io.formats.open_log`."""
    from fgloc.io.formats import open_log as _open_log

    return _open_log(path, topics, max_range_m)
