"""The one typed config: defaults in one place, documented YAML round trip, one-line errors.

The defaults live only in the section dataclasses (found in an installed wheel as in a
checkout); `fgloc config init` writes them as documented YAML that loads back to the
same config; every typo, wrong type or out-of-range value is one ConfigError line that
names the file and the key (issue 12 item 6).
"""

from dataclasses import fields, is_dataclass

import numpy as np
import pytest

from fgloc.cli import main
from fgloc.config import FglocConfig, load_config, parse_config
from fgloc.errors import ConfigError
from fgloc.localization import Localizer, Session
from fgloc.sim import simulate_paper


@pytest.fixture(scope="module")
def short_run():
    return simulate_paper(seed=1, route=[[2.5, 3.0], [14.0, 3.0], [14.0, 6.0]])


def _all_fields(obj, prefix=""):
    for f in fields(obj):
        v = getattr(obj, f.name)
        yield prefix + f.name, f
        if is_dataclass(v):
            yield from _all_fields(v, prefix + f.name + ".")


def test_every_key_is_documented():
    keys = list(_all_fields(FglocConfig()))
    assert len(keys) > 150
    undocumented = [k for k, f in keys if not f.metadata.get("doc")]
    assert undocumented == []


def test_init_file_loads_back_to_the_defaults(tmp_path):
    out = tmp_path / "fgloc.yaml"
    assert main(["config", "init", "-o", str(out)]) == 0
    text = out.read_text()
    assert "frontend_every: 2" in text and "# match every n-th scan" in text
    assert load_config(out) == FglocConfig()
    # refuses to overwrite without --force
    assert main(["config", "init", "-o", str(out)]) == 2
    assert main(["config", "init", "-o", str(out), "--force"]) == 0


def test_show_lists_the_effective_config(tmp_path, capsys):
    user = tmp_path / "user.yaml"
    user.write_text("pipeline:\n  frontend_every: 3\nfrontends:\n  native:\n    max_iterations: 9\n")
    assert main(["config", "show", "--config", str(user)]) == 0
    out = capsys.readouterr().out
    assert "frontend_every: 3" in out and "max_iterations: 9" in out and "lag_s: 2.0" in out
    cfg = load_config(user)
    assert cfg.pipeline.frontend_every == 3 and cfg.frontends.native.max_iterations == 9
    assert cfg.smoother == FglocConfig().smoother  # untouched sections keep their defaults


@pytest.mark.parametrize("text,message", [
    ("smoother:\n  lag_s: fast\n", "smoother.lag_s: expected a number, got fast"),
    ("smoother:\n  lag_s: -1\n", "smoother.lag_s: must be > 0, got -1"),
    ("pipeline:\n  frontend_evry: 3\n", "pipeline.frontend_evry: unknown key (did you mean frontend_every?)"),
    ("pipline:\n  frontend_every: 3\n", "pipline: unknown section (did you mean pipeline?)"),
    ("frontends:\n  native:\n    loss: l3\n", "frontends.native.loss: must be one of huber, cauchy, got l3"),
    ("frontends:\n  kiss:\n    preprocess: {deskw: true}\n", "frontends.kiss.preprocess.deskw: unknown key "
     "(did you mean deskew?)"),
    ("ekf:\n  omni: 1\n", "ekf.omni: expected true or false or null, got 1"),
    ("pipeline:\n  pose_delta_sigmas: [1, 2]\n", "pipeline.pose_delta_sigmas: expected a list of 3 numbers"),
    ("sources:\n  inputs:\n    wheels: {type: odometry, topic: /odom, usee: [vx]}\n",
     "sources.inputs.wheels.usee: unknown key (did you mean use?)"),
    ("sources:\n  inputs:\n    gyro: {type: imu, use: [yaw, vyawn]}\n",
     "sources.inputs.gyro.use: 'vyawn' is not one of"),
    ("sources:\n  static_transforms:\n    - {parent: base_link, child: imu_link, yw: 1}\n",
     "sources.static_transforms[0]: unknown key 'yw' (did you mean xyzw?)"),
    ("- a\n- b\n", "config must be a mapping of sections"),
    ("pipeline: [\n", "does not parse as YAML"),
])
def test_config_errors_are_one_line_naming_file_and_key(tmp_path, capsys, text, message):
    bad = tmp_path / "bad.yaml"
    bad.write_text(text)
    with pytest.raises(ConfigError) as e:
        load_config(bad)
    msg = str(e.value)
    assert msg.startswith(f"{bad}: ") and message in msg and "\n" not in msg
    assert main(["config", "show", "--config", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("fgloc: error: ") and message in err and "\n" not in err


def test_defaults_reach_the_localizer(short_run):
    """A dict, the defaults and a loaded file give the same run; a changed value changes it."""
    out = []
    for cfg in (None, load_config(), {"frontends": {"native": {"cov_inflation": [50.0, 90.0]}}}):
        loc = Localizer(short_run.map, short_run.laser_mount, backend="smoother", frontend="native",
                        initial_pose=short_run.ground_truth.poses[0], config=cfg)
        out.append(Session(loc).run(short_run.messages))
    assert len(out[0]) > 50
    assert np.allclose(out[0].poses, out[1].poses, atol=1e-12)
    assert not np.allclose(out[0].poses, out[2].poses, atol=1e-9)


def test_overrides_are_checked_like_files():
    cfg = parse_config({"frontends": {"amcl": {"max_particles": 3000}}})
    assert cfg.frontends.amcl.max_particles == 3000 and cfg.frontends.amcl.min_particles == 500
    with pytest.raises(ConfigError, match="overrides: pipeline.relocalize_after: must be >= 1"):
        load_config(overrides={"pipeline": {"relocalize_after": 0}})


@pytest.mark.parametrize("text,message", [
    ("faults:\n  wheel_slp: {start: 1.0, duration: 2.0, fraction: 0.3}\n",
     "faults.wheel_slp: unknown key (did you mean wheel_slip?)"),
    ("faults:\n  kidnap: {tme: 5.0, skip_s: 3.0}\n", "faults.kidnap.tme: unknown key (did you mean time?)"),
    ("odom:\n  rate_hzz: 20\n", "odom.rate_hzz: unknown key (did you mean rate_hz?)"),
    ("speed_mp: 1.0\n", "speed_mp: unknown key (did you mean speed_mps?)"),
])
def test_scenario_typos_are_one_line_with_a_suggestion(tmp_path, text, message):
    """Issue 12 item 6 for simulator scenarios: misspelled fault names and keys."""
    from fgloc.sim import run_scenario

    bad = tmp_path / "scenario.yaml"
    bad.write_text(text)
    with pytest.raises(ConfigError) as e:
        run_scenario(bad)
    assert str(e.value) == f"{bad}: {message}"
