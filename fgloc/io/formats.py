"""Which reader a path needs, decided by content (magic bytes, folder contents), not by name."""

from __future__ import annotations

from pathlib import Path

from fgloc.errors import LogError, read_user_head
from fgloc.io.mcap_format import MCAP_MAGIC
from fgloc.io.rosbag1 import is_ros1_head
from fgloc.io.rosbag2 import SQLITE_MAGIC, compressed_bag
from fgloc.io.source import LogSource
from fgloc.io.topics import Topics

LFS_POINTER = b"version https://git-lfs.github.com/spec/"


def lfs_pointer_error(p: Path, head: bytes) -> LogError | None:
    """A one-line error for a Git LFS pointer file (what a clone without git-lfs holds in place of
    a log: three text lines naming the real file's hash and size), else None."""
    if not head.startswith(LFS_POINTER):
        return None
    size = next((ln.split()[1] for ln in head.decode("utf-8", "replace").splitlines()
                 if ln.startswith("size ") and len(ln.split()) == 2), "?")
    return LogError(f"{p}: a Git LFS pointer, not the log ({size} bytes not downloaded): fetch it with "
                    "`git lfs pull` in its repository")


def _bag_files(folder: Path) -> list[Path]:
    """The data files of a rosbag2 folder (from metadata.yaml, else by suffix)."""
    files: list[Path] = []
    meta = folder / "metadata.yaml"
    if meta.is_file():
        try:
            import yaml

            info = (yaml.safe_load(meta.read_text()) or {}).get("rosbag2_bagfile_information") or {}
            files = [folder / str(f) for f in info.get("relative_file_paths") or []]
        except Exception:  # noqa: BLE001 - a broken metadata.yaml: look at the files themselves
            files = []
        files = [f for f in files if f.is_file()]
    return files or sorted([*folder.glob("*.mcap"), *folder.glob("*.db3")])


def detect_format(path: str | Path) -> tuple[str, Path]:
    """``(format, path to open)``: ``"mcap"`` (also a rosbag2 folder holding one uncompressed
    ``.mcap``: the path is then that file), ``"rosbag2"``, ``"rosbag1"`` or ``"carmen"``."""
    p = Path(path)
    if not p.exists():
        raise LogError(f"{p}: log file not found")
    if p.is_file() and p.name == "metadata.yaml":
        # a rosbag2 folder given by its metadata file (as `ros2 bag info` prints it): the folder is the log
        p = p.parent
    if p.is_dir():
        files = _bag_files(p)
        if not files and not (p / "metadata.yaml").is_file():
            raise LogError(f"{p}: is a directory without a log (no metadata.yaml, .db3 or .mcap file in it)")
        for f in files:
            err = lfs_pointer_error(f, read_user_head(f, 200))
            if err is not None:
                raise err
        if len(files) == 1 and read_user_head(files[0], 8) == MCAP_MAGIC and not compressed_bag(p):
            return "mcap", files[0]
        return "rosbag2", p
    head = read_user_head(p, 4096)
    err = lfs_pointer_error(p, head)
    if err is not None:
        raise err
    if head.startswith(MCAP_MAGIC):
        return "mcap", p
    if is_ros1_head(head):
        return "rosbag1", p
    if head.startswith(SQLITE_MAGIC):
        return "rosbag2", p
    if p.suffix.lower() == ".mcap":
        return "mcap", p  # the MCAP reader names what is wrong with it
    if not head:
        raise LogError(f"{p}: empty file (0 bytes), not a log")
    if head[:2] != b"\x1f\x8b" and head[:3] != b"BZh" and b"\x00" in head:
        raise LogError(f"{p}: not a log fgloc reads (not MCAP, a ROS 1 bag, a ROS 2 bag or CARMEN text)")
    return "carmen", p


def open_log(path: str | Path, topics: Topics | None = None, max_range_m: float | None = None) -> LogSource:
    """The :class:`LogSource` of a log of any format fgloc reads, chosen by content.

    ``topics`` names the topic of each role (default ``/scan``, ``/odom``, ...);
    ``max_range_m`` is the CARMEN no-return threshold (default: detected).  Raises
    :class:`~fgloc.errors.LogError` (one line: the file and the problem) for a missing,
    empty or unreadable log.
    """
    fmt, p = detect_format(path)
    if fmt == "mcap":
        from fgloc.io.mcap_reader import McapSource

        return McapSource(p, topics)
    if fmt == "rosbag2":
        from fgloc.io.rosbag2 import Rosbag2Source

        return Rosbag2Source(p, topics)
    if fmt == "rosbag1":
        from fgloc.io.rosbag1 import Rosbag1Source

        return Rosbag1Source(p, topics)
    from fgloc.io.carmen import CarmenSource

    return CarmenSource(p, topics, max_range_m=max_range_m)
