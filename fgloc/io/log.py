"""Compatibility names for code written against the old single-module reader/writer.

The reader interface is :mod:`fgloc.io.source` (``fgloc.io.open_log``); MCAP is read by
:mod:`fgloc.io.mcap_reader` and written by :mod:`fgloc.io.mcap_writer`; the conversion rules
live in :mod:`fgloc.io.ros`, the topic roles in :mod:`fgloc.io.topics`.  New code imports
from those modules.
"""

from __future__ import annotations

from pathlib import Path

from fgloc.io.mcap_format import MCAP_MAGIC
from fgloc.io.mcap_writer import LogWriter
from fgloc.io.ros import COV_IDX, FROM_ROS, sec_nsec_to_stamp, stamp_to_ns, stamp_to_sec_nsec
from fgloc.io.source import LogSource
from fgloc.io.topics import (
    IMU,
    LASER_SCAN,
    ODOMETRY,
    POSE_COV_STAMPED,
    ROLE_TYPES,
    TF_MESSAGE,
    Topics,
)

__all__ = [
    "COV_IDX", "FROM_ROS", "IMU", "LASER_SCAN", "MCAP_MAGIC", "ODOMETRY", "POSE_COV_STAMPED", "ROLE_TYPES",
    "TF_MESSAGE", "LogReader", "LogWriter", "Topics", "sec_nsec_to_stamp", "stamp_to_ns", "stamp_to_sec_nsec",
]


def LogReader(path: str | Path, topics: Topics | None = None) -> LogSource:  # noqa: N802 - the old class name
    """The log at ``path`` in any format fgloc reads: :func:`fgloc.io.open_log`."""
    from fgloc.io.formats import open_log

    return open_log(path, topics)
