"""The smoother's running median spacing of a stamp list equals the plain one after every change."""

import random

from fgloc.backends.smoother import PERIOD_STAMPS, RunningSpacing, median_spacing


def test_running_spacing_equals_median_spacing_as_the_list_grows_and_is_trimmed():
    rng = random.Random(7)
    checked = 0
    for _ in range(200):
        ts: list[float] = []
        running = RunningSpacing(ts)
        t = rng.uniform(0.0, 10.0)
        for _ in range(rng.randint(1, 200)):
            # steady, jittered, bursty and stalled streams; several stamps between two questions, or many
            for _ in range(rng.choice([0, 1, 1, 2, 3, 5, PERIOD_STAMPS + 10])):
                t += rng.choice([0.02, 0.02, 0.0199999, 0.05, rng.uniform(1e-4, 0.3)])
                ts.append(t)
            if rng.random() < 0.05 and len(ts) > 2:  # the oldest stamps dropped, sometimes into the window
                del ts[:rng.randint(1, len(ts) - 1)]
            expected, got = median_spacing(ts), running.value()
            assert got == expected
            checked += 1
    assert checked > 5000


def test_running_spacing_follows_a_steady_stream():
    ts = [0.02 * i for i in range(2)]
    running = RunningSpacing(ts)
    assert running.value() == float("inf")  # fewer than 3 stamps
    ts.extend(0.02 * i for i in range(2, 500))
    assert abs(running.value() - 0.02) < 1e-12
    ts.append(ts[-1] + 1.0)   # one stall does not move the median
    assert abs(running.value() - 0.02) < 1e-12
