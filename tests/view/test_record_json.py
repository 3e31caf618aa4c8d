"""The recorder's JSON channels are written by a direct encoder: the same bytes as ``json.dumps``."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from fgloc.types import PoseFix
from fgloc.view import encode
from fgloc.view.record import flat_json


def _dumps(obj: dict) -> bytes:
    return json.dumps(obj, separators=(",", ":"), allow_nan=False).encode()


def test_flat_json_is_json_dumps_byte_for_byte():
    rng = np.random.default_rng(5)
    floats = [0.0, -0.0, 1.0, -2.5, 1e-300, 5e-324, 1.7976931348623157e308, 123456789.123456789, 0.1 + 0.2]
    floats += [float(x) for x in rng.standard_normal(200) * 10.0 ** rng.integers(-12, 12, 200)]
    strings = ["", "map", 'quote " and \\ backslash', "tab\tnewline\n", "\u00e9t\u00e9 \u2192 \U0001f600", "\x00\x1f"]
    for i in range(300):
        obj = {"stamp": floats[i % len(floats)], "status": strings[i % len(strings)],
               "n": int(rng.integers(-5, 10**12)), "ok": bool(i % 2), "none": None,
               "cov": [floats[(i + k) % len(floats)] for k in range(i % 10)],
               strings[(i + 1) % len(strings)]: floats[(i * 7) % len(floats)]}
        assert flat_json(obj) == _dumps(obj), obj


def test_the_channels_messages_are_json_dumps():
    f = PoseFix(12.5, np.array([1.25, -2.0, 3.1]), np.array([[1e-4, 2e-5, 0.0], [2e-5, 3e-4, 0.0], [0.0, 0.0, 1e-5]]),
                source="smoother")
    fix = PoseFix(12.5, np.array([1.26, -2.01, 3.09]), np.diag([1e-4, 1e-4, -1.0]), source="native")
    for obj in (encode.fused_json(f), encode.fix_json(12.5, "accepted", "", fix, f),
                encode.fix_json(12.5, "no_fix", "too few inliers (3 of 40)", None, None)):
        assert flat_json(obj) == _dumps(obj)
    assert encode.fix_json(12.5, "accepted", "", fix, f)["sigma_yaw_deg"] is None  # a negative variance


@pytest.mark.parametrize("obj", [{"x": math.nan}, {"x": [1.0, math.inf]}, {"x": np.float64(1.5)}, {"x": {"y": 1.0}},
                                 {"x": [1]}, {1: 2.0}, {"x": (1.0, 2.0)}])
def test_anything_else_is_left_to_json(obj):
    assert flat_json(obj) is None
