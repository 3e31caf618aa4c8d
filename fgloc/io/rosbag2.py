"""rosbag2 folders (``metadata.yaml`` with SQLite ``.db3`` or MCAP files, split bags too), read
with ``rosbags`` (:class:`Rosbag2Source`): the default storage of ROS 2 Humble (sqlite3) needs
no ROS install.  A folder holding a single uncompressed ``.mcap`` is read by
:class:`~fgloc.io.mcap_reader.McapSource` instead (see :func:`fgloc.io.formats.open_log`).

A recording that did not end cleanly (killed, power lost) leaves a folder without
``metadata.yaml`` (the recorder writes it when it closes) and, with SQLite's write-ahead log
(Foxy's and Galactic's recorder, Humble's ``resilient`` preset), its last messages in
``<file>.db3-wal`` beside the database.  A lone ``.db3`` is read without the metadata, and a
``-wal`` file's messages are read from a copy the log is merged into (``rosbags`` opens
databases immutable, which leaves the ``-wal`` out); where that cannot be done (split or
compressed bags) a warning says how many bytes are left out.  A ``metadata.yaml`` that disagrees
with the files is read with a warning: a database renamed after recording is read alone, a topic
whose QoS, serialization or type hash differ from the file's is read by topic and type.

``fgloc info`` calls a folder *indexed* when it is read through its ``metadata.yaml`` with nothing
left in a ``-wal`` (a clean recording, whose counts and time span the recorder wrote); one read
without it, or with unmerged messages, is *not indexed*.
"""

from __future__ import annotations

import logging
import shutil
import sqlite3
import tempfile
import weakref
from pathlib import Path
from typing import Any

from fgloc.errors import LogError
from fgloc.io.bags import BagSource
from fgloc.io.topics import Topics

log = logging.getLogger(__name__)

SQLITE_MAGIC = b"SQLite format 3\x00"


def _wal(db: Path) -> Path:
    return db.with_name(db.name + "-wal")


