"""``import_log``: ROS 1 bags, ROS 2 bag folders (SQLite .db3 or split MCAP), MCAP files (ROS 1
encoded, as ``mcap convert`` writes them, or ROS 2) and CARMEN logs into fgloc's ROS 2 MCAP form,
through the same readers ``fgloc run`` uses (:func:`fgloc.io.open_log`)."""

from __future__ import annotations

import logging
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from fgloc.errors import LogError
from fgloc.io.formats import open_log
from fgloc.io.mcap_format import MCAP_MAGIC
from fgloc.io.mcap_writer import LIBRARY, LogWriter
from fgloc.io.outputs import OutputFile
from fgloc.io.topics import Topics, choose_topics

log = logging.getLogger(__name__)

#: the MCAP header's library of an imported log (an import replaces its own earlier output only)
IMPORT_LIBRARY = f"{LIBRARY} import"


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


def mcap_library(path: Path) -> str | None:
    """The library an MCAP's header names (None: not an MCAP, or unreadable)."""
    try:
        with path.open("rb") as f:
            head = f.read(4096)
    except OSError:
        return None
    if not head.startswith(MCAP_MAGIC) or len(head) < 17 or head[8] != 0x01:
        return None
    p = 17
    try:
        n = int.from_bytes(head[p : p + 4], "little")
        p += 4 + n
        m = int.from_bytes(head[p : p + 4], "little")
        return head[p + 4 : p + 4 + m].decode()
    except (UnicodeDecodeError, IndexError):
        return None


def written_by_import(path: Path) -> bool:
    """Is ``path`` an MCAP that ``fgloc import`` wrote (its header's library)?"""
    return mcap_library(path) == IMPORT_LIBRARY


def output_file(dst: Path, inputs: list[Path], force: bool = False) -> OutputFile:
    """The import's output (:class:`fgloc.io.outputs.OutputFile`): an output that is one of the
    inputs is refused (never, even with ``force``), so is a directory, and an existing file that
    ``fgloc import`` did not write (unless ``force``: a recording or someone else's file)."""
    return OutputFile(dst, command="import", inputs=inputs, force=force, ours=written_by_import, what="output log")


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
    renamed at the end (``dst.partial`` meanwhile: :class:`fgloc.io.outputs.OutputFile`), so a
    failed or interrupted import leaves no half-written log; an output that is the input, or an
    existing file fgloc import did not write (unless ``force``), is refused.
    """
    from tqdm import tqdm

    from fgloc.io.topics import READ_TYPES, normalize_type, resolve_name

    src, dst = Path(src), Path(dst)
    out = output_file(dst, [src], force)
    out.check()
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
    with out:  # written as dst.partial, renamed when complete (fgloc.io.outputs)
        with LogWriter(out.path, library=IMPORT_LIBRARY) as w, \
                tqdm(total=total, unit="msg", desc=f"import {src.name}",
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
