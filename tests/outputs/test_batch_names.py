"""`fgloc batch run` keeps every output inside OUTDIR whatever the logs are called: a log named
`...mcap` got the output folder `..` and its results overwrote a user's config.yaml and
trajectory.tum in the parent folder.  Names from a manifest or a glob: `..`, `...mcap`,
`../x.mcap`, absolute paths, symlinks; a job folder that is a symlink; a user's files."""

from __future__ import annotations

import shutil
from pathlib import Path

from fgloc.testing.cli import run_cli as cli

from .conftest import START, snapshot


def _tree_outside(root: Path, outdir: Path) -> dict[str, bytes]:
    """Every file under ``root`` except those under ``outdir``."""
    return {k: v for k, v in snapshot(root).items() if not (root / k).resolve().is_relative_to(outdir.resolve())}


def test_hostile_log_names_stay_inside_outdir(tiny, tmp_path):
    root = tmp_path / "site"
    work = root / "work"
    logs = work / "logs"
    logs.mkdir(parents=True)
    for name in ("...mcap", "..mcap", ".hidden.mcap", "summary.csv.mcap"):
        shutil.copy(tiny / "log.mcap", logs / name)
    shutil.copy(tiny / "log.mcap", work / "x.mcap")                 # ../x.mcap from the manifest's folder
    (logs / "link.mcap").symlink_to(logs / "...mcap")             # a symlink to a hostile name
    absolute = tmp_path / "elsewhere" / "abs.mcap"
    absolute.parent.mkdir()
    shutil.copy(tiny / "log.mcap", absolute)
    for bait in (work / "config.yaml", work / "trajectory.tum", root / "config.yaml"):  # what `..` would hit
        bait.write_text("# the user's own file\n")
    manifest = logs / "fleet.csv"
    manifest.write_text("log,map,x,y,yaw\n"
                        "../x.mcap,,,,\n"
                        f"{absolute},,,,\n"
                        "link.mcap,,,,\n"
                        "..,,,,\n")                                 # a folder: read as a bag of its one MCAP
    outdir = work / "out"
    before = _tree_outside(tmp_path, outdir)
    rc, out, err = cli("batch", "run", str(logs), str(work / "*.mcap"), "--manifest", manifest,
                       "--map", tiny / "map.yaml", "--initial-pose", *START, "-o", outdir, "-q", "--engine", "inline")
    assert rc == 0, out + err
    assert _tree_outside(tmp_path, outdir) == before  # nothing written, nothing replaced outside OUTDIR
    from fgloc.batch import read_summary_csv

    rows = {r["log"]: r for r in read_summary_csv(outdir / "summary.csv")}
    folders = sorted(p.name for p in outdir.iterdir() if p.is_dir())
    assert all(n not in (".", "..") and "/" not in n and not n.startswith(".") for n in rows)
    assert set(folders) == {n for n, r in rows.items() if r["status"] == "ok"}
    ok = [n for n, r in rows.items() if r["status"] == "ok"]
    # ...mcap, ..mcap, .hidden.mcap, summary.csv.mcap (link.mcap is ...mcap once more), x.mcap (the glob and
    # ../x.mcap), the absolute path, `..` (the folder holding x.mcap)
    assert sorted(ok) == ["_", "__", "_hidden", "abs", "logs_summary.csv", "work", "x"], rows
    assert "summary.csv" not in folders and (outdir / "summary.csv").is_file()
    for n in ok:
        assert (outdir / n / "trajectory.tum").is_file() and (outdir / n / "batch-done.json").is_file()


def test_a_job_folder_that_is_a_symlink_is_refused(tiny, tmp_path):
    """OUTDIR/<name> a symbolic link to another folder: the job's error row, nothing written there."""
    logs = tmp_path / "logs"
    logs.mkdir()
    shutil.copy(tiny / "log.mcap", logs / "alpha.mcap")
    outdir = tmp_path / "out"
    outdir.mkdir()
    victim = tmp_path / "victim"
    victim.mkdir()
    (victim / "trajectory.tum").write_text("# keep\n")
    (outdir / "alpha").symlink_to(victim)
    rc, out, err = cli("batch", "run", str(logs), "--map", tiny / "map.yaml", "--initial-pose", *START,
                       "-o", outdir, "-q", "--engine", "inline", "--force")
    assert rc == 1
    from fgloc.batch import read_summary_csv

    (row,) = read_summary_csv(outdir / "summary.csv")
    assert row["status"] == "error" and "symbolic link" in row["error"]
    assert snapshot(victim) == {"trajectory.tum": b"# keep\n"}


def test_a_users_files_in_a_job_folder_need_force(tiny, tmp_path):
    logs = tmp_path / "logs"
    logs.mkdir()
    shutil.copy(tiny / "log.mcap", logs / "alpha.mcap")
    outdir = tmp_path / "out"
    (outdir / "alpha").mkdir(parents=True)
    (outdir / "alpha" / "trajectory.tum").write_text("# the user's reference\n")
    args = ["batch", "run", str(logs), "--map", tiny / "map.yaml", "--initial-pose", *START, "-o", outdir, "-q",
            "--engine", "inline"]
    rc, out, err = cli(*args)
    assert rc == 1
    from fgloc.batch import read_summary_csv

    (row,) = read_summary_csv(outdir / "summary.csv")
    assert row["status"] == "error" and "trajectory.tum, not written by fgloc run; pass --force" in row["error"]
    assert (outdir / "alpha" / "trajectory.tum").read_text() == "# the user's reference\n"
    rc, out, err = cli(*args, "--force")
    assert rc == 0, err
    assert (outdir / "alpha" / "trajectory.tum").read_text() != "# the user's reference\n"
    # a summary.csv the user wrote is refused before anything runs
    other = tmp_path / "out2"
    other.mkdir()
    (other / "summary.csv").write_text("my,own,table\n")
    rc, out, err = cli("batch", "run", str(logs), "--map", tiny / "map.yaml", "--initial-pose", *START,
                       "-o", other, "-q", "--engine", "inline")
    assert rc == 2 and "summary.csv, not written by fgloc batch; pass --force" in err
    assert (other / "summary.csv").read_text() == "my,own,table\n" and not (other / "alpha").exists()
