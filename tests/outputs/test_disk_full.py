"""Every command on a full disk (a small real tmpfs: ENOSPC), on a failing one (ext4 on a loop
device whose backing store runs out: EIO) and over a file-size limit (RLIMIT_FSIZE: EFBIG): one
line ``fgloc: error: FILE: problem``, exit 2, nothing truncated left looking complete, and an
output folder's previous contents unchanged."""

from __future__ import annotations

import errno
import re
import resource
import shutil
import signal
import subprocess

from fgloc.testing.cli import run_cli as cli

from .conftest import FGLOC, START, error_line, fill, snapshot, staging_left

NOSPACE = "no space left on device"


def _nothing_left(folder):
    assert not staging_left(folder)
    assert not [p for p in folder.rglob("*.partial")]


def test_run_on_a_full_disk(tiny, disks):
    full = disks.tmpfs(64)
    rc, _, err = cli("run", tiny / "log.mcap", "--map", tiny / "map.yaml", "--initial-pose", *START,
                     "-o", full / "r", "-q")
    line = error_line(err)
    assert rc == 2 and re.match(rf"fgloc: error: {full}/r/\S+: {NOSPACE}; nothing was written to {full}/r ", line)
    assert not (full / "r").exists()  # the folder it made for nothing is gone
    _nothing_left(full)


def test_run_over_earlier_outputs_on_a_full_disk_keeps_them(tiny, disks):
    """Issue 32 item 6: a re-run that fails leaves the earlier outputs whole, not mixed with new ones."""
    full = disks.tmpfs(640)
    args = ["run", tiny / "log.mcap", "--map", tiny / "map.yaml", "--initial-pose", *START, "-o", full / "r", "-q"]
    rc, _, err = cli(*args)
    assert rc == 0, err
    before = snapshot(full / "r")
    fill(full, leave=16 * 1024)
    rc, _, err = cli(*args, "--backend", "ekf")
    assert rc == 2 and NOSPACE in error_line(err)
    assert snapshot(full / "r") == before
    _nothing_left(full)


def test_map_over_an_earlier_map_on_a_full_disk_keeps_it(tiny, disks):
    full = disks.tmpfs(1024)
    rc, _, err = cli("map", tiny / "log.mcap", "-o", full / "m", "--no-progress")
    assert rc == 0, err
    before = snapshot(full / "m")
    fill(full, leave=32 * 1024)
    rc, _, err = cli("map", tiny / "log.mcap", "-o", full / "m", "--no-progress", "--resolution", "0.04")
    assert rc == 2 and re.match(rf"fgloc: error: {full}/m/\S+: {NOSPACE}; ", error_line(err))
    assert snapshot(full / "m") == before
    _nothing_left(full)


def test_map_check_simulate_eval_import_config_on_a_full_disk(tiny, disks, tmp_path):
    full = disks.tmpfs(256)
    fill(full, leave=8 * 1024)
    scenario = tmp_path / "tiny.yaml"
    scenario.write_text("route: [[2.5, 3.0], [3.0, 3.0]]\nlaser: {rate_hz: 5.0}\n")
    rc, _, err = cli("map", tiny / "log.mcap", "-o", tmp_path / "m", "--no-progress", "--no-check")
    assert rc == 0, err
    cases = {
        "map-check": ["map-check", tmp_path / "m" / "map.yaml", tiny / "log.mcap", "-o", full / "c", "--no-progress"],
        "simulate": ["simulate", "scenario", scenario, "-o", full / "s"],
        "eval": ["eval", tmp_path / "m" / "trajectory.tum", tiny / "ground_truth.tum", "--align", "--plots",
                 full / "p"],
        "import": ["import", tiny / "log.mcap", "-o", full / "i.mcap"],
    }
    for name, args in cases.items():
        rc, out, err = cli(*args)
        assert rc == 2, (name, out, err)
        line = error_line(err)
        assert f": {NOSPACE}" in line and str(full) in line, (name, err)
    fill(full)  # small text files: the disk full to the last block
    for name, f in (("config", "c.yaml"), ("view", "layout.json")):
        rc, out, err = cli(name, "init" if name == "config" else "layout", "-o", full / f)
        assert rc == 2 and error_line(err) == f"fgloc: error: {full}/{f}: {NOSPACE}; nothing was written", (out, err)
    assert not [p.name for p in full.iterdir() if not p.name.startswith("filler")]  # no folder, partial, staging


