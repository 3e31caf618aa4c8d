"""Fixtures of the localization tests."""

from __future__ import annotations

from collections.abc import Callable
from importlib import resources
from pathlib import Path
from typing import Any

import pytest


@pytest.fixture
def changed_world_until() -> Callable[..., tuple[Any, Any, Any]]:
    """``run(seed, backend, frontend, until_s)``: the changed_world scenario at ``seed`` localized from its true
    start up to ``until_s`` with the default config; ``(localizer, estimate, simulation)``."""

    def run(seed: int, backend: str, frontend: str, until_s: float) -> tuple[Any, Any, Any]:
        from fgloc.config import load_config
        from fgloc.localization import Localizer, Session
        from fgloc.sim import load_scenario, run_scenario

        scen = Path(str(resources.files("fgloc.config") / "scenarios")) / "changed_world.yaml"
        sim = run_scenario(load_scenario(scen), seed=seed)
        msgs = [(k, m) for k, m in sim.messages
                if k != "/ground_truth" and (isinstance(m, list) or m.stamp <= until_s)]
        loc = Localizer(sim.map, sim.laser_mount, backend, frontend, initial_pose=sim.ground_truth.poses[0],
                        config=load_config(None))
        return loc, Session(loc).run(msgs), sim

    return run
