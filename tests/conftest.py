"""Shared fixtures: the real data folder and one simulated paper run per session."""

from __future__ import annotations

import os
from collections import OrderedDict
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

#: pytest-xdist (pyproject's ``-n 2 --dist loadgroup``) sends a whole file to one worker, so its
#: module fixtures are made once. The tests that keep real time (live replays through the emulators,
#: DDS peers, the viewer's websocket) and those that start Ray instances form one unit, run one after
#: another on one worker: never two of them at once, while the other worker runs the rest
SERIAL_GROUPS = {"live": "realtime", "ros2": "realtime", "view": "realtime", "batch": "realtime"}


def xdist_unit(nodeid: str) -> str:
    """The unit of work a test is sent to a worker with: its group of :data:`SERIAL_GROUPS`, else its file."""
    path = nodeid.split("::", 1)[0]
    parts = path.split("/")
    return SERIAL_GROUPS.get(parts[1], path) if len(parts) > 2 and parts[0] == "tests" else path


try:
    from xdist.scheduler import LoadScopeScheduling
except ImportError:  # pytest-xdist is in the test extra; without it the suite runs in one process
    LoadScopeScheduling = None

#: the longest units (measured), handed out first so that no long one starts last
LONG_UNITS = ("realtime", "tests/acceptance/test_rl_matrix.py", "tests/outputs/test_signals.py",
              "tests/test_conformance.py", "tests/sim/test_fusion_acceptance.py", "tests/localization/test_pipeline.py",
              "tests/config/test_robot_configs.py")


class _LongestFirst(OrderedDict):
    """xdist's queue of units: the :data:`LONG_UNITS` leave it first, the rest in order."""

    def popitem(self, last: bool = True):
        first = next((u for u in LONG_UNITS if u in self), None)
        if last or first is None:
            return super().popitem(last)
        return first, self.pop(first)


if LoadScopeScheduling is not None:
    class _UnitScheduling(LoadScopeScheduling):
        def __init__(self, config, log=None) -> None:
            super().__init__(config, log)
            self.workqueue = _LongestFirst()

        def _split_scope(self, nodeid: str) -> str:
            return xdist_unit(nodeid)

    @pytest.hookimpl(tryfirst=True, optionalhook=True)
    def pytest_xdist_make_scheduler(config, log):
        return _UnitScheduling(config, log) if config.getvalue("dist") == "loadgroup" else None


#: the skip reason of the tests that read the real logs (README, "Data and attribution": where to get them)
SHARED_DATA_MISSING = (
    "real logs not found at {d} (set FGLOC_SHARED_DATA): radish/*.clf.bz2 and radish-reference/ (the Freiburg "
    "SLAM evaluation page), robot_localization/ and robot_localization-groovy/ (test bags and .test files of "
    "cra-ros-pkg/robot_localization, noetic-devel and groovy-devel), maps/willow-2010-02-18-0.10 (turtlebot_apps); "
    "see README, Data and attribution")


def _shared_data_dir() -> Path:
    env = os.environ.get("FGLOC_SHARED_DATA")
    return Path(env) if env else REPO.parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """``../shared/data`` beside the checkout (or ``$FGLOC_SHARED_DATA``)."""
    d = _shared_data_dir()
    if not d.is_dir():
        pytest.skip(SHARED_DATA_MISSING.format(d=d))
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
