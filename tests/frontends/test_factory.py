"""make_frontend, config files and the shared preprocessing."""

from __future__ import annotations

import numpy as np
import pytest

from fgloc.config import load_config
from fgloc.config.schema import to_dict
from fgloc.errors import ConfigError
from fgloc.frontends import FrontendsConfig, PreprocessOptions, ScanMatcher, ScanPreprocessor, make_frontend
from fgloc.frontends.base import deskew_offsets, voxel_downsample
from fgloc.types import LaserScan, StaticTransform

from .synth import MOUNT, make_map


@pytest.fixture(scope="module")
def world():
    return make_map(0.1)


def test_factory_names_and_sections(world):
    cfg = to_dict(FrontendsConfig())
    assert {"native", "kiss", "amcl"} <= set(cfg)
    for name in ("native", "kiss", "kiss-icp", "KISS_ICP"):
        fe = make_frontend(name, world, MOUNT, cfg)
        assert isinstance(fe, ScanMatcher)
        assert fe.name in ("native", "kiss")
    fe = make_frontend("native", world, MOUNT, {"native": {"max_iterations": 7}, "kiss": {}})
    assert fe.max_iterations == 7  # type: ignore[attr-defined]
    fe = make_frontend("native", world, MOUNT, {"max_iterations": 9})
    assert fe.max_iterations == 9  # type: ignore[attr-defined]


def test_factory_errors(world):
    with pytest.raises(ConfigError, match="unknown front-end"):
        make_frontend("icp", world, MOUNT, None)
    with pytest.raises(ConfigError, match="unknown key"):
        make_frontend("native", world, MOUNT, {"max_iteration": 3})
    with pytest.raises(ConfigError, match="unknown key"):
        make_frontend("kiss", world, MOUNT, {"preprocess": {"deskw": True}})
    with pytest.raises(ConfigError, match="loss"):
        make_frontend("native", world, MOUNT, {"loss": "l3"})
    with pytest.raises(ConfigError):
        load_config("/nonexistent/frontends.yaml")


def test_yaml_defaults_match_constructor_defaults(world):
    """The documented defaults (the frontends: section as `fgloc config show` writes it) build the
    same front-ends as {}."""
    cfg = to_dict(load_config().frontends)
    for name in ("native", "kiss"):
        a = make_frontend(name, world, MOUNT, cfg)
        b = make_frontend(name, world, MOUNT, {})
        for key, val in vars(b).items():
            if isinstance(val, (int, float, str, bool)):
                assert getattr(a, key) == val, (name, key)


def test_preprocess_filters_and_transforms():
    r = np.array([np.nan, np.inf, -np.inf, 0.0, 0.01, 1.0, 2.0, 30.0] + [1.5] * 10, dtype=np.float32)
    scan = LaserScan(0.0, 0.0, 0.1, 0.05, 20.0, r)
    pre = ScanPreprocessor(StaticTransform("base_link", "laser", np.array([0.5, 0.0, np.pi])))
    pts, why = pre(scan)
    assert why == "" and pts is not None and len(pts) == 12
    # beam 5 (1.0 m at 0.5 rad) seen by a laser mounted backwards at x = 0.5
    assert pts[0] == pytest.approx([0.5 - np.cos(0.5), -np.sin(0.5)])
    pts, _ = ScanPreprocessor(None, PreprocessOptions(max_beams=6))(scan)
    assert pts is not None and len(pts) == 6
    pts, why = ScanPreprocessor(None, PreprocessOptions(min_valid_beams=13))(scan)
    assert pts is None and "12 valid beams" in why


def test_deskew_offsets_and_voxels():
    offs = deskew_offsets(3, 0.01, np.array([0.04, 0.0, 0.0]), 0.04)
    assert offs[:, 0] == pytest.approx([0.0, 0.01, 0.02])
    offs = deskew_offsets(2, 0.5, np.array([0.0, 0.0, np.pi / 2]), 1.0)
    assert offs[1, 2] == pytest.approx(np.pi / 4)
    pts = np.array([[0.01, 0.01], [0.02, 0.02], [0.5, 0.5]])
    assert len(voxel_downsample(pts, 0.1)) == 2
