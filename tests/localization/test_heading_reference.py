"""How much of a localizer's heading error against a SLAM reference is the reference's: the
three-cornered hat with a second reference (issue 13 item 4; tools/eval_frontends_real.py prints it
beside the full figure for the segments GMapping's corrected logs cover)."""

from __future__ import annotations

import numpy as np

from fgloc.eval.metrics import three_cornered_hat


def _ms(v: np.ndarray) -> float:
    return float(np.mean(v * v))


def test_independent_errors_are_split_to_their_sources():
    rng = np.random.default_rng(7)
    n = 200_000
    est, slam, gm = rng.normal(0.0, 0.6, n), rng.normal(0.0, 0.3, n), rng.normal(0.0, 0.8, n)
    a, b, c = three_cornered_hat(_ms(est - slam), _ms(est - gm), _ms(slam - gm))
    # sigmas 0.6 / 0.3 / 0.8 deg back within 1 %
    assert abs(np.sqrt(a) - 0.6) < 0.006
    assert abs(np.sqrt(b) - 0.3) < 0.006
    assert abs(np.sqrt(c) - 0.8) < 0.008


def test_exact_variances():
    # v_ab = 1 + 4, v_ac = 1 + 9, v_bc = 4 + 9
    assert three_cornered_hat(5.0, 10.0, 13.0) == (1.0, 4.0, 9.0)


def test_an_error_two_share_goes_to_the_third():
    # the localizer and SLAM share an error (the same scans, a map from SLAM's other passes): it cancels
    # in their pair and is counted to GMapping, whose own error is 0 here
    rng = np.random.default_rng(3)
    n = 200_000
    shared = rng.normal(0.0, 0.5, n)
    est, slam, gm = shared + rng.normal(0.0, 0.2, n), shared, np.zeros(n)
    a, b, c = three_cornered_hat(_ms(est - slam), _ms(est - gm), _ms(slam - gm))
    assert abs(np.sqrt(a) - 0.2) < 0.005      # the localizer's own part only
    assert abs(b) < 0.003                      # SLAM's own: none
    assert abs(np.sqrt(c) - 0.5) < 0.005      # the shared 0.5 deg shows up as GMapping's
