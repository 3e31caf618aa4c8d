"""The mapped / unmapped split of a real-map localization run (tools/eval_frontends_real.py)."""

from __future__ import annotations

import math

import numpy as np

from fgloc.eval.metrics import split_errors, within_radius


def test_within_radius_marks_points_near_an_anchor():
    pts = np.array([[0.0, 0.0], [1.9, 0.0], [2.1, 0.0], [10.0, 10.0]])
    anchors = np.array([[0.0, 0.0], [10.0, 11.5]])
    assert within_radius(pts, anchors, 2.0).tolist() == [True, True, False, True]
    assert within_radius(pts, np.zeros((0, 2)), 2.0).tolist() == [False] * 4


def test_split_errors_rms_per_part():
    e_xy = np.array([0.1, 0.1, 3.0, 4.0])
    e_yaw = np.radians([1.0, -1.0, 10.0, 0.0])
    s = split_errors(e_xy, e_yaw, np.array([True, True, False, False]))
    assert s["in"]["n"] == 2 and s["out"]["n"] == 2
    assert math.isclose(s["in"]["rmse_m"], 0.1) and math.isclose(s["in"]["rmse_deg"], 1.0)
    assert math.isclose(s["out"]["rmse_m"], math.sqrt(12.5)) and s["out"]["max_m"] == 4.0
    assert math.isclose(s["out"]["rmse_deg"], math.sqrt(50.0))
    empty = split_errors(e_xy, e_yaw, np.ones(4, dtype=bool))["out"]
    assert empty["n"] == 0 and math.isnan(empty["rmse_m"]) and math.isnan(empty["rmse_deg"])
