"""The jump gate's anchor check (JumpGate.map_prefers_fix) answers what its definition asks, whichever of the
poses near the prediction settles it: the map explains the scan better at the fix than at every pose of
JumpGate.agreement's neighbourhood of the prediction (the prediction itself, turned, moved)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from fgloc.localization.gate import JumpGate
from fgloc.localization.monitor import IntegrityConfig
from fgloc.types import PoseFix

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "frontends"))
from synth import MOUNT, make_map, make_scan  # noqa: E402


def test_the_map_prefers_the_fix_exactly_when_it_beats_the_whole_neighbourhood():
    room = make_map()
    rng = np.random.default_rng(3)
    gate = JumpGate(IntegrityConfig(), room, MOUNT)
    truth = np.array([8.0, 5.0, 0.3])
    scan = make_scan(room, truth, rng)
    answers = []
    for _ in range(60):
        # the fix near the truth, the prediction off it by up to 15 cm / 4 deg, its covariance a few cm
        fix = PoseFix(1.0, truth + rng.normal(0.0, [0.01, 0.01, 0.003]), np.diag([1e-4, 1e-4, 1e-5]))
        pred = truth + rng.normal(0.0, [0.06, 0.06, 0.03])
        cov = np.diag([rng.uniform(1e-5, 4e-4), rng.uniform(1e-5, 4e-4), rng.uniform(1e-6, 1e-4)])
        a_near, a_fix = gate.agreement(fix, pred, cov, scan)
        answer = gate.map_prefers_fix(fix, pred, cov, scan)
        assert answer == (a_fix > a_near)
        answers.append(answer)
    assert 10 <= sum(answers) <= 50  # both answers asked for
    # the prediction's own pose turned a little explains the scan as well as the fix: that alone says no
    pred = truth + np.array([0.0, 0.0, 0.01])
    fix = PoseFix(1.0, truth.copy(), np.diag([1e-4, 1e-4, 1e-5]))
    assert not gate.map_prefers_fix(fix, pred, np.diag([1e-6, 1e-6, 1e-4]), scan)
