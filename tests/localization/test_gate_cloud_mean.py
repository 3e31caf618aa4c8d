"""A particle filter's fix whose scan fit was not kept (its cloud's mean, ``fitted=False``) is judged by the
jump gate (fgloc.localization.gate) without the map's resolution: a cloud moving from a wrong place to the right
one passes between the two, and the map's floor (its 5 cm cell) would pass such a mean 0.15 m from a sure
prediction.  A scan fit as far off, and a cloud mean the covariances explain, are taken as before."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from fgloc.localization.gate import JumpGate
from fgloc.localization.monitor import IntegrityConfig
from fgloc.types import PoseFix

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "frontends"))
from synth import MOUNT, make_map, make_scan  # noqa: E402

PRED_COV = np.diag([0.006**2, 0.006**2, np.radians(0.3) ** 2])


@pytest.fixture(scope="module")
def room():
    return make_map()


def _fix(pose, sigma_m):
    return PoseFix(1.0, np.asarray(pose, dtype=float), np.diag([sigma_m**2, sigma_m**2, np.radians(0.5) ** 2]),
                   quality=1.0, source="test")


def _check(room, offset_m, sigma_m, fitted):
    gate = JumpGate(IntegrityConfig(), room, MOUNT)
    p = np.array([4.0, 3.0, 0.0])  # the truth and the prediction
    return gate.check(_fix(p + [0.0, offset_m, 0.0], sigma_m), p, PRED_COV, make_scan(room, p), np.zeros(3), 1.0,
                      fitted=fitted)


def test_a_cloud_mean_between_two_places_is_held(room):
    """0.15 m off a prediction sure to 6 mm, a 2.5 cm sigma: within the map's floor (3.7 x 5 cm), not within
    the covariances (d2 about 35); the map, which sees the scan at the prediction, does not confirm it."""
    v = _check(room, 0.15, 0.025, fitted=False)
    assert not v.take and not v.confirmed
    assert v.d2 > 13.82
    assert v.agree_fix is not None and v.agree_pred is not None and v.agree_fix < v.agree_pred


def test_a_scan_fit_as_far_off_is_still_within_the_maps_floor(room):
    v = _check(room, 0.15, 0.025, fitted=True)
    assert v.take and v.d2 < 13.82


def test_a_cloud_mean_the_covariances_explain_is_taken(room):
    """3 cm off with the same spread: the cloud is where the prediction is."""
    v = _check(room, 0.03, 0.025, fitted=False)
    assert v.take and v.d2 < 13.82


def test_a_cloud_leaving_the_shelves_wrong_place_does_not_pull_the_ekf():
    """changed_world seed 11, EKF + AMCL, up to 84 s: a wrong AMCL run along the north-wall shelves is held 13 s,
    then two cloud means between it and the truth reach the gate (measured: max error 0.078 m, largest step 0.084
    m, no pose lost; 0.113 m, 0.129 m and 49 lost when the map's floor passed them)."""
    from fgloc.eval.metrics import position_errors_and_steps
    from fgloc.testing.scenario_runs import localize_until

    run = localize_until("changed_world", 11, "ekf", "amcl", until_s=84.0)
    err, step = position_errors_and_steps(run.estimate, run.sim.ground_truth)
    assert float(step.max()) <= 0.1
    assert float(err.max()) <= 0.1
    assert run.localizer.monitor.counts(run.estimate.stamps)["lost"] == 0
