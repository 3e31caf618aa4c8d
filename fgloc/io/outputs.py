"""The one output-writing layer of every command: outputs confined to their folder, written to a
staging place and published whole, never onto an input or a file fgloc did not write (without
``--force``), a full or failing disk as one line.

* :class:`Outputs` - a command's files in one output folder (``fgloc run -o DIR``, ``map``,
  ``map-check``, ``simulate``, ``eval --plots``, ``demo``, ``bench paper -o``, every ``fgloc
  batch`` job).  Before any work, :meth:`Outputs.check` refuses (one line) a folder that is a
  file, an output name that is an input (always, even with ``force``), a folder where a file
  goes, and files of the command's output names that fgloc did not write (unless ``force``).
  The command writes into ``.fgloc-staging-*/`` inside the folder (same file system); on
  success each file is flushed to disk and renamed into place, the command's files this run
  did not produce are removed (no old check.yaml beside a new map), and the folder's record of
  what fgloc wrote, ``.fgloc-outputs.json``, is updated; on an error or a signal the staging
  folder goes and the folder holds exactly what it held before.
* :class:`OutputFile` - one file (``import -o``, ``live --record`` / ``--out``, ``config init
  -o``): written as ``NAME.partial`` beside it and renamed at the end.  A recording
  (``precious``) is never replaced without ``force``, and what a failing disk or a kill left of
  it stays as ``NAME.partial`` (readable: ``fgloc info``), never under the final name.
* Names are confined (:func:`confined`): no absolute path, no ``..``, no writing through a
  symbolic link inside the folder (a link at an output name is replaced, its target never
  written; it is not fgloc's, so only with ``force``).  :func:`safe_name` turns foreign text (a
  log's name) into one harmless path component.
* ``ENOSPC``, ``EDQUOT``, ``EFBIG``, ``EROFS`` and ``EIO`` while writing become
  :class:`OutputError` ``FILE: no space left on device ...`` (the CLI prints ``fgloc: error:``
  and exits 2).
* Publishing runs in a :func:`fgloc.io.stop.critical` section: a signal never cuts it.

Which files fgloc wrote: those listed in ``.fgloc-outputs.json`` whose content digest (size,
first and last 64 KiB) still matches, as written by the same command (or one that shares the
file: ``map`` and ``map-check`` write check.yaml); ``legacy(folder)`` names the files of an
output folder written before that record existed.  ``fgloc map sim -o sim`` does not replace the
map ``fgloc simulate`` wrote there without ``--force``.
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import secrets
import shutil
import socket
import stat
from collections.abc import Callable, Iterable
from pathlib import Path, PurePosixPath
from typing import IO, Any

from fgloc.errors import FglocError
from fgloc.io import stop

MANIFEST = ".fgloc-outputs.json"
MANIFEST_VERSION = 1
STAGING = ".fgloc-staging-"
PARTIAL = ".partial"

#: errors of a full or failing disk, turned into one line
DISK_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS, errno.EIO})

_DIGEST_SPAN = 64 * 1024

#: a partial recording this small holds a header at most (an MCAP's first chunk is written at 1 MiB
#: or at the end): nothing to keep
_EMPTY_PARTIAL_BYTES = 4096


class OutputError(FglocError):
    """An output that would destroy an input or a file fgloc did not write, leave its folder, or
    could not be written (a full or failing disk)."""


# ---------------------------------------------------------------------------- names
def safe_name(text: str, fallback: str = "output") -> str:
    """One path component made from foreign text (a log's name): separators and NULs become
    ``_``, leading dots become ``_`` (so neither ``..`` nor a hidden name), empty is ``fallback``."""
    name = "".join("_" if c in "/\\\0" else c for c in str(text)).strip()
    stripped = name.lstrip(".")
    name = "_" * (len(name) - len(stripped)) + stripped
    return name or fallback


def confined(root: str | Path, rel: str | os.PathLike[str], folder: bool = False) -> Path:
    """``root/rel``, refusing a name that leaves ``root``: absolute, empty, ``.`` or ``..``
    components, or a folder on the way that is a symbolic link or a file (``folder``: ``rel``
    itself is a folder, checked the same way)."""
    root = Path(root)
    text = os.fspath(rel)
    parts = text.replace("\\", "/").split("/")
    if not text or "\0" in text or PurePosixPath(text).is_absolute() or any(p in ("", ".", "..") for p in parts):
        raise OutputError(f"{root}: output name {text!r} would leave the output folder")
    path = root
    for part in parts if folder else parts[:-1]:
        path = path / part
        if path.is_symlink():
            raise OutputError(f"{path}: is a symbolic link; outputs are never written through links "
                              f"(remove it, or choose another output folder)")
        if path.exists() and not path.is_dir():
            raise OutputError(f"{path}: is a file where an output folder goes")
    return root.joinpath(*parts)


def refuse_file_name(folder: str | Path, names: Iterable[str], command: str, option: str = "-o") -> None:
    """A new output folder named like one of the command's own files (``fgloc map -o map.yaml``,
    ``fgloc run -o run.tum``) is a file name typed where a folder goes: :class:`OutputError`, one
    line naming the folder to give instead.  An existing folder of any name is used as it is."""
    f = Path(folder)
    names = tuple(names)
    kinds = {PurePosixPath(n).suffix.lower() for n in names} - {""}
    if ".yaml" in kinds:
        kinds.add(".yml")
    if f.exists() or f.suffix.lower() not in kinds:
        return
    shown = ", ".join(names[:3]) + (", ..." if len(names) > 3 else "")
    raise OutputError(f"{f}: {option} takes a folder (fgloc {command} writes {shown} in it), not a "
                      f"{f.suffix} file name; give a folder, e.g. {option} {f.with_suffix('')}")


def same_file(a: str | Path, b: str | Path) -> bool:
    """Whether two paths name the same existing file (symlinks, hard links, ``..`` resolved)."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        return Path(a).resolve() == Path(b).resolve()


