"""Every writing command refuses, before any work, to replace a file fgloc did not write (exit 2,
one line naming it; the file unchanged), never writes over one of its inputs, and treats a link
at an output name as someone else's file."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from fgloc.testing.cli import run_cli as cli

from .conftest import START, error_line


def _cases(tiny: Path, d: Path) -> dict[str, tuple[list, Path, str]]:
    """name -> (arguments, the user's file, the message's expected part)."""
    sim = d / "sim"
    return {
        # issue 31: `fgloc map sim/log.mcap -o sim` replaced the map fgloc simulate wrote there
        "map onto simulate's folder": (["map", sim / "log.mcap", "-o", sim, "-q"], sim / "map.yaml",
                                       f"{sim}: holds map.yaml, map.pgm, not written by fgloc map; pass --force"),
        "simulate": (["simulate", "scenario", "paper", "-o", d / "s"], d / "s" / "map.yaml",
                     "holds map.yaml, not written by fgloc simulate"),
        "eval --plots": (["eval", tiny / "ground_truth.tum", tiny / "ground_truth.tum", "--plots", d / "p"],
                         d / "p" / "path.png", "holds path.png, not written by fgloc eval; pass --force"),
        "map-check": (["map-check", tiny / "map.yaml", tiny / "log.mcap", "--trajectory", tiny / "ground_truth.tum",
                       "-o", d / "c", "-q"], d / "c" / "check.yaml",
                      "holds check.yaml, not written by fgloc map-check"),
        "import": (["import", tiny / "log.mcap", "-o", d / "i.mcap"], d / "i.mcap",
                   "exists and was not written by fgloc import; pass --force"),
        "export": (["export", tiny / "ground_truth.tum", "-o", d / "e.tum"], d / "e.tum", "exists; pass --force"),
        "config init": (["config", "init", "-o", d / "c.yaml"], d / "c.yaml", "exists; pass --force"),
        "view layout": (["view", "layout", "-o", d / "l.json"], d / "l.json", "exists; pass --force"),
        "demo": (["demo", "-o", d / "demo"], d / "demo" / "ekf.tum", "holds ekf.tum, not written by fgloc demo"),
        "bench paper": (["bench", "paper", "--seeds", "1", "-o", d / "b"], d / "b" / "table.md",
                        "holds table.md, not written by fgloc bench paper"),
        "batch bench paper": (["batch", "bench", "paper", "--seeds", "1", "-o", d / "bb", "--engine", "inline"],
                              d / "bb" / "table.md", "holds table.md, not written by fgloc bench paper"),
        "run": (["run", tiny / "log.mcap", "--map", tiny / "map.yaml", "--initial-pose", *START, "-o", d / "r"],
                d / "r" / "online.tum", "holds online.tum, not written by fgloc run; pass --force"),
    }


def test_no_command_replaces_a_file_it_did_not_write(tiny, tmp_path):
    shutil.copytree(tiny, tmp_path / "sim")  # a folder as fgloc simulate wrote it before (no record)
    for name, (args, users, want) in _cases(tiny, tmp_path).items():
        if not users.exists():
            users.parent.mkdir(parents=True, exist_ok=True)
            users.write_text(f"the user's {users.name}\n")
        before = users.read_bytes()
        rc, out, err = cli(*args)
        assert rc == 2 and want in error_line(err), (name, out, err)
        assert users.read_bytes() == before, name


def test_inputs_and_links(tiny, tmp_path):
    # a scenario file inside the output folder under an output name: an input, never replaced
    d = tmp_path / "s"
    d.mkdir()
    (d / "scenario.yaml").write_text("route: [[2.5, 3.0], [3.0, 3.0]]\n")
    rc, _, err = cli("simulate", "scenario", d / "scenario.yaml", "-o", d, "--force")
    assert rc == 2 and f"{d}/scenario.yaml: is an input of this command" in error_line(err)
    # a link at an output name: someone else's file (the link is replaced with --force, its target never written)
    target = tmp_path / "precious.yaml"
    target.write_text("keep\n")
    r = tmp_path / "r"
    r.mkdir()
    (r / "config.yaml").symlink_to(target)
    args = ["run", tiny / "log.mcap", "--map", tiny / "map.yaml", "--initial-pose", *START, "-o", r, "-q"]
    rc, _, err = cli(*args)
    assert rc == 2 and "config.yaml (a symbolic link), not written by fgloc run" in error_line(err)
    rc, _, err = cli(*args, "--force")
    assert rc == 0, err
    assert target.read_text() == "keep\n" and not (r / "config.yaml").is_symlink()
    # the map's own folder for map-check: the map is an input (its image too)
    rc, _, err = cli("map-check", tiny / "map.yaml", tiny / "log.mcap", "-o", tmp_path / "m", "-q",
                     "--trajectory", tiny / "ground_truth.tum")
    assert rc in (0, 1), err


@pytest.mark.parametrize("prior", ["map", "map-check"])
def test_map_and_map_check_share_the_check_files(tiny, tmp_path, prior):
    """`fgloc map` replaces the check.yaml a map-check wrote (and the other way round); a map made
    without its self-check removes the old check.yaml, so it never describes another map."""
    m = tmp_path / "m"
    rc, _, err = cli("map", tiny / "log.mcap", "-o", m, "-q")
    assert rc == 0, err
    if prior == "map-check":
        rc, _, err = cli("map-check", m / "map.yaml", tiny / "log.mcap", "-q", "--mode", "consistency")
        assert rc in (0, 1), err
    rc, _, err = cli("map", tiny / "log.mcap", "-o", m, "-q", "--no-check")
    assert rc == 0, err
    assert not (m / "check.yaml").exists() and not (m / "check.png").exists()
