"""Real signals at several points of `fgloc run`, `map`, `batch run` and `live` (child processes):
SIGINT and SIGTERM stop cleanly (exit 130, the interrupted line, the output folder as it was),
a second signal exits at once without losing what was complete, SIGKILL leaves nothing that
looks complete and the same command then works again without --force."""

from __future__ import annotations

import shutil
import signal
import time
from pathlib import Path

import pytest

from .conftest import START, popen, snapshot, staging_left

pytestmark = pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="reads /proc (Linux)")


def _wait(pred, timeout: float = 60.0, what: str = "") -> None:
    t_end = time.monotonic() + timeout
    while not pred():
        if time.monotonic() > t_end:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.02)


def _handles_sigterm(pid: int) -> bool:
    """Whether the process catches SIGTERM (fgloc's handlers are installed: the command has begun)."""
    try:
        text = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return True  # gone already
    caught = int(next(ln.split()[1] for ln in text.splitlines() if ln.startswith("SigCgt:")), 16)
    return bool(caught & (1 << (signal.SIGTERM - 1)))


def _staged(folder: Path, name: str) -> bool:
    return any((d / name).exists() for d in folder.glob(".fgloc-staging-*"))


def _finish(p, *signals: int, gap_s: float = 0.1) -> tuple[int, str, str]:
    for i, s in enumerate(signals):
        if i:
            time.sleep(gap_s)
        if p.poll() is None:
            p.send_signal(s)
    try:
        out, err = p.communicate(timeout=120)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    return p.returncode, out, err


def _no_traceback(err: str) -> None:
    assert "Traceback" not in err and "SystemError" not in err and "Segmentation" not in err, err


# ---------------------------------------------------------------------------------------- run
def _run_args(longer: Path, out: Path, *extra: str) -> list[str]:
    return ["run", str(longer / "log.mcap"), "--map", str(longer / "map.yaml"), "--initial-pose", *START,
            "-o", str(out), "-q", "--realtime", "4", *extra]


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_run_stopped_mid_run_then_the_same_command_works(longer, tmp_path, sig):
    """Issue 31: Ctrl-C on `fgloc run` left a partial run.mcap, and the same command again said it
    was 'not written by fgloc run; pass --force'.  Now: exit 130 with the interrupted line, the
    folder untouched (a fresh one not even created), the same command again works."""
    out = tmp_path / "out"
    p = popen(*_run_args(longer, out))
    _wait(lambda: _staged(out, "run.mcap") or p.poll() is not None, what="the run's staging")
    time.sleep(0.5)
    rc, _, err = _finish(p, sig)
    _no_traceback(err)
    name = signal.Signals(sig).name
    assert rc == 130 and err.strip().splitlines()[-1] == (
        f"fgloc: interrupted ({name}): nothing was written to {out} (what it held is unchanged)"), err
    assert not out.exists()
    if sig == signal.SIGINT:  # the same command again (a partial run.mcap made it refuse before)
        p = popen(*_run_args(longer, out, "--realtime", "50"))
        rc, _, err = _finish(p)
        assert rc == 0, err
        assert {"trajectory.tum", "run.mcap", "config.yaml"} <= {f.name for f in out.iterdir()}


def test_run_signals_at_set_up_twice_and_kill_keep_earlier_outputs(longer, tmp_path):
    out = tmp_path / "out"
    p = popen(*_run_args(longer, out, "--realtime", "50"))
    assert _finish(p)[0] == 0
    before = snapshot(out)
    # SIGTERM while it sets up (reading the log, building the localizer): stops before the first message
    p = popen(*_run_args(longer, out, "--backend", "ekf"))
    _wait(lambda: _handles_sigterm(p.pid), what="fgloc's handlers")
    rc, _, err = _finish(p, signal.SIGTERM)
    _no_traceback(err)
    assert rc == 130 and "fgloc: interrupted (SIGTERM)" in err and snapshot(out) == before
    # two Ctrl-C 0.1 s apart mid-run: out at once at the latest, the folder as it was, no staging left
    p = popen(*_run_args(longer, out, "--backend", "ekf"))
    _wait(lambda: _staged(out, "run.mcap"), what="the run's staging")
    time.sleep(0.5)
    rc, _, err = _finish(p, signal.SIGINT, signal.SIGINT)
    _no_traceback(err)
    assert rc == 130 and "fgloc: interrupted (SIGINT)" in err and snapshot(out) == before
    assert not staging_left(out)
    # SIGKILL mid-run: nothing can run, the earlier outputs stay whole; the next run clears the staging
    p = popen(*_run_args(longer, out, "--backend", "ekf"))
    _wait(lambda: _staged(out, "run.mcap"), what="the run's staging")
    time.sleep(0.5)
    rc, _, _ = _finish(p, signal.SIGKILL)
    assert rc == -signal.SIGKILL and snapshot(out) == before and staging_left(out)
    p = popen(*_run_args(longer, out, "--realtime", "50", "--backend", "ekf"))
    rc, _, err = _finish(p)
    assert rc == 0, err
    assert not staging_left(out) and snapshot(out) != before