def _count(db: Path) -> int:
    con = sqlite3.connect(f"file:{db}?immutable=1", uri=True)
    try:
        return int(con.execute("SELECT COUNT(*) FROM messages").fetchone()[0])
    finally:
        con.close()


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
        self._open_path = self._unclean(p)
        super().__init__(p, topics)
        self.indexed = (self._open_path == p and p.is_dir() and (p / "metadata.yaml").is_file()
                        and not any(_wal(db).is_file() and _wal(db).stat().st_size > 0 for db in p.glob("*.db3")))

    def _unclean(self, p: Path) -> Path:
        """What ``rosbags`` opens for ``p``: ``p`` itself, its lone ``.db3`` when it has no
        ``metadata.yaml``, or a copy of that file with its ``-wal`` merged in (see the module doc)."""
        dbs = [p] if p.is_file() else sorted(p.glob("*.db3"))
        meta = p.is_dir() and (p / "metadata.yaml").is_file()
        if meta and len(dbs) == 1:
            listed = _listed_files(p)
            if listed and not any((p / f).exists() for f in listed):  # the database renamed after recording
                log.warning("%s: metadata.yaml names %s, not in the folder; reading %s alone", p,
                            ", ".join(listed), dbs[0].name)
                meta = False
        elif p.is_dir() and not meta:
            n = len(dbs) + len(list(p.glob("*.mcap")))
            if n > 1:
                raise LogError(f"{p}: no metadata.yaml beside its {n} storage files (a split recording that "
                               f"did not end cleanly); `ros2 bag reindex {p}` writes one")
            if len(dbs) == 1:
                log.warning("%s: no metadata.yaml (a recording that did not end cleanly?); reading %s alone",
                            p, dbs[0].name)
        walled = [db for db in dbs if _wal(db).is_file() and _wal(db).stat().st_size > 0]
        if not walled:
            return dbs[0] if p.is_dir() and not meta and dbs else p
        if len(dbs) > 1 or (meta and compressed_bag(p)):
            log.warning("%s: %s not read: %s (a recording that did not end cleanly; open the database once "
                        "with sqlite3 to merge them)", p, ", ".join(f"{_wal(db).name} ({_wal(db).stat().st_size} "
                                                                    "bytes)" for db in walled),
                        "the recorder's last messages, not yet merged into the database")
            return p
        return self._merged(dbs[0])

    def _merged(self, db: Path) -> Path:
        tmp = Path(tempfile.mkdtemp(prefix="fgloc-wal-"))
        weakref.finalize(self, shutil.rmtree, tmp, True)
        copy = tmp / db.name
        try:
            shutil.copyfile(db, copy)
            shutil.copyfile(_wal(db), _wal(copy))
            con = sqlite3.connect(copy)  # recovers the log's committed transactions
            try:
                con.execute("PRAGMA wal_checkpoint(TRUNCATE)")
            finally:
                con.close()
            before, after = _count(db), _count(copy)
        except (OSError, sqlite3.Error) as e:
            raise LogError(f"{db}: cannot merge {_wal(db).name} into a copy of the database ({e})") from None
        log.warning("%s: %s holds %d messages not yet merged into the database (a recording that did not end "
                    "cleanly); read from a merged copy: %d messages", db, _wal(db).name, after - before, after)
        return copy

    def _storage_connections(self, reader: Any, conns: list[Any]) -> list[Any]:
        """``conns`` (the metadata's topics) and, for each storage file's topic that none of them
        matches as ``rosbags`` matches (topic, type, serialization and QoS, type hash when both have
        one) but one names with the same type, that one again with the file's serialization, QoS and
        hash: without it a ``metadata.yaml`` rewritten by a tool (a Jazzy bag's converted for Humble)
        or edited by hand would read none of that topic's messages, silently."""
        def same(y: Any, x: Any) -> bool:
            return (y.topic == x.topic and y.msgtype == x.msgtype and y.ext == x.ext
                    and (not x.digest or not y.digest or y.digest == x.digest))

        extra: list[Any] = []
        folder = getattr(reader, "storage", reader)  # rosbags' Reader wraps the folder's reader
        for storage in getattr(folder, "storages", None) or ():
            for x in getattr(storage, "connections", None) or ():
                if any(same(y, x) for y in (*conns, *extra)):
                    continue
                y = next((y for y in conns if y.topic == x.topic and y.msgtype == x.msgtype), None)
                if y is not None:
                    extra.append(y._replace(ext=x.ext, digest=x.digest))
        if extra:
            log.warning("%s: metadata.yaml's QoS / serialization / type hash of %s differ from the storage "
                        "files'; read by topic and type", self.path, ", ".join(sorted({c.topic for c in extra})))
        return [*conns, *extra]

    def _reader(self) -> Any:
        from rosbags.rosbag2 import Reader

        return Reader(self._open_path)

    def _reader_errors(self) -> tuple[type[Exception], ...]:
        from rosbags.rosbag2.errors import ReaderError

        return (ReaderError,)


def _listed_files(folder: Path) -> list[str]:
    """The storage files a folder's metadata.yaml names ([] when it cannot be read)."""
    import yaml

    try:
        info = yaml.safe_load((folder / "metadata.yaml").read_text(errors="replace"))["rosbag2_bagfile_information"]
        return [str(f) for f in info.get("relative_file_paths") or ()]
    except (OSError, yaml.YAMLError, TypeError, KeyError):
        return []


def compressed_bag(folder: Path) -> bool:
    """Whether a rosbag2 folder's metadata.yaml says its messages or files are compressed."""
    meta = folder / "metadata.yaml"
    if not meta.is_file():
        return False
    try:
        import yaml

        info = (yaml.safe_load(meta.read_text()) or {}).get("rosbag2_bagfile_information") or {}
    except Exception:  # noqa: BLE001
        return False
    return bool(info.get("compression_mode")) and str(info.get("compression_mode")).lower() != "none"