def _input_paths(inputs: Iterable[str | Path | None]) -> list[Path]:
    """The inputs and, for a folder input (a rosbag2 folder), the files in it."""
    out: list[Path] = []
    for src in inputs:
        if src is None:
            continue
        p = Path(src)
        out.append(p)
        if p.is_dir():
            out += [f for f in p.iterdir() if f.is_file()]
    return out


def _is_input(p: Path, inputs: list[Path]) -> Path | None:
    if not os.path.lexists(p):
        return None
    for src in inputs:
        if same_file(p, src):
            return src
    return None


# ---------------------------------------------------------------------------- disk errors
def is_disk_error(e: BaseException) -> bool:
    return isinstance(e, OSError) and e.errno in DISK_ERRNOS


def problem(e: OSError) -> str:
    """``no space left on device`` (the error's text, lower case)."""
    text = e.strerror or os.strerror(e.errno or 0) or str(e)
    return text[:1].lower() + text[1:]


# ---------------------------------------------------------------------------- record of what fgloc wrote
def digest(path: str | Path) -> str | None:
    """A file's content digest: its size and its first and last 64 KiB (None if unreadable)."""
    h = hashlib.sha256()
    try:
        with open(path, "rb") as f:
            size = os.fstat(f.fileno()).st_size
            h.update(str(size).encode())
            h.update(f.read(_DIGEST_SPAN))
            if size > _DIGEST_SPAN:
                f.seek(max(_DIGEST_SPAN, size - _DIGEST_SPAN))
                h.update(f.read(_DIGEST_SPAN))
    except OSError:
        return None
    return h.hexdigest()[:32]


def read_manifest(folder: str | Path) -> dict[str, Any]:
    """``{name: {"by", "digest", "previous"}}`` of a folder's ``.fgloc-outputs.json`` (empty if none)."""
    try:
        doc = json.loads((Path(folder) / MANIFEST).read_text())
    except (OSError, ValueError):
        return {}
    files = doc.get("files") if isinstance(doc, dict) else None
    return {k: v for k, v in files.items() if isinstance(v, dict)} if isinstance(files, dict) else {}