# ---------------------------------------------------------------------------------------- map
@pytest.fixture(scope="module")
def earlier_map(longer, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("earlier") / "m"
    p = popen("map", str(longer / "log.mcap"), "-o", str(out), "-q")
    assert _finish(p)[0] == 0
    return out


@pytest.mark.parametrize("delay_s", [0.0, 0.6, 1.5], ids=["reading", "mapping", "later"])
def test_map_ctrl_c_at_several_points_is_a_clean_130(longer, earlier_map, tmp_path, delay_s):
    """Ctrl-C during `fgloc map` crashed 2 of 41 times (a numba SystemError, a segfault): the
    first signal now only asks, and the mapping stops between two scans.  The earlier map is kept."""
    out = tmp_path / "m"
    shutil.copytree(earlier_map, out)
    before = snapshot(out)
    p = popen("map", str(longer / "log.mcap"), "-o", str(out), "-q", "--resolution", "0.04")
    _wait(lambda: _staged(out, "") or p.poll() is not None, what="the map's staging")
    time.sleep(delay_s)
    rc, _, err = _finish(p, signal.SIGINT)
    _no_traceback(err)
    if rc == 0:  # it finished before the signal came: a whole new map, nothing mixed
        assert snapshot(out) != before and not staging_left(out)
        return
    assert rc == 130 and "fgloc: interrupted (SIGINT): nothing was written to" in err, err
    assert snapshot(out) == before and not staging_left(out)


def test_map_sigterm_and_double_sigint(longer, tmp_path):
    out = tmp_path / "m"
    for sigs in ((signal.SIGTERM,), (signal.SIGINT, signal.SIGINT)):
        p = popen("map", str(longer / "log.mcap"), "-o", str(out), "-q")
        _wait(lambda p=p: _staged(out, "") or p.poll() is not None, what="the map's staging")
        time.sleep(0.3)
        rc, _, err = _finish(p, *sigs)
        _no_traceback(err)
        assert rc == 130 and f"fgloc: interrupted ({signal.Signals(sigs[0]).name})" in err, err
        assert not out.exists() or not [f for f in out.iterdir()]
    p = popen("map", str(longer / "log.mcap"), "-o", str(out), "-q")
    assert _finish(p)[0] == 0  # and then the same command works


# ---------------------------------------------------------------------------------------- batch
@pytest.fixture
def two_logs(longer, tmp_path) -> Path:
    d = tmp_path / "logs"
    d.mkdir()
    for n in ("a", "b"):
        shutil.copy(longer / "log.mcap", d / f"{n}.mcap")
    return d


def _batch(logs: Path, longer: Path, out: Path):
    return popen("batch", "run", str(logs), "--map", str(longer / "map.yaml"), "--initial-pose", *START,
                 "-o", str(out), "-q", "-j", "1", start_new_session=True)


def _workers(pid: int) -> list:
    import psutil

    try:
        return [c for c in psutil.Process(pid).children(recursive=True) if "spawn_main" in " ".join(c.cmdline())]
    except psutil.NoSuchProcess:
        return []


@pytest.mark.parametrize("sigs", [(signal.SIGTERM,), (signal.SIGTERM, signal.SIGTERM), (signal.SIGKILL,)],
                         ids=["SIGTERM", "SIGTERM twice", "SIGKILL"])
def test_batch_stopped_by_a_service_manager_keeps_finished_logs(two_logs, longer, tmp_path, sigs):
    """SIGTERM (a service manager's stop) to the batch driver alone: the finished log is kept
    with its marker, no worker outlives the driver (a second signal kills them; SIGKILL of the
    driver reaches them as their parent-death signal), nothing half-written is left in a job's
    folder, and the same command then finishes the rest."""
    import psutil

    out = tmp_path / "out"
    p = _batch(two_logs, longer, out)
    _wait(lambda: len(list(out.glob("*/batch-done.json"))) >= 1 or p.poll() is not None, 180, "a finished log")
    workers = _workers(p.pid)
    rc, _, err = _finish(p, *sigs)
    _no_traceback(err)
    if sigs[0] == signal.SIGKILL:
        assert rc == -signal.SIGKILL
    else:
        assert rc == 130 and "fgloc: interrupted (SIGTERM)" in err, err
    assert workers
    _, alive = psutil.wait_procs(workers, timeout=15)
    assert not alive
    done = sorted(d.parent.name for d in out.glob("*/batch-done.json"))
    assert done == ["a"]
    assert not staging_left(out)
    p = _batch(two_logs, longer, out)
    rc, stdout, err = _finish(p)
    assert rc == 0, err
    assert "1 already done" in stdout and len(list(out.glob("*/batch-done.json"))) == 2


# ---------------------------------------------------------------------------------------- live
@pytest.mark.parametrize("sigs", [(signal.SIGINT,), (signal.SIGTERM,), (signal.SIGINT, signal.SIGINT)],
                         ids=["SIGINT", "SIGTERM", "SIGINT twice"])
def test_live_stops_cleanly_and_a_second_signal_never_loses_the_recording(tmp_path, sigs):
    """Two Ctrl-C within 0.3 s aborted `fgloc live`'s shutdown (recording not finalized, no --out
    files).  Now the first stops cleanly (exit 0); a second skips only the final smoothing (exit
    130): the recording is complete under its name and the live trajectory written either way."""
    from fgloc.io import open_log

    from .test_live_record import LiveFeed

    rec, tum, smoothed = tmp_path / "rec.mcap", tmp_path / "live.tum", tmp_path / "smoothed.tum"
    with LiveFeed(tmp_path, seconds=20.0, lead_s=0.2) as feed:
        p = popen("live", *feed.args, "--quiet", "--record", str(rec), "-o", str(tum), "--out-smoothed",
                  str(smoothed))
        _wait(lambda: (tmp_path / "rec.mcap.partial").exists() or p.poll() is not None, what="the recording")
        time.sleep(2.0)
        rc, _, err = _finish(p, *sigs, gap_s=0.1)
    _no_traceback(err)
    if len(sigs) == 1:
        assert rc == 0, err
    else:  # 0 when the shutdown was over before the second signal came
        assert rc == 0 or (rc == 130 and "fgloc: interrupted (SIGINT): the final smoothing was skipped" in err), err
    counts = {t: v["count"] for t, v in open_log(rec).summary()["topics"].items()}
    assert counts.get("/odom", 0) > 20 and counts.get("/scan", 0) > 5, counts
    assert not (tmp_path / "rec.mcap.partial").exists()
    assert len(tum.read_text().splitlines()) > 5


def test_live_killed_leaves_a_partial_recording_never_a_truncated_one(tmp_path):
    rec = tmp_path / "rec.mcap"
    from .test_live_record import LiveFeed

    with LiveFeed(tmp_path, seconds=20.0, lead_s=0.2) as feed:
        p = popen("live", *feed.args, "--quiet", "--record", str(rec))
        _wait(lambda: (tmp_path / "rec.mcap.partial").exists() or p.poll() is not None, what="the recording")
        time.sleep(1.0)
        rc, _, _ = _finish(p, signal.SIGKILL)
        assert rc == -signal.SIGKILL and not rec.exists()
        partial = tmp_path / "rec.mcap.partial"
        p = popen("live", *feed.args, "--quiet", "--record", str(rec), "--duration", "1")
        rc, _, err = _finish(p)
    if partial.exists() and partial.stat().st_size > 4096:  # a chunk was written: kept, refused
        assert rc == 2 and f"{partial}: what an earlier fgloc live left" in err, err
    else:  # a header only: nothing to keep, the new session records
        assert rc == 0 and rec.exists(), err
