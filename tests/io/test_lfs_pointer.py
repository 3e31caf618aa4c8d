"""A Git LFS pointer in place of a log (a public repository cloned without git-lfs: three text
lines naming the log's hash and size) is one line saying so, for every command and every name
it may have, where it was a misleading "not a CARMEN log?", "file is not a database" or "bad
magic bytes".  The pointer is written here."""

from __future__ import annotations

import pytest

from fgloc.cli import main

POINTER = ("version https://git-lfs.github.com/spec/v1\n"
           "oid sha256:aa20eaef40a3e958c7b60b3b036290a3cbcbf55eab54aff74c9f32894d1011ab\n"
           "size 347807744\n")
SAID = "a Git LFS pointer, not the log (347807744 bytes not downloaded): fetch it with `git lfs pull`"


@pytest.mark.parametrize("name", ["run.bag", "run.mcap", "intel.clf", "folder"])
@pytest.mark.parametrize("command", ["info", "run", "map", "import"])
def test_an_lfs_pointer_is_one_line(tmp_path, capsys, name, command):
    if name == "folder":  # a rosbag2 folder whose database is the pointer
        log = tmp_path / "bag"
        log.mkdir()
        (log / "bag_0.db3").write_text(POINTER)
        (log / "metadata.yaml").write_text(
            "rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: sqlite3\n"
            "  relative_file_paths:\n    - bag_0.db3\n")
        pointer = log / "bag_0.db3"
    else:
        log = pointer = tmp_path / name
        log.write_text(POINTER)
    out = tmp_path / ("out.mcap" if command == "import" else "out")
    extra = {"info": [], "run": ["-o", str(out), "-q"], "map": ["-o", str(out), "--no-progress"],
             "import": ["-o", str(out)]}[command]
    capsys.readouterr()
    assert main([command, str(log), *extra]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"fgloc: error: {pointer}: {SAID} in its repository"], err
    assert not out.exists()