def test_batch_run_on_a_full_disk(tiny, disks):
    """A job that hits the full disk is an error row naming the file; its folder holds nothing."""
    full = disks.tmpfs(128)
    fill(full, leave=24 * 1024)
    rc, out, err = cli("batch", "run", tiny / "log.mcap", "--map", tiny / "map.yaml", "--initial-pose", *START,
                       "-o", full / "b", "-q", "--engine", "local", "-j", "1")
    assert rc == 1, err
    from fgloc.batch import read_summary_csv

    (row,) = read_summary_csv(full / "b" / "summary.csv")
    assert row["status"] == "error" and NOSPACE in row["error"] and "log" in row["error"]
    assert not (full / "b" / "log" / "run.mcap").exists() and not staging_left(full)


def test_run_on_a_failing_disk_is_one_line(tiny, disks):
    """EIO (the disk's blocks cannot be written): found when the outputs are flushed before they
    are published, so nothing half-written is left looking complete."""
    bad = disks.failing(backing_kib=1024, fs_kib=16384)
    fill_tmp = disks.mounts[-2]  # the backing tmpfs: leave it a little room only
    fill(fill_tmp, leave=96 * 1024)
    rc, _, err = cli("run", tiny / "log.mcap", "--map", tiny / "map.yaml", "--initial-pose", *START,
                     "-o", bad / "r", "-q")
    line = error_line(err)
    assert rc == 2 and re.search(r": (input/output error|no space left on device); nothing was written", line), line
    assert not (bad / "r" / "run.mcap").exists()


def test_run_over_the_file_size_limit_is_one_line(tiny, tmp_path):
    """RLIMIT_FSIZE gives EFBIG ('file too large'), not ENOSPC; handled the same way."""
    out = tmp_path / "r"
    limit = 64 * 1024

    def limited() -> None:
        signal.signal(signal.SIGINT, signal.SIG_DFL)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    p = subprocess.run([FGLOC, "run", str(tiny / "log.mcap"), "--map", str(tiny / "map.yaml"), "--initial-pose",
                        *START, "-o", str(out), "-q"], capture_output=True, text=True, preexec_fn=limited)
    line = error_line(p.stderr)
    assert p.returncode == 2 and re.match(rf"fgloc: error: {out}/\S+: file too large; nothing was written", line)
    assert not out.exists()


def test_live_recording_on_a_full_disk_keeps_the_other_outputs(tmp_path, disks):
    """`fgloc live --record FULL/rec.mcap --out HEALTHY/live.tum`: the recording's disk fills; the
    live trajectory on the healthy disk is written all the same, the recording's error is one
    line (exit 2), what was recorded stays as rec.mcap.partial, never under the final name."""
    from .test_live_record import LiveFeed

    full = disks.tmpfs(32)
    with LiveFeed(tmp_path, seconds=4.0) as feed:
        rc, out, err = cli("live", *feed.args, "--duration", "3", "--quiet", "--json", "--record", full / "rec.mcap",
                           "-o", tmp_path / "live.tum")
    assert rc == 2, err
    line = [ln for ln in err.splitlines() if ln.startswith("fgloc: error: ")]
    assert line == [f"fgloc: error: {full}/rec.mcap: {NOSPACE}; what was recorded until then is in "
                    f"{full}/rec.mcap.partial"], err
    assert not (full / "rec.mcap").exists() and (full / "rec.mcap.partial").stat().st_size > 4096
    assert len((tmp_path / "live.tum").read_text().splitlines()) > 10
    assert '"record_error"' in out
    shutil.rmtree(tmp_path / "feed", ignore_errors=True)


def test_errno_set_is_what_a_disk_gives():
    from fgloc.io.outputs import DISK_ERRNOS

    assert {errno.ENOSPC, errno.EIO, errno.EFBIG, errno.EDQUOT, errno.EROFS} == set(DISK_ERRNOS)
