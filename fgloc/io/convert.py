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
    # input topic -> (messages not written, why): every message of the input is written or counted here
    dropped: dict[str, tuple[int, str]] = field(default_factory=dict)
    renamed: dict[str, str] = field(default_factory=dict)  # input topic -> output topic (asked for)


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
               force: bool = False, only: list[str] | None = None,
               rename: dict[str, str] | None = None) -> ImportResult:
    """Convert a ROS 1 ``.bag``, a ROS 2 bag folder, an MCAP (ROS 1 or ROS 2 encoded) or a CARMEN
    ``.clf/.log`` (plain/gz/bz2) into ``dst`` (MCAP).

    Every topic keeps its name and every message is written, or counted in
    :attr:`ImportResult.dropped` with the reason: the types fgloc reads are converted
    (:mod:`fgloc.io.ros`) or, from a ROS 2 input, copied as their CDR bytes with their schemas
    (lossless); other types are copied from ROS 2 inputs and converted by rosbags from ROS 1
    bags.  ``only``: import these topics only.  ``rename``: ``{input topic: output topic}``;
    ``topics`` (the old role options): a role's topic that is not its default name is renamed to
    the default (``Topics(scan="/base_scan")``: ``/base_scan`` -> ``/scan``), and must exist.
    Each message keeps its log time (a bag's record time, a CARMEN line's timestamp), so the MCAP
    reads back in the order the source reads.  ``progress``: a tqdm bar on stderr (None = only when
    stderr is a terminal).  ``max_range_m``: CARMEN no-return threshold override (see
    :mod:`fgloc.io.carmen`).  The output is written to ``dst`` through a temporary file and
    renamed at the end, so a failed import leaves no half-written log; an output that is the
    input, or an existing file fgloc did not write (unless ``force``), is refused.
    """
    from tqdm import tqdm

    from fgloc.io.topics import READ_TYPES, normalize_type, resolve_name

    src, dst = Path(src), Path(dst)
    check_output(dst, [src], force)
    source = open_log(src, Topics(), max_range_m=max_range_m)
    available = {t: ty for t, ty in source.topic_types().items() if source.has(t)}
    have_line = ", ".join(f"{t} ({ty})" for t, ty in sorted(source.topic_types().items())) or "none"
    renames: dict[str, str] = {}
    default = Topics()
    names_line = ", ".join(sorted(source.topic_types())) or "none"
    for topic, role in (topics.roles().items() if topics is not None else ()):
        want = getattr(default, role)
        if topic != want:
            if topic not in available:
                raise LogError(f"{src}: {role} topic '{topic}' not in log (topics: {names_line})")
            renames[topic] = want
    for a, b in (rename or {}).items():
        a, b = resolve_name(a), resolve_name(b)
        if a not in available:
            raise LogError(f"{src}: --rename {a}: no such topic in the log (topics: {have_line})")
        renames[a] = b
    wanted = set(available)
    if only:
        wanted = {resolve_name(t) for t in only}
        missing = sorted(wanted - set(available))
        if missing:
            raise LogError(f"{src}: --topic {missing[0]}: no such topic in the log (topics: {have_line})")
    if not any(normalize_type(available[t]) in READ_TYPES for t in wanted):
        raise LogError(f"{src}: no scan, odometry, IMU or tf topic to import (topics: {have_line})")
    out_names = [renames.get(t, t) for t in wanted]
    clash = sorted({n for n in out_names if out_names.count(n) > 1})
    if clash:
        raise LogError(f"{src}: two topics would both be written as {clash[0]}; rename one of them")
    roles = {role: topic for topic, role in choose_topics(available, Topics(), src).items()}
    source.topics = Topics(**{r: roles.get(r, getattr(default, r)) for r in ("scan", "tf_static", "tf")})
    if source.has(source.topics.scan) and (source.has(source.topics.tf_static) or source.has(source.topics.tf)):
        source.laser_mount()  # an upside-down scanner's scans are then written mirrored
    source.keep_other_types = True
    have = source.summary()["topics"]
    total = sum(have[t]["count"] for t in wanted)
    t0 = time.perf_counter()
    counts: Counter[str] = Counter()
    read: Counter[str] = Counter()
    tmp = dst.with_name(dst.name + ".part")
    try:
        with LogWriter(tmp) as w, tqdm(total=total, unit="msg", desc=f"import {src.name}",
                                       disable=(None if progress is None else not progress), leave=False) as bar:
            for rec in source.records(wanted):
                name = renames.get(rec.topic, rec.topic)
                if rec.data is not None and rec.channel is not None:  # ROS 2 CDR: copied as it is
                    w.copy(rec, topic=name)
                elif isinstance(rec.msg, list):
                    w.write(name, rec.msg, stamp=rec.log_time_ns * 1e-9, log_time_ns=rec.log_time_ns)
                else:
                    w.write(name, rec.msg, log_time_ns=rec.log_time_ns)
                counts[name] += 1
                read[rec.topic] += 1
                bar.update()
        if not sum(counts.values()):
            raise LogError(f"{src}: no messages to import")
        tmp.replace(dst)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    dropped = {}
    for t in sorted(available):
        n = have[t]["count"] - read[t]
        if n <= 0:
            continue
        if t not in wanted:
            why = "not asked for (--topic)"
        elif source.undecodable.get(t):
            why = "undecodable"
        elif read[t] == 0 and normalize_type(available[t]) not in READ_TYPES:
            why = (f"type {available[t]} that fgloc does not read, stored in a way it cannot copy "
                   f"({source.format}: ROS 1 encoding, or a definition rosbags cannot convert)")
        else:
            why = "in damaged or cut-off data" if (source.damage() or source.truncated) else "not read"
        dropped[t] = (int(n), why)
    skipped = {**source.skipped, **{f"undecodable {t}": n for t, n in source.undecodable.items()}}
    return ImportResult(src, dst, source.format, dict(counts), time.perf_counter() - t0, skipped, dropped,
                        {a: b for a, b in renames.items() if a != b})
