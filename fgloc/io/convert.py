"""``import_log``: ROS 1 bags, ROS 2 bag folders (SQLite .db3 or split MCAP) and CARMEN logs
into fgloc's ROS 2 MCAP form."""

from __future__ import annotations

import logging
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from fgloc.errors import LogError
from fgloc.io.log import MCAP_MAGIC, LogWriter, Topics

log = logging.getLogger(__name__)


@dataclass
class ImportResult:
    src: Path
    dst: Path
    format: str                      # "rosbag1" or "carmen"
    counts: dict[str, int] = field(default_factory=dict)  # output topic -> messages
    seconds: float = 0.0


def detect_format(src: str | Path) -> str:
    """``"rosbag1"``, ``"rosbag2"`` (a bag folder or its .db3), ``"mcap"`` or ``"carmen"``
    (anything else is tried as CARMEN text)."""
    from fgloc.io.rosbag1 import ROSBAG1_MAGIC

    p = Path(src)
    if p.is_dir():
        if (p / "metadata.yaml").is_file() or any(p.glob("*.db3")) or any(p.glob("*.mcap")):
            return "rosbag2"
        raise LogError(f"{p}: is a directory without a ROS 2 bag (no metadata.yaml, .db3 or .mcap)")
    if p.suffix == ".db3":
        return "rosbag2"
    try:
        with p.open("rb") as f:
            head = f.read(16)
    except FileNotFoundError:
        raise LogError(f"{p}: file not found") from None
    except OSError as e:
        raise LogError(f"{p}: cannot open ({e.strerror or e})") from None
    if head.startswith(ROSBAG1_MAGIC):
        return "rosbag1"
    if head.startswith(MCAP_MAGIC):
        return "mcap"
    return "carmen"


def import_log(src: str | Path, dst: str | Path, topics: Topics | None = None,
               progress: bool | None = None, max_range_m: float | None = None) -> ImportResult:
    """Convert a ROS 1 ``.bag``, a ROS 2 bag folder or a CARMEN ``.clf/.log`` (plain/gz/bz2) into
    ``dst`` (MCAP).

    ``topics`` names the source topics of a bag (outputs use the default names).
    ``progress``: a tqdm bar on stderr (None = only when stderr is a terminal).
    ``max_range_m``: CARMEN no-return threshold override (see :mod:`fgloc.io.carmen`).
    The output is written to ``dst`` through a temporary file and renamed at the end,
    so a failed import leaves no half-written log.
    """
    from tqdm import tqdm

    src, dst = Path(src), Path(dst)
    fmt = detect_format(src)
    total: list[int] = []
    if fmt == "rosbag1":
        from fgloc.io.rosbag1 import iter_rosbag1

        it = iter_rosbag1(src, topics, counter=total)
    elif fmt == "rosbag2":
        from fgloc.io.rosbag1 import iter_rosbag2

        it = iter_rosbag2(src, topics, counter=total)
    elif fmt == "mcap":
        raise LogError(f"{src}: already an MCAP log; nothing to import")
    else:
        from fgloc.io.carmen import iter_carmen

        it = iter_carmen(src, max_range_m=max_range_m)
    t0 = time.perf_counter()
    counts: Counter[str] = Counter()
    tmp = dst.with_name(dst.name + ".part")
    try:
        with LogWriter(tmp) as w:
            first = next(it, None)  # errors in the source surface here, before the bar
            bar = tqdm(total=total[0] if total else None, unit="msg", desc=f"import {src.name}",
                       disable=(None if progress is None else not progress), leave=False)
            with bar:
                while first is not None:
                    topic, msg = first
                    w.write(topic, msg)
                    counts[topic] += 1
                    bar.update()
                    first = next(it, None)
        if not sum(counts.values()):
            raise LogError(f"{src}: no messages to import")
        tmp.replace(dst)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return ImportResult(src, dst, fmt, dict(counts), time.perf_counter() - t0)
