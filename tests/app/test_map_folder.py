"""The folder ``fgloc map -o FOLDER`` writes is a map wherever a map_server YAML goes, and an
output folder option given a file name (``-o map.yaml``, ``-o run.tum``) is one line, nothing
created: a user who maps a log and then localizes on it types what map_server taught them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fgloc.testing.cli import last_error_line as error_line
from fgloc.testing.cli import run_cli as fgloc


@pytest.fixture(scope="module")
def short_log(tmp_path_factory) -> dict:
    """A 10 s simulated run and the folder holding its map.yaml (as ``fgloc map`` leaves one)."""
    from fgloc.sim import simulate_paper, write_sim

    d = tmp_path_factory.mktemp("short")
    write_sim(simulate_paper(seed=0, route=[[2.5, 3.0], [6.5, 3.0]]), d)
    return {"dir": d, "log": d / "log.mcap", "map": d / "map.yaml"}


def test_load_map_takes_the_folder_holding_map_yaml(short_log, tmp_path):
    from fgloc.errors import MapError
    from fgloc.maps import load_map, map_file

    assert map_file(short_log["dir"]) == short_log["map"]
    assert map_file(short_log["map"]) == short_log["map"]
    assert load_map(short_log["dir"]).equals(load_map(short_log["map"]))
    (tmp_path / "empty").mkdir()
    with pytest.raises(MapError, match="is a directory, not a map file"):
        load_map(tmp_path / "empty")


def test_run_on_the_map_folder_is_the_run_on_its_map_yaml(short_log, tmp_path):
    runs = {}
    for name, given in (("file", short_log["map"]), ("folder", short_log["dir"])):
        rc, out, err = fgloc("run", short_log["log"], "--map", given, "--initial-pose", "2.5", "3.0", "0.0",
                             "-o", tmp_path / name, "-q", "--backend", "ekf")
        assert rc == 0, out + err
        runs[name] = np.loadtxt(tmp_path / name / "trajectory.tum")
    assert runs["folder"].shape[0] > 50
    assert np.array_equal(runs["folder"], runs["file"])
    import yaml

    recorded = yaml.safe_load((tmp_path / "folder" / "config.yaml").read_text())["run"]["map"]
    assert Path(recorded) == short_log["map"]  # the file read, not the folder named


@pytest.mark.parametrize("command", ["map", "run"])
def test_an_output_folder_given_a_file_name_is_refused(short_log, tmp_path, command):
    name = {"map": "office.yaml", "run": "office.tum"}[command]
    rc, out, err = fgloc(command, short_log["log"], "-o", tmp_path / name, "-q")
    assert rc == 2, out + err
    line = error_line(err)
    assert line.startswith(f"{tmp_path / name}: -o takes a folder (fgloc {command} writes ")
    assert line.endswith(f"give a folder, e.g. -o {tmp_path / 'office'}")
    assert not (tmp_path / name).exists()


def test_an_existing_folder_of_any_name_is_an_output_folder(short_log, tmp_path):
    (tmp_path / "maps.yaml").mkdir()  # the user's own folder, named so on purpose
    rc, out, err = fgloc("map", short_log["log"], "-o", tmp_path / "maps.yaml", "-q", "--no-check")
    assert rc == 0, out + err
    assert (tmp_path / "maps.yaml" / "map.yaml").is_file()


def test_map_check_on_the_map_folder(short_log, tmp_path):
    folder = tmp_path / "m"
    rc, out, err = fgloc("map", short_log["log"], "-o", folder, "-q", "--no-check")
    assert rc == 0, out + err
    rc, out, err = fgloc("map-check", folder, short_log["log"], "-q")
    assert rc in (0, 1), out + err
    assert "Traceback" not in err
    assert f"wrote {folder}/check.yaml" in out
    assert (folder / "check.yaml").is_file()
