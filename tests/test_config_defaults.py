"""The YAML files in config/ document the defaults; an installed wheel has no config/ folder.

Both must behave the same: the shipped YAML and the code's built-in defaults give
identical results (so `pip install .` and a checkout localize alike).
"""

from pathlib import Path

import numpy as np
import pytest
import yaml

from fgloc.pipeline import Localizer, load_config, run_messages
from fgloc.sim import simulate_paper

CONFIG = Path(__file__).resolve().parents[1] / "config"


@pytest.fixture(scope="module")
def short_run():
    return simulate_paper(seed=1, route=[[2.5, 3.0], [14.0, 3.0], [14.0, 6.0]])


@pytest.mark.parametrize("backend,frontend", [("ekf", "native"), ("smoother", "native"), ("ekf", "amcl")])
def test_shipped_yaml_equals_builtin_defaults(short_run, backend, frontend):
    shipped = load_config()
    assert shipped, "config/fgloc.yaml should be read in a checkout"
    shipped["frontends"] = yaml.safe_load((CONFIG / "frontends.yaml").read_text())
    trajs = []
    for cfg in (shipped, {}):
        loc = Localizer(short_run.map, short_run.laser_mount, backend=backend, frontend=frontend,
                        initial_pose=short_run.ground_truth.poses[0], config=cfg)
        trajs.append(run_messages(loc, short_run.messages))
    a, b = trajs
    assert len(a) == len(b) > 50
    assert np.allclose(a.poses, b.poses, atol=1e-9)


def test_config_values_do_reach_the_localizer(short_run):
    """The comparison above has teeth: a changed value in the config changes the result."""
    cfg = load_config()
    cfg["frontends"] = yaml.safe_load((CONFIG / "frontends.yaml").read_text())
    changed = dict(cfg)
    changed["frontends"] = {**cfg["frontends"], "native": {**cfg["frontends"]["native"], "cov_inflation": [50.0, 90.0]}}
    out = []
    for c in (cfg, changed):
        loc = Localizer(short_run.map, short_run.laser_mount, backend="smoother", frontend="native",
                        initial_pose=short_run.ground_truth.poses[0], config=c)
        out.append(run_messages(loc, short_run.messages))
    assert not np.allclose(out[0].poses, out[1].poses, atol=1e-9)
