"""The Must-show numbers on the simulated paper run: convergence from 0.3 m / 10 deg off and NEES."""

from __future__ import annotations

import numpy as np
import pytest

from fgloc.frontends import make_frontend
from fgloc.geometry import wrap_angle


def _offset_guesses(truth: np.ndarray, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    a = rng.uniform(0, 2 * np.pi, len(truth))
    d = np.column_stack([0.3 * np.cos(a), 0.3 * np.sin(a), np.radians(10.0) * rng.choice([-1, 1], len(truth))])
    return truth + d


def _run(fe, data, idx, guesses):
    """Match scans ``idx``, each after feeding the two scans before it through the preprocessor
    (as a front-end called on every scan would have seen them: de-skew clock and twist history)."""
    out = []
    for i in idx:
        fe.reset()
        for j in (i - 2, i - 1):
            if j >= 0:
                fe.pre(data.scans[j], data.odom_deltas[j])
        out.append(fe.match(data.scans[i], guesses[i], data.odom_deltas[i]))
    return out


STRIDE = {"native": 3, "kiss": 12}


@pytest.mark.parametrize("name", ["native", "kiss"])
def test_paper_converges_from_30cm_10deg(paper_scans, name):
    data = paper_scans
    fe = make_frontend(name, data.map, data.laser_mount, None)
    idx = np.arange(0, len(data.scans), STRIDE[name])
    res = _run(fe, data, idx, _offset_guesses(data.truth, 7))
    good = 0
    for i, r in zip(idx, res, strict=True):
        if r.ok:
            e = r.pose - data.truth[i]
            good += np.hypot(e[0], e[1]) < 0.02 and abs(np.degrees(wrap_angle(e[2]))) < 0.3
    assert good / len(idx) >= 0.95


@pytest.mark.parametrize("name", ["native", "kiss"])
def test_paper_nees_is_honest(paper_scans, name):
    data = paper_scans
    fe = make_frontend(name, data.map, data.laser_mount, None)
    idx = np.arange(2, len(data.scans), STRIDE[name])
    rng = np.random.default_rng(3)
    guesses = data.truth + np.column_stack([rng.normal(0, 0.05, (len(data.truth), 2)),
                                            rng.normal(0, np.radians(2), len(data.truth))])
    nees = []
    for i, r in zip(idx, _run(fe, data, idx, guesses), strict=True):
        if r.ok:
            e = r.pose - data.truth[i]
            e[2] = wrap_angle(e[2])
            nees.append(float(e @ np.linalg.solve(r.cov, e)))
    assert len(nees) >= 0.9 * len(idx)
    assert 1.5 <= np.mean(nees) <= 6.0
