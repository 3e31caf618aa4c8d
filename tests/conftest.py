"""Shared fixtures: the real data folder and one simulated paper run per session."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def _shared_data_dir() -> Path:
    env = os.environ.get("FGLOC_SHARED_DATA")
    return Path(env) if env else REPO.parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """``../shared/data`` beside the checkout (or ``$FGLOC_SHARED_DATA``)."""
    d = _shared_data_dir()
    if not d.is_dir():
        pytest.skip(f"shared data folder not found at {d}")
    return d


@pytest.fixture(scope="session")
def repo_data() -> Path:
    """The project's own bundled ``data/`` folder."""
    return REPO / "data"


@pytest.fixture(scope="session")
def paper_sim():
    """The paper experiment simulated once per test session (seed 0)."""
    from fgloc.sim import simulate_paper

    return simulate_paper(seed=0)


@pytest.fixture(scope="session")
def paper_dir(paper_sim, tmp_path_factory) -> Path:
    """A folder with the paper run written out: log.mcap, map.yaml/.pgm, ground_truth.tum."""
    from fgloc.sim import write_sim

    d = tmp_path_factory.mktemp("paper")
    write_sim(paper_sim, d)
    return d
