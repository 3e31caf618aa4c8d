"""A config's settings for a front-end that does not run are said, not silently dropped: a nav2
params file ported with ``fgloc config from-nav2`` holds AMCL's settings, and ``fgloc run --config``
(and ``fgloc live``) localize with the native front-end unless ``--frontend amcl`` is given."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

from fgloc.app.run import RunRequest, run_log, unused_frontend_settings
from fgloc.config import FglocConfig, load_config

NAV2_PARAMS = """\
amcl:
  ros__parameters:
    use_sim_time: true
    alpha1: 0.2
    alpha2: 0.2
    base_frame_id: base_footprint
    max_particles: 2000
    min_particles: 500
    robot_model_type: nav2_amcl::DifferentialMotionModel
    update_min_d: 0.25
    scan_topic: scan
"""


def _ported(tmp_path: Path) -> Path:
    from fgloc.cli import app

    params = tmp_path / "nav2_params.yaml"
    params.write_text(NAV2_PARAMS)
    out = tmp_path / "fgloc.yaml"
    r = CliRunner().invoke(app, ["config", "from-nav2", str(params), "-o", str(out)])
    assert r.exit_code == 0, r.output
    # the converter says how its AMCL settings are used, on the terminal and atop the file
    usage = "frontends.amcl is used with --frontend amcl (fgloc run, fgloc live)"
    assert usage in r.output
    assert usage in out.read_text().splitlines()[1]
    return out


def test_a_ported_nav2_configs_amcl_settings_are_named_when_the_native_front_end_runs(tmp_path: Path) -> None:
    cfg = load_config(_ported(tmp_path))
    (line,) = unused_frontend_settings(cfg, "native")
    assert line.startswith("frontends.amcl sets ")
    assert line.endswith(": unused, the front-end is native (pass --frontend amcl to localize with it)")
    assert "alpha1" in line and "more" in line  # nav2's defaults are not fgloc's: many keys differ
    assert unused_frontend_settings(cfg, "amcl") == []
    # kiss runs: the AMCL settings are named the same way ("kiss-icp" is kiss)
    (line,) = unused_frontend_settings(cfg, "kiss-icp")
    assert "frontends.amcl" in line and "the front-end is kiss" in line


def test_default_front_end_settings_are_not_warned_about() -> None:
    for name in ("native", "kiss", "amcl"):
        assert unused_frontend_settings(FglocConfig(), name) == []
    # one key off its default is enough, and it is named
    cfg = FglocConfig()
    kiss = dataclasses.replace(cfg.frontends.kiss, voxel_size_m=cfg.frontends.kiss.voxel_size_m * 2)
    cfg = dataclasses.replace(cfg, frontends=dataclasses.replace(cfg.frontends, kiss=kiss))
    assert unused_frontend_settings(cfg, "native") == [
        "frontends.kiss sets voxel_size_m: unused, the front-end is native (pass --frontend kiss to localize with it)"]
    assert unused_frontend_settings(cfg, "kiss") == []


@pytest.fixture(scope="module")
def short_log(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, tuple[float, float, float]]:
    from fgloc.io.mcap_writer import LogWriter
    from fgloc.sim import run_scenario

    sim = run_scenario({"route": [[2.5, 3.0], [4.5, 3.0]], "laser": {"rate_hz": 5.0}}, seed=0)
    d = tmp_path_factory.mktemp("short")
    sim.map.save(d / "map.yaml")
    with LogWriter(d / "log.mcap") as w:
        for topic, msg in sim.messages:
            w.write(topic, msg)
    x, y, yaw = (float(v) for v in sim.ground_truth.poses[0])
    return d, (x, y, yaw)


def test_fgloc_run_with_a_ported_nav2_config_warns_that_amcl_did_not_run(short_log, tmp_path: Path) -> None:
    d, pose0 = short_log
    cfg = _ported(tmp_path)
    r = run_log(RunRequest(log=d / "log.mcap", outdir=tmp_path / "out", map_yaml=d / "map.yaml", config=cfg,
                           initial_pose=pose0, view_channels=False))
    assert r.frontend == "native" and r.fixes > 0
    assert [w for w in r.warnings if w.startswith("frontends.")] == unused_frontend_settings(load_config(cfg), "native")
    assert len(r.warnings) == 1, r.warnings
    # without a map no front-end runs: nothing to say
    r = run_log(RunRequest(log=d / "log.mcap", outdir=tmp_path / "odom", config=cfg, view_channels=False))
    assert r.warnings == []
    # the effective config written beside the outputs still holds the ported settings
    written = yaml.safe_load((tmp_path / "out" / "config.yaml").read_text())
    assert written["frontends"]["amcl"]["max_particles"] == 2000 and written["run"]["frontend"] == "native"


def test_a_batch_job_keeps_the_runs_warnings(short_log, tmp_path: Path) -> None:
    """`fgloc batch run` calls the same run: its summary row says what `fgloc run` warns about."""
    from fgloc.batch import adapter
    from fgloc.batch.jobs import Job, execute

    d, pose0 = short_log
    cfg = _ported(tmp_path)
    out = adapter.localize_log(d / "log.mcap", tmp_path / "a", d / "map.yaml", list(pose0), cfg, "smoother", "native",
                               None, None, None)
    want = unused_frontend_settings(load_config(cfg), "native")
    assert out.warnings == want and len(want) == 1
    job = Job(name="log", kind="run", inputs={"log": str(d / "log.mcap"), "map": str(d / "map.yaml"),
                                              "config": str(cfg)},
              outdir=str(tmp_path / "b"), params={"initial_pose": list(pose0)})
    res = execute(job)
    assert res.ok, res.error
    assert want[0] in res.row["note"]
