"""Fixtures of the output-layer fault suite: a tiny simulated log, small real file systems that
fill up (tmpfs) or fail (a loop device whose backing store runs out), the CLI in a process."""

from __future__ import annotations

import errno
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

#: a 2 m drive in the paper's hall, 10 Hz laser: ~3 s of log, run.mcap ~200 KB
TINY = {"route": [[2.5, 3.0], [3.5, 3.0]], "laser": {"rate_hz": 10.0}}
#: 12 s of log (slow replays for the signal tests)
LONGER = {"route": [[2.5, 3.0], [6.5, 3.0], [6.5, 4.0]], "laser": {"rate_hz": 10.0}}
START = ("2.5", "3.0", "0.0")
FGLOC = str(Path(sys.executable).parent / "fgloc")


def _sim(tmp_path_factory, name: str, scenario: dict) -> Path:
    from fgloc.sim import run_scenario, write_sim

    d = tmp_path_factory.mktemp(name)
    write_sim(run_scenario(scenario, seed=0), d)
    return d


@pytest.fixture(scope="session")
def tiny(tmp_path_factory) -> Path:
    """log.mcap, map.yaml/.pgm, ground_truth.tum of a 3 s simulated drive."""
    return _sim(tmp_path_factory, "tiny", TINY)


@pytest.fixture(scope="session")
def longer(tmp_path_factory) -> Path:
    """The same files for a 12 s drive."""
    return _sim(tmp_path_factory, "longer", LONGER)



def error_line(err: str) -> str:
    """The one ``fgloc: error:`` line of stderr (asserting there is exactly one line and no traceback)."""
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    assert "Traceback" not in err, err
    assert len(lines) == 1 and lines[0].startswith("fgloc: error: "), err
    return lines[0]


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` (hidden ones included, staging folders not) by relative path."""
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and not p.relative_to(folder).as_posix().startswith(".fgloc-staging-")}


def staging_left(folder: Path) -> list[Path]:
    return [p for p in folder.rglob(".fgloc-staging-*")]


def popen(*args: str, **kw) -> subprocess.Popen:
    """``fgloc ARGS`` as a child process with SIGINT at its default (a test run as a background job
    of a shell inherits SIGINT ignored, and a Python started so never sees Ctrl-C)."""
    return subprocess.Popen([FGLOC, *map(str, args)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL), **kw)


class SmallDisks:
    """Real small file systems, unmounted at the end: ``tmpfs(kib)`` fills up (ENOSPC);
    ``failing(kib)`` is an ext4 on a loop device whose backing tmpfs is smaller than it, so
    writes past that fail in the block layer (EIO)."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.mounts: list[Path] = []
        self.loops: list[str] = []

    def _mount(self, args: list[str], at: Path, what: str) -> None:
        at.mkdir(parents=True)
        r = subprocess.run(["mount", *args, str(at)], capture_output=True, text=True)
        if r.returncode:
            pytest.skip(f"cannot mount {what} here ({r.stderr.strip() or r.returncode}): the disk-full tests "
                        f"mount small real file systems and need root (CI runs them as root)")
        self.mounts.append(at)

    def tmpfs(self, kib: int) -> Path:
        d = self.root / f"tmpfs{len(self.mounts)}"
        self._mount(["-t", "tmpfs", "-o", f"size={kib}k", "tmpfs"], d, "a tmpfs")
        return d

    def failing(self, backing_kib: int = 1024, fs_kib: int = 16384) -> Path:
        for tool in ("losetup", "mkfs.ext4"):
            if shutil.which(tool) is None:
                pytest.skip(f"{tool} not installed: the EIO test builds an ext4 on a loop device")
        back = self.tmpfs(backing_kib)
        img = back / "disk.img"
        with open(img, "wb") as f:
            f.truncate(fs_kib * 1024)
        r = subprocess.run(["mkfs.ext4", "-q", "-F", str(img)], capture_output=True, text=True)
        if r.returncode:
            pytest.skip(f"mkfs.ext4 failed: {r.stderr.strip()}")
        r = subprocess.run(["losetup", "-f", "--show", str(img)], capture_output=True, text=True)
        if r.returncode:
            pytest.skip(f"no loop device here ({r.stderr.strip()}): the EIO test needs one")
        dev = r.stdout.strip()
        self.loops.append(dev)
        d = self.root / f"ext4{len(self.mounts)}"
        self._mount([dev, "-o", "errors=continue"], d, "an ext4 on a loop device")
        return d

    def close(self) -> None:
        for d in reversed(self.mounts):
            subprocess.run(["umount", "-l", str(d)], capture_output=True)
        for dev in self.loops:
            subprocess.run(["losetup", "-d", dev], capture_output=True)


@pytest.fixture
def disks(tmp_path):
    d = SmallDisks(tmp_path / "mnt")
    try:
        yield d
    finally:
        d.close()


def fill(folder: Path, leave: int = 0) -> None:
    """Fill ``folder``'s file system, then free ``leave`` bytes again."""
    f = folder / f"filler{len(list(folder.glob('filler*')))}.bin"
    with open(f, "wb", buffering=0) as fh:
        block = b"\0" * 4096
        try:
            while True:
                fh.write(block)
        except OSError as e:
            assert e.errno == errno.ENOSPC
    if leave:
        os.truncate(f, max(0, f.stat().st_size - leave))