def written_by_fgloc(folder: str | Path, name: str, manifest: dict[str, Any] | None = None,
                     by: Iterable[str] | None = None) -> bool:
    """Whether ``folder/name`` is a regular file listed in the folder's record with its content
    unchanged since (a link or anything else is not), written by one of the commands ``by``
    (None: any)."""
    p = Path(folder) / name
    try:
        if not stat.S_ISREG(os.lstat(p).st_mode):
            return False
    except OSError:
        return False
    entry = (read_manifest(folder) if manifest is None else manifest).get(name)
    if not entry or (by is not None and entry.get("by") not in set(by)):
        return False
    d = digest(p)
    return d is not None and d in (entry.get("digest"), entry.get("previous"))


def _fsync_file(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _fsync_dir(path: Path) -> None:
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError as e:  # some file systems cannot sync a folder: a disk error is still one
        if e.errno in DISK_ERRNOS:
            raise
    finally:
        os.close(fd)


def host_tag() -> str:
    """This host in a staging folder's name (a folder another host left is not this one's to remove)."""
    return safe_name(socket.gethostname(), "host").replace(".", "_")


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale_staging(folder: Path) -> list[Path]:
    """Remove staging folders that a killed fgloc on this host left in ``folder``."""
    removed: list[Path] = []
    try:
        entries = list(folder.iterdir())
    except OSError:
        return removed
    host = host_tag()
    for d in entries:
        if not d.name.startswith(STAGING) or not d.is_dir() or d.is_symlink():
            continue
        try:
            h, pid, _ = d.name[len(STAGING):].rsplit(".", 2)
            if h != host or _alive(int(pid)):
                continue
        except ValueError:
            continue
        shutil.rmtree(d, ignore_errors=True)
        removed.append(d)
    return removed


# ---------------------------------------------------------------------------- a folder of outputs
class Outputs:
    """A command's outputs in ``folder``: checked first, staged, published whole (module doc).

    ``names``: the files the command writes there (relative, ``/`` for sub-folders); existing
    ones are checked, and those of them this run does not produce are removed when it publishes.
    ``command``: for messages and the record (``"run"``).  ``inputs``: files never replaced.
    ``option``: how the user named the folder, for messages (``"-o"``).  ``legacy(folder)``: the
    names fgloc wrote there before the folder had a record.  ``shares``: other commands whose
    files of these names this one replaces (``map-check`` and ``map``: check.yaml).

    Use as a context manager: ``with Outputs(...) as out: write(out.path("x.tum")) ...``; the
    outputs are published when the block ends without an error and discarded otherwise.
    """

    def __init__(self, folder: str | Path, names: Iterable[str] = (), *, command: str,
                 inputs: Iterable[str | Path | None] = (), force: bool = False, option: str = "-o",
                 legacy: Callable[[Path], Iterable[str]] | None = None, shares: Iterable[str] = ()) -> None:
        self.folder = Path(folder)
        self.names = tuple(dict.fromkeys(names))
        for n in self.names:
            confined(self.folder, n)
        self.command = command
        self.by = (command, *shares)
        self.inputs = _input_paths(inputs)
        self.force = force
        self.option = option
        self.legacy = legacy
        self.stage: Path | None = None
        self.published: list[str] = []
        self._last: str | None = None
        self._unhook: Callable[[], None] | None = None
        self._checked = False
        self._made: list[Path] = []  # folders the with block created (removed again when nothing is published)

    # -- before the work -----------------------------------------------------------------
    def check(self) -> None:
        """The one-line refusals (module doc); nothing is written."""
        f = self.folder
        if f.exists() and not f.is_dir():
            raise OutputError(f"{f}: is a file; {self.option} takes a folder")
        if not f.is_dir():
            self._checked = True
            return
        existing = [n for n in self.names if os.path.lexists(confined(f, n))]
        for n in existing:
            p = f / n
            src = _is_input(p, self.inputs)
            if src is not None:
                same = "" if os.path.abspath(src) == os.path.abspath(p) else f" ({src} by another name)"
                raise OutputError(f"{p}: is an input of this command{same}; refusing to overwrite it "
                                  f"(choose another {self.option} folder)")
            if p.is_dir() and not p.is_symlink():
                raise OutputError(f"{p}: is a folder where fgloc {self.command} writes a file")
        if existing and not self.force:
            manifest = read_manifest(f)
            legacy = set(self.legacy(f)) if self.legacy is not None else set()
            foreign = [n for n in existing if not (written_by_fgloc(f, n, manifest, self.by)
                                                   or (n in legacy and not (f / n).is_symlink()))]
            if foreign:
                shown = ", ".join(n + (" (a symbolic link)" if (f / n).is_symlink() else "") for n in foreign)
                raise OutputError(f"{f}: holds {shown}, not written by fgloc {self.command}; pass --force to "
                                  f"overwrite, or choose another {self.option} folder")
        self._checked = True

    def __enter__(self) -> Outputs:
        if not self._checked:
            self.check()
        self._made = [d for d in (self.folder, *self.folder.parents) if not d.exists()]
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            remove_stale_staging(self.folder)
            stage = self.folder / f"{STAGING}{host_tag()}.{os.getpid()}.{secrets.token_hex(4)}"
            stage.mkdir()
        except OSError as e:
            raise OutputError(f"{e.filename or self.folder}: cannot create the output folder ({problem(e)})") from None
        self.stage = stage
        self._unhook = stop.at_hard_exit(lambda: shutil.rmtree(stage, ignore_errors=True))
        return self

    # -- during the work -----------------------------------------------------------------
    def path(self, name: str) -> Path:
        """Where to write output ``name`` now (in the staging folder; its folders made)."""
        if self.stage is None:
            raise RuntimeError("Outputs.path outside the with block")
        p = confined(self.stage, name)
        p.parent.mkdir(parents=True, exist_ok=True)
        self._last = name
        return p

    @property
    def dir(self) -> Path:
        """The folder to write into now (the staging folder: a file written there by its output
        name is an output; :meth:`path` also says which output a write error hit)."""
        if self.stage is None:
            raise RuntimeError("Outputs.dir outside the with block")
        return self.stage

    def final(self, name: str) -> Path:
        """Where output ``name`` will be once published."""
        return self.folder / name

    def staged(self) -> list[str]:
        """The files written so far, relative to the folder (layer files left out)."""
        if self.stage is None or not self.stage.is_dir():
            return []
        out = []
        for p in sorted(self.stage.rglob("*")):
            rel = p.relative_to(self.stage).as_posix()
            if p.is_file() and not p.is_symlink() and not _layer_file(rel):
                out.append(rel)
        return out

    # -- at the end ----------------------------------------------------------------------
    def publish(self) -> list[str]:
        """Flush the staged files to disk, rename them into the folder, remove the command's files
        this run did not produce, update the record; returns the names published."""
        stage = self.stage
        if stage is None:
            return self.published
        with stop.critical():
            try:
                written = self.staged()
                for rel in written:
                    self._last = rel
                    _fsync_file(stage / rel)
                manifest = read_manifest(self.folder)
                for rel in written:
                    old = manifest.get(rel)
                    prev = digest(self.folder / rel) if old and written_by_fgloc(self.folder, rel, manifest) \
                        else None
                    manifest[rel] = {"by": self.command, "digest": digest(stage / rel),
                                     **({"previous": prev} if prev else {})}
                stale = [n for n in self.names if n not in written and os.path.lexists(self.folder / n)]
                for n in stale:
                    manifest.pop(n, None)
                self._last = MANIFEST
                _write_json(stage / (MANIFEST + ".tmp"), {"version": MANIFEST_VERSION, "files": manifest})
                os.replace(stage / (MANIFEST + ".tmp"), self.folder / MANIFEST)
                for rel in written:
                    self._last = rel
                    dst = confined(self.folder, rel)
                    dst.parent.mkdir(parents=True, exist_ok=True)
                    os.replace(stage / rel, dst)
                for n in stale:
                    p = self.folder / n
                    if not p.is_dir() or p.is_symlink():
                        p.unlink()
                _fsync_dir(self.folder)
            except OSError as e:
                err = self._error(e, partly=any(not (stage / rel).exists() for rel in written), name=self._last)
                self.discard()
                raise err from None
            self.discard()
        self.published = written
        return written

    def discard(self) -> None:
        """Remove the staging folder (what was published stays)."""
        if self.stage is not None:
            shutil.rmtree(self.stage, ignore_errors=True)
            self.stage = None
        if self._unhook is not None:
            self._unhook()
            self._unhook = None

    def __exit__(self, exc_type: Any, exc: BaseException | None, tb: Any) -> None:
        if exc is None:
            self.publish()
            return
        err = self._error(exc) if isinstance(exc, OSError) and is_disk_error(exc) else None
        self.discard()
        for d in self._made:  # deepest first: a folder this command created stays only with outputs in it
            try:
                d.rmdir()
            except OSError:
                break
        if isinstance(exc, KeyboardInterrupt):
            stop.note(f"nothing was written to {self.folder} (what it held is unchanged)")
        elif err is not None:
            raise err from None

    def _newest(self) -> str | None:
        return _newest_in(self.stage)

    def _error(self, e: OSError, partly: bool = False, name: str | None = None) -> OutputError:
        """The one line of a write error: the output it hit (by its final name: ``name``, else the
        staged file written last) and the problem."""
        name = name or self._newest() or self._last
        fn = e.filename if isinstance(e.filename, str) else None
        tail = (f"the outputs in {self.folder} were replaced in part; run the command again" if partly
                else f"nothing was written to {self.folder} (what it held is unchanged)")
        if fn and self.stage is not None and fn.startswith(str(self.stage) + os.sep):
            name = Path(fn).relative_to(self.stage).as_posix()
        elif fn:
            return OutputError(f"{fn}: {problem(e)}; {tail}")
        where = self.folder / name if name else self.folder
        return OutputError(f"{where}: {problem(e)}; {tail}")


def _newest_in(stage: Path | None) -> str | None:
    """The staged file written last (the one a write error hit, when nothing else says)."""
    best: tuple[int, str] | None = None
    if stage is None:
        return None
    for p in stage.rglob("*"):
        try:
            st = p.lstat()
        except OSError:
            continue
        rel = p.relative_to(stage).as_posix()
        if stat.S_ISREG(st.st_mode) and not _layer_file(rel) and (best is None or st.st_mtime_ns >= best[0]):
            best = (st.st_mtime_ns, rel)
    return best[1] if best else None


def _layer_file(rel: str) -> bool:
    first = rel.split("/", 1)[0]
    return first == MANIFEST or first.startswith((STAGING, MANIFEST))


def _write_json(path: Path, doc: Any) -> None:
    with open(path, "w") as f:
        f.write(json.dumps(doc, indent=1, sort_keys=True) + "\n")
        f.flush()
        os.fsync(f.fileno())


# ---------------------------------------------------------------------------- one file
class OutputFile:
    """One output file ``path``, written as ``path.partial`` and renamed when complete.

    ``ours(path)``: whether an existing file there may be replaced without ``force`` (default:
    never).  ``precious``: a recording: an existing ``.partial`` (what a killed session left) is
    refused without ``force``, and on an error the partial file is kept (and said).
    ``option``: how the user named it, for messages (``"--record"``).
    """

    def __init__(self, path: str | Path, *, command: str, inputs: Iterable[str | Path | None] = (),
                 force: bool = False, ours: Callable[[Path], bool] | None = None, precious: bool = False,
                 option: str = "-o", what: str = "output") -> None:
        self.final = Path(path)
        self.command = command
        self.inputs = _input_paths(inputs)
        self.force = force
        self.ours = ours
        self.precious = precious
        self.option = option
        self.what = what
        self.stage = self.final.with_name(self.final.name + PARTIAL)
        self.kept: Path | None = None
        self._open = False

    def check(self) -> None:
        p = self.final
        src = _is_input(p, self.inputs)
        if src is not None:
            raise OutputError(f"{p}: is the input {src}; write the output elsewhere")
        if p.is_dir() and not p.is_symlink():
            raise OutputError(f"{p}: is a directory; give the {self.what} file's name")
        if os.path.lexists(p) and not self.force:
            if self.ours is None:
                raise OutputError(f"{p}: exists; pass --force to overwrite it")
            if p.is_symlink() or not self.ours(p):
                raise OutputError(f"{p}: exists and was not written by fgloc {self.command}; pass --force to "
                                  f"overwrite it, or choose another {self.option} name")
        if self.precious and not self.force and _holds_data(self.stage):
            raise OutputError(f"{self.stage}: what an earlier fgloc {self.command} left (killed, or its disk "
                              f"failed; fgloc info reads it): move it away, or pass --force to replace it")

    def __enter__(self) -> OutputFile:
        self.check()
        try:
            self.final.parent.mkdir(parents=True, exist_ok=True)
            if os.path.lexists(self.stage):
                self.stage.unlink()
        except OSError as e:
            raise OutputError(f"{e.filename or self.final}: cannot write {self.what} ({problem(e)})") from None
        self._open = True
        return self

    @property
    def path(self) -> Path:
        """Where to write now."""
        return self.stage

    def publish(self) -> Path:
        with stop.critical():
            try:
                _fsync_file(self.stage)
                os.replace(self.stage, self.final)
                _fsync_dir(self.final.parent)
            except OSError as e:
                self.discard(e)
                raise self._error(e) from None
        self._open = False
        return self.final

    def discard(self, why: BaseException | None = None) -> None:
        """Remove the partial file, or keep it (a recording that holds something)."""
        if not self._open:
            return
        self._open = False
        try:
            if self.precious and _holds_data(self.stage):
                self.kept = self.stage
                return
            self.stage.unlink(missing_ok=True)
        except OSError:
            pass

    def __exit__(self, exc_type: Any, exc: BaseException | None, tb: Any) -> None:
        if exc is None:
            self.publish()
            return
        self.discard(exc)
        if isinstance(exc, KeyboardInterrupt):
            stop.note(f"{self.final} not written" + (f" (what was recorded is in {self.kept})" if self.kept else ""))
        elif isinstance(exc, OSError) and is_disk_error(exc):
            raise self._error(exc) from None

    def _newest(self) -> str | None:
        return _newest_in(self.stage)

    def _error(self, e: OSError) -> OutputError:
        kept = f"; what was written is in {self.kept}" if self.kept else "; nothing was written"
        return OutputError(f"{self.final}: {problem(e)}{kept}")


def _holds_data(p: Path) -> bool:
    try:
        st = os.lstat(p)
    except OSError:
        return False
    return not stat.S_ISREG(st.st_mode) or st.st_size > _EMPTY_PARTIAL_BYTES


def write_text_output(path: str | Path, text: str, force: bool = False, what: str = "file",
                      command: str = "", option: str = "-o") -> Path:
    """Write ``text`` to a new file (an existing one only with ``force``), whole or not at all."""
    with OutputFile(path, command=command, force=force, option=option, what=f"{what} file") as out:
        out.path.write_text(text)
    return Path(path)


class GuardedFile:
    """A binary file for a long recording: the first write error (a full disk) stops the writing
    (later writes are dropped, so the file is a readable prefix) and is reported once through
    ``on_error``; :attr:`error` holds it."""

    def __init__(self, f: IO[bytes], on_error: Callable[[OSError], None] | None = None) -> None:
        self._f = f
        self.on_error = on_error
        self.error: OSError | None = None

    def _failed(self, e: OSError) -> None:
        if self.error is None:
            self.error = e
            if self.on_error is not None:
                self.on_error(e)

    def write(self, b: bytes) -> int:
        if self.error is None:
            try:
                return self._f.write(b)
            except OSError as e:
                self._failed(e)
        return len(b)

    def flush(self) -> None:
        if self.error is None:
            try:
                self._f.flush()
            except OSError as e:
                self._failed(e)

    def close(self) -> None:
        try:
            self.flush()
            self._f.close()
        except OSError as e:
            self._failed(e)

    @property
    def closed(self) -> bool:
        return self._f.closed
