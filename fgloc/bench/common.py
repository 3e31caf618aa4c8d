"""What every benchmark does: localize a simulated run with one back-end and front-end."""

from __future__ import annotations

import importlib
import time
from typing import Any

import numpy as np


def localize_sim(sim: Any, backend: str, frontend: str, config: Any = None,
                 initial_pose: np.ndarray | None = None, use_initial: bool = True,
                 progress: Any = None) -> tuple[Any, Any, Any, float]:
    """Run one back-end/front-end on a simulated run; returns (final, online, localizer, wall_s).

    ``initial_pose`` defaults to the ground truth's first pose (``use_initial=False``: none,
    global localization).  ``config``: a :class:`fgloc.config.FglocConfig` (None: the defaults).
    ``progress``: wraps the message list (e.g. ``lambda m: tqdm(m)``) to show how far it is.
    """
    from fgloc.localization import build_session

    pose0 = initial_pose
    if pose0 is None and use_initial:
        pose0 = sim.ground_truth.poses[0]
    session = build_session(sim.map, sim.laser_mount, backend=backend, frontend=frontend, initial_pose=pose0,
                            config=config)
    t0 = time.perf_counter()
    final = session.run(sim.messages if progress is None else progress(sim.messages))
    wall = time.perf_counter() - t0
    return final, session.loc.online_trajectory(), session.loc, wall


def localize_variants(sim: Any, variants: Any, config: Any = None) -> dict[str, tuple[Any, float]]:
    """Each variant ``(label, backend, frontend, which)`` on a simulated run: ``label -> (trajectory,
    wall_s)``, ``which`` = ``online`` or ``final``; a back-end/front-end pair runs once."""
    runs: dict[tuple[str, str], tuple[Any, Any, Any, float]] = {}
    out: dict[str, tuple[Any, float]] = {}
    for label, backend, frontend, which in variants:
        if (backend, frontend) not in runs:
            runs[(backend, frontend)] = localize_sim(sim, backend, frontend, config)
        final, online, _loc, wall = runs[(backend, frontend)]
        out[label] = (online if which == "online" else final, wall)
    return out


def frontend_available(name: str) -> bool:
    """Whether front-end module ``name`` imports (AMCL's dependencies may be missing)."""
    try:
        importlib.import_module(f"fgloc.frontends.{name}")
    except ImportError:
        return False
    return True
