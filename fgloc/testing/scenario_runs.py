"""A shipped simulated scenario localized in process, as ``fgloc run`` would (tests, diagnostics).

``localize_until`` runs a :class:`~fgloc.localization.Localizer` in a :class:`~fgloc.localization.Session`
from the true start pose over a scenario's messages up to a time, so a test can look at one stretch of a
long run (a wrong run of fixes and what follows it) without simulating a shorter world.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

from fgloc.types import Trajectory


def shipped_scenario_path(name: str) -> Path:
    """The YAML file of a scenario shipped in the package (``changed_world`` -> .../changed_world.yaml)."""
    return Path(str(resources.files("fgloc.config") / "scenarios")) / f"{name}.yaml"


@dataclass
class ScenarioRun:
    sim: Any  # fgloc.sim.SimResult
    localizer: Any  # fgloc.localization.Localizer
    estimate: Trajectory  # the session's final trajectory


def localize_until(name: str, seed: int, backend: str, frontend: str, until_s: float | None = None,
                   config: Any = None) -> ScenarioRun:
    """Shipped scenario ``name`` at ``seed`` localized by ``backend`` + ``frontend`` from its true start pose,
    over its messages stamped up to ``until_s`` (None: all); the ground truth is not fed.  ``config``: a
    :class:`fgloc.config.FglocConfig` (None: the defaults)."""
    from fgloc.config import load_config
    from fgloc.localization import Localizer, Session
    from fgloc.sim import load_scenario, run_scenario

    sim = run_scenario(load_scenario(shipped_scenario_path(name)), seed=seed)
    msgs = [(k, m) for k, m in sim.messages if k != "/ground_truth" and _stamped_by(m, until_s)]
    loc = Localizer(sim.map, sim.laser_mount, backend, frontend, initial_pose=sim.ground_truth.poses[0],
                    config=config if config is not None else load_config(None))
    return ScenarioRun(sim, loc, Session(loc).run(msgs))


def _stamped_by(msg: Any, until_s: float | None) -> bool:
    """Whether a message is one to feed: stamped up to ``until_s`` (a list, the static tf, always is)."""
    return until_s is None or isinstance(msg, list) or float(msg.stamp) <= until_s
