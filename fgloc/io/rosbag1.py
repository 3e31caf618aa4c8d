"""ROS 1 ``.bag`` files, read with ``rosbags`` (:class:`Rosbag1Source`).

Messages come in record-time order; the conversion rules are those of :mod:`fgloc.io.ros`
(ROS 1 and ROS 2 messages of these types have the same fields but for the header's ``seq``).
A bag ``rosbags`` cannot open through its index (format 1.2, an index the 2010 recorder wrote
with wrong lengths, a killed recording without one) is read by walking its records
(:mod:`fgloc.io.bagwalk`), with a warning that says why.
"""

from __future__ import annotations

import logging
import struct
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from fgloc.errors import LogError
from fgloc.io.bags import BagSource
from fgloc.io.bagwalk import ROS1_MAGICS, WalkedBag
from fgloc.io.topics import Topics

log = logging.getLogger(__name__)


def is_ros1_head(head: bytes) -> bool:
    """Whether a file's first bytes are a ROS 1 bag's first line (any format version)."""
    return head.startswith(ROS1_MAGICS)


class Rosbag1Source(BagSource):
    """A ROS 1 bag as a :class:`~fgloc.io.source.LogSource`."""

    format = "rosbag1"
    ros2 = False
    what = "ROS 1 bag"

    def __init__(self, path: str | Path, topics: Topics | None = None) -> None:
        if not Path(path).exists():
            raise LogError(f"{path}: bag file not found")
        self._walked: WalkedBag | None = None
        super().__init__(path, topics)
        self.indexed = self._walked is None
        if self._walked is not None and self._walked.broke:
            self.truncated = self._walked.broke

    def _open_reader(self) -> Any:
        if self._walked is not None:
            return self._walked
        reader = self._reader()
        try:
            reader.open()
            return reader
        except OSError as e:
            raise LogError(f"{self.path}: cannot read {self.what} ({e.strerror or e})") from None
        except (*self._reader_errors(), AssertionError, struct.error, ValueError, KeyError, IndexError,  # type: ignore[misc]
                EOFError) as e:
            why = str(e).rstrip(".") or f"{type(e).__name__} in its index"
        walked = WalkedBag(self.path)
        walked.open()  # LogError: not even its records read
        if not walked.connections and walked.broke:
            raise LogError(f"{self.path}: cannot read ROS 1 bag ({why}; walking its records: {walked.broke})")
        if walked.broke and walked.broke.startswith("file ends"):
            why = "the file is cut short"  # what rosbags tripped over is a consequence
        broke = f"; {walked.broke}" if walked.broke else ""
        broke += "".join(f"; chunk at byte {pos}: {why}" for pos, why in walked.damaged.items())
        if walked.version == "1.2":  # a format of its own, not a damaged bag: said only when cut
            log.log(logging.WARNING if broke else logging.INFO,
                    "%s: format 1.2 bag (ROS before 1.1) read record by record: %d messages%s",
                    self.path, walked.message_count, broke)
        else:
            fix = (f"; {walked.bad_index_lengths} index record(s) with a wrong length field"
                   if walked.bad_index_lengths else "")
            log.warning("%s: bag not read through its index (%s%s); read by walking its records: %d messages%s",
                        self.path, why, fix, walked.message_count, broke)
        self._walked = walked
        self._damaged.update(walked.damaged)
        return walked

    def _resume(self, conns: list[Any], after_t: int, n_at_t: int,
                error: Exception) -> Iterator[tuple[Any, int, Any]] | None:
        """After damage the index-driven read stumbled on (``error``): the rest by walking the
        records, where damaged records are skipped (ties in file order, as both reads give them)."""
        if self._walked is not None:
            return None  # the walk itself failed: nothing else to try
        walked = WalkedBag(self.path)
        walked.open()
        self._damaged.update(walked.damaged)
        log.warning("%s: damaged data after t=%.3f (%s); the rest read by walking its records%s", self.path,
                    after_t * 1e-9, str(error).rstrip(".") or type(error).__name__,
                    "".join(f"; chunk at byte {pos}: {why}" for pos, why in walked.damaged.items()))

        def rest() -> Iterator[tuple[Any, int, Any]]:
            skip = n_at_t
            for conn, t, raw in walked.messages(conns):
                if t < after_t:
                    continue
                if t == after_t and skip > 0:
                    skip -= 1
                    continue
                yield conn, t, raw
            if walked.broke:
                self.truncated = walked.broke

        return rest()

    def _reader(self) -> Any:
        from rosbags.rosbag1 import Reader

        return Reader(self.path)

    def _reader_errors(self) -> tuple[type[Exception], ...]:
        from rosbags.rosbag1 import ReaderError

        return (ReaderError,)
