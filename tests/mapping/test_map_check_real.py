"""``fgloc map-check`` in localization mode on real logs against their own maps: a good run passes.
The Radish excerpts (bundled) are mapped by ``fgloc map`` and checked with the mapping run's own
trajectory; what the check still finds there (people, a door, a beam glancing off a wall along the
path) is listed as minor, under ``change_significant_share`` of the returns that saw it, and the
exit status is 0.  The injected changes of the simulator are still found (test_changed_world_sim)."""

from __future__ import annotations

import contextlib
import io

import pytest
import yaml


def _cli(*args) -> tuple[int, str]:
    from fgloc.cli import main

    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        rc = main([str(a) for a in args])
    return rc, out.getvalue()


@pytest.mark.parametrize("name", ["fr079-head", "intel-head"])
def test_a_log_checked_against_its_own_map_passes(repo_data, tmp_path, name):
    log = repo_data / "radish" / f"{name}.clf.bz2"
    rc, out = _cli("map", log, "-o", tmp_path / "map", "--no-check", "-q")
    assert rc == 0, out
    rc, out = _cli("map-check", tmp_path / "map" / "map.yaml", log, "--trajectory", tmp_path / "map" / "trajectory.tum",
                   "-o", tmp_path / "check", "-q")
    assert rc == 0 and out.startswith("map-check: MATCHES"), out
    doc = yaml.safe_load((tmp_path / "check" / "check.yaml").read_text())
    assert doc["passed"] is True
    assert all(c["minor"] and c["share_of_returns"] < 0.04 for c in doc["changes"])


def test_map_exits_1_when_its_self_check_flags(repo_data, tmp_path, monkeypatch):
    """fgloc map writes the map and exits 1 when its own self-check flags it, as fgloc map-check does
    (here the real check's result is turned into a flagged one: the exit code is what is tested)."""
    import dataclasses

    from fgloc.mapping import build

    real = build.check_consistency

    def flagged(*a, **k):
        res = real(*a, **k)
        return dataclasses.replace(res, passed=False, verdict="map-check: INCONSISTENT - (forced)")

    monkeypatch.setattr(build, "check_consistency", flagged)
    rc, out = _cli("map", repo_data / "radish" / "fr079-head.clf.bz2", "-o", tmp_path / "m", "-q")
    assert rc == 1 and "INCONSISTENT" in out and (tmp_path / "m" / "map.yaml").exists()
