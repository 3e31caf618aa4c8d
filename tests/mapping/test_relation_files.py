"""``fgloc map`` scored against the published, manually verified relation sets of Kuemmerle et al.
2009 ("On measuring the accuracy of SLAM algorithms": ``aces.relations``, ``intel.relations``,
``fr079.relations``, ``mit-csail.relations``; lines ``t1 t2 x y z roll pitch yaw`` on the logs'
ipc clock).

``aces.relations`` ships in ``data/radish/`` (CC-BY, see its README); the others are not in this
repository: the test also looks in ``$FGLOC_RELATIONS`` (folders separated by ``os.pathsep``) and
skips when a log's file is absent.  The logs themselves come from the shared data folder.  What it
guards is the class of error issue 13 reported on ACES: a region whose early and late passes are metres apart
(relations off by ~3 m while the median is 3 cm).
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from fgloc.eval.relations import read_relations, relation_errors
from fgloc.mapping.build import load_records
from fgloc.mapping.slam import run_slam

LOGS = {"aces": "aces.clf.bz2", "intel": "intel.clf.bz2", "fr079": "fr079.clf.bz2", "mit-csail": "mit-csail.clf.bz2"}


REPO_DATA = Path(__file__).resolve().parents[2] / "data" / "radish"


def _relation_file(name: str) -> Path | None:
    env = os.environ.get("FGLOC_RELATIONS")
    for d in [REPO_DATA, *([Path(e) for e in env.split(os.pathsep) if e] if env else [])]:
        for f in (f"{name}.relations", f"{name}.clf.relations", f"{name}.relations.txt"):
            if (d / f).is_file():
                return d / f
    return None


@pytest.mark.parametrize("name", list(LOGS))
def test_relation_file_has_no_metre_errors(shared_data, name):
    rel = _relation_file(name)
    if rel is None:
        pytest.skip(f"no {name}.relations in data/radish or $FGLOC_RELATIONS (only aces.relations is shipped)")
    log = shared_data / "radish" / LOGS[name]
    if not log.is_file():
        pytest.skip(f"{log} not found (the Radish logs come from the Freiburg SLAM evaluation page; README, "
                    "Data and attribution)")
    recs, mount = load_records(log)
    traj = run_slam(recs, mount).scan_trajectory
    et, er, unmatched = relation_errors(traj, read_relations(rel))
    assert len(et) >= 0.9 * (len(et) + unmatched)  # one pose per scan: the relations' stamps are found
    # ACES: fgloc map 0.0355 m (session 10); Cartographer 0.0375 m, a graph-SLAM baseline 0.044 m
    assert float(et.mean()) < 0.05
    worst = sorted(et)[-5:]
    assert worst[-1] < 1.0, f"relations off by metres: {[round(float(v), 2) for v in worst]} m"
