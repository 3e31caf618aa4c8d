"""``import_log``: ROS 1 bags, ROS 2 bag folders (SQLite .db3 or split MCAP), MCAP files (ROS 1
encoded, as ``mcap convert`` writes them, or ROS 2) and CARMEN logs into fgloc's ROS 2 MCAP form,
through the same readers ``fgloc run`` uses (:func:`fgloc.io.open_log`)."""

from __future__ import annotations

import logging
import os
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from fgloc.errors import LogError
from fgloc.io.formats import open_log
from fgloc.io.mcap_format import MCAP_MAGIC
from fgloc.io.mcap_writer import LIBRARY, LogWriter
from fgloc.io.topics import Topics, choose_topics

log = logging.getLogger(__name__)


@dataclass
class ImportResult:
    src: Path
    dst: Path
    format: str                      # "rosbag1", "rosbag2", "mcap" or "carmen"
    counts: dict[str, int] = field(default_factory=dict)  # output topic -> messages
    seconds: float = 0.0
    skipped: dict[str, int] = field(default_factory=dict)  # bad lines / undecodable messages


def _input_files(src: Path) -> list[Path]:
    if src.is_dir():
        return [p for p in src.iterdir() if p.is_file()]
    return [src]


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return a.resolve() == b.resolve()


def written_by_fgloc(path: Path) -> bool:
    """Is ``path`` an MCAP whose header names fgloc as the writing library?"""
    try:
        with path.open("rb") as f:
            head = f.read(4096)
    except OSError:
        return False
    if not head.startswith(MCAP_MAGIC) or len(head) < 17 or head[8] != 0x01:
        return False
    p = 17
    try:
        n = int.from_bytes(head[p : p + 4], "little")
        p += 4 + n
        m = int.from_bytes(head[p : p + 4], "little")
        lib = head[p + 4 : p + 4 + m].decode()
    except (UnicodeDecodeError, IndexError):
        return False
    return lib.split()[0:1] == [LIBRARY] if lib else False


def check_output(dst: Path, inputs: list[Path], force: bool = False) -> None:
    """Refuse (one line) an output that is one of the inputs (never, even with ``force``), a
    directory, or an existing file not written by fgloc (unless ``force``)."""
    for src in inputs:
        for f in [src, *_input_files(src)]:
            if dst.resolve() == f.resolve() or _same_file(dst, f):
                raise LogError(f"{dst}: is the input {src}; write the output elsewhere")
    if dst.is_dir():
        raise LogError(f"{dst}: is a directory; give the output file's name")
    if dst.exists() and not force and not written_by_fgloc(dst):
        raise LogError(f"{dst}: exists and was not written by fgloc; pass --force to overwrite it")


def import_log(src: str | Path, dst: str | Path, topics: Topics | None = None,
               progress: bool | None = None, max_range_m: float | None = None,
               force: bool = False) -> ImportResult:
    """Convert a ROS 1 ``.bag``, a ROS 2 bag folder, an MCAP (ROS 1 or ROS 2 encoded) or a CARMEN
    ``.clf/.log`` (plain/gz/bz2) into ``dst`` (MCAP).

    ``topics`` names the source topics of a bag (outputs use the default names; a role whose
    default topic is absent takes the only topic of its type).  Each message keeps its log
    time (a bag's record time, a CARMEN line's timestamp), so the MCAP reads back in the order
    the source reads; ROS 2 bags' messages are copied as their CDR bytes with their schemas
    (lossless), others are converted (:mod:`fgloc.io.ros`).  ``progress``: a tqdm bar on
    stderr (None = only when stderr is a terminal).  ``max_range_m``: CARMEN no-return threshold override (see
    :mod:`fgloc.io.carmen`).  The output is written to ``dst`` through a temporary file and
    renamed at the end, so a failed import leaves no half-written log; an output that is the
    input, or an existing file fgloc did not write (unless ``force``), is refused.
    """
    from tqdm import tqdm

    src, dst = Path(src), Path(dst)
    check_output(dst, [src], force)
    source = open_log(src, Topics(), max_range_m=max_range_m)
    available = source.topic_types()
    chosen = choose_topics(available, topics or Topics(), src)
    if not chosen:
        have = ", ".join(f"{t} ({ty})" for t, ty in sorted(available.items())) or "none"
        raise LogError(f"{src}: no scan, odometry, IMU or tf topic to import (topics: {have})")
    use = Topics()
    for topic, role in chosen.items():
        setattr(use, role, topic)
    source.topics = use
    if source.has(use.scan) and (source.has(use.tf_static) or source.has(use.tf)):
        source.laser_mount()  # an upside-down scanner's scans are then written mirrored
    out_name = {topic: getattr(Topics(), role) for topic, role in chosen.items()}
    have = source.summary()["topics"]
    total = sum(have[t]["count"] for t in chosen)
    t0 = time.perf_counter()
    counts: Counter[str] = Counter()
    tmp = dst.with_name(dst.name + ".part")
    try:
        with LogWriter(tmp) as w, tqdm(total=total, unit="msg", desc=f"import {src.name}",
                                       disable=(None if progress is None else not progress), leave=False) as bar:
            for rec in source.records(set(chosen)):
                name = out_name[rec.topic]
                if rec.data is not None and rec.channel is not None:  # ROS 2 CDR: copied as it is
                    w.copy(rec, topic=name)
                elif isinstance(rec.msg, list):
                    w.write(name, rec.msg, stamp=rec.log_time_ns * 1e-9, log_time_ns=rec.log_time_ns)
                else:
                    w.write(name, rec.msg, log_time_ns=rec.log_time_ns)
                counts[name] += 1
                bar.update()
        if not sum(counts.values()):
            raise LogError(f"{src}: no messages to import")
        tmp.replace(dst)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    skipped = {**source.skipped, **{f"undecodable {t}": n for t, n in source.undecodable.items()}}
    return ImportResult(src, dst, source.format, dict(counts), time.perf_counter() - t0, skipped)

