"""Config files as users write them: YAML 1.2 floats (``1e-3`` was rejected as "not a number",
PyYAML reading YAML 1.1), non-finite numbers where a finite one is required (``.inf`` was
accepted), and documents nested deeper than Python can follow (a RecursionError traceback).
Each is a number or a one-line error, for every file fgloc reads through
:func:`fgloc.config.schema.load_yaml` (configs, mapping configs, scenarios, maps)."""

from __future__ import annotations

import math
from dataclasses import fields, is_dataclass
from typing import get_type_hints

import numpy as np
import pytest
import yaml

from fgloc.cli import main
from fgloc.config import FglocConfig, load_config, schema
from fgloc.errors import ConfigError
from fgloc.maps import load_map


@pytest.mark.parametrize(("text", "value"), [("1e-3", 0.001), ("2E+1", 20.0), (".5", 0.5), ("1.", 1.0),
                                             ("3", 3.0), ("1.5e+2", 150.0)])
def test_yaml_1_2_floats_are_numbers(tmp_path, text, value):
    f = tmp_path / "c.yaml"
    f.write_text(f"pipeline:\n  lost_after_s: {text}\n")
    assert load_config(f).pipeline.lost_after_s == value


def _float_settings(cls, where=""):
    """``(path, field)`` of every float (or tuple of floats) setting of the config, recursively."""
    hints = get_type_hints(cls)
    for f in fields(cls):
        tp = hints[f.name]
        if is_dataclass(tp):
            yield from _float_settings(tp, f"{where}{f.name}.")
        elif "float" in str(tp) and f.metadata.get("finite", True) and "doc" in f.metadata:
            yield f"{where}{f.name}", f


FLOATS = list(_float_settings(FglocConfig))


def test_every_float_setting_refuses_infinity(tmp_path):
    """As a class: every float setting of every section (those that take a tuple with .inf in it)."""
    assert len(FLOATS) > 100
    refused = 0
    for path, _ in FLOATS:
        *sections, key = path.split(".")
        default = getattr(FglocConfig(), sections[0]) if sections else None
        for s in sections[1:]:
            default = getattr(default, s)
        cur = getattr(default, key) if default is not None else None
        value = [math.inf] * len(cur) if isinstance(cur, tuple) else math.inf
        doc: dict = {}
        node = doc
        for s in sections:
            node = node.setdefault(s, {})
        node[key] = value
        with pytest.raises(ConfigError) as e:
            schema.parse(FglocConfig, doc, source="c.yaml")
        assert str(e.value).startswith(f"c.yaml: {path}: ") and "inf" in str(e.value), str(e.value)
        refused += 1
    assert refused == len(FLOATS)


@pytest.mark.parametrize(("text", "problem"), [
    (".inf", "pipeline.lost_after_s: must be a finite number, got .inf"),
    ("-.Inf", "pipeline.lost_after_s: must be a finite number, got -.inf"),
    (".nan", "pipeline.lost_after_s: must be a number, got NaN"),
    ("inf", "pipeline.lost_after_s: expected a number, got inf"),
])
def test_non_finite_numbers_are_one_line_errors(tmp_path, capsys, text, problem):
    f = tmp_path / "c.yaml"
    f.write_text(f"pipeline:\n  lost_after_s: {text}\n")
    assert main(["config", "show", "--config", str(f)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"fgloc: error: {f}: {problem}"]


@pytest.mark.parametrize("shape", ["flow", "block", "value"])
def test_a_deeply_nested_config_is_a_one_line_error(tmp_path, capsys, shape):
    n = 5000
    text = {"flow": "pipeline: " + "[" * n + "]" * n + "\n",
            "block": "".join("  " * i + f"k{i}:\n" for i in range(n)) + "  " * n + "v\n",
            # deep but readable: the value itself is too deep to show in the error
            "value": "pipeline:\n  lost_after_s: " + "[" * 400 + "]" * 400 + "\n"}[shape]
    f = tmp_path / "deep.yaml"
    f.write_text(text)
    rc = main(["config", "show", "--config", str(f)])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and err[0].startswith(f"fgloc: error: {f}: "), err
    assert len(err[0]) < 300


def test_without_libyaml_deep_nesting_is_a_yaml_error_not_a_recursion_error():
    """PyYAML's own composer recurses per level (libyaml stops at its nesting limit)."""
    with pytest.raises(yaml.YAMLError):
        schema.load_yaml("a: " + "[" * 5000 + "]" * 5000, loader=schema.yaml12_loader(yaml.SafeLoader))
    assert schema.load_yaml("a: 1e-3", loader=schema.yaml12_loader(yaml.SafeLoader)) == {"a": 0.001}


def test_a_map_server_yaml_with_a_1_2_float_loads(tmp_path):
    """map_server (yaml-cpp) writes and reads YAML 1.2: ``resolution: 5e-2`` is its number."""
    from PIL import Image

    Image.fromarray(np.full((20, 30), 254, dtype=np.uint8)).save(tmp_path / "m.pgm")
    (tmp_path / "m.yaml").write_text("image: m.pgm\nresolution: 5e-2\norigin: [-1e0, 0.0, 0.0]\nnegate: 0\n"
                                     "occupied_thresh: 0.65\nfree_thresh: 0.196\n")
    m = load_map(tmp_path / "m.yaml")
    assert m.resolution == 0.05 and m.origin[0] == -1.0
