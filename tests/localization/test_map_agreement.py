"""It knows when it is wrong (fgloc.localization.monitor.MapAgreement): the scan's agreement with the map at
the fused pose, against the run's own good level; a sustained drop makes the poses suspect, then lost, and the
localizer searches again (a particle filter that tracked on after a kidnapping)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from fgloc.localization import Localizer, Session
from fgloc.localization.monitor import IntegrityConfig, MapAgreement
from fgloc.maps import OccupancyMap

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "frontends"))
from synth import MOUNT, make_map, make_scan  # noqa: E402

TRUE = np.array([3.0, 3.0, 0.3])


def test_the_expectation_is_learnt_and_a_wrong_pose_is_low_for_as_long_as_it_lasts():
    m = make_map()
    cfg = IntegrityConfig()
    ag = MapAgreement(cfg, m, MOUNT, 0.1)
    rng = np.random.default_rng(1)
    scan = make_scan(m, TRUE, rng)
    t = 0.0
    for _ in range(MapAgreement.MIN_SAMPLES):
        t += cfg.agreement_period_s
        pose = TRUE + [rng.normal(0, 0.01), rng.normal(0, 0.01), 0.0]  # the fused pose, a centimetre off
        assert ag.check(t, scan, pose, good=True) > 0.8
    assert ag.expected() > 0.8 and ag.low_for(t) == 0.0
    # not due again before a period passed (log time)
    assert ag.check(t + cfg.agreement_period_s / 2, scan, TRUE, good=True) is None
    wrong = TRUE + [2.0, 1.5, 0.0]  # where the fusion believes the robot is: the scan lies off the walls
    t_right = t
    for k in range(1, 5):
        a = ag.check(t + k * cfg.agreement_period_s, scan, wrong, good=True)
        assert a < cfg.agreement_low * ag.expected()
    assert ag.low_for(t + 4 * cfg.agreement_period_s) == pytest.approx(3 * cfg.agreement_period_s)
    assert ag.wrong_since == t_right  # the last measurement that fit
    assert ag.expected() > 0.8  # the low ones did not teach it
    t += 5 * cfg.agreement_period_s
    assert ag.check(t, scan, TRUE, good=True) > 0.8 and ag.low_for(t) == 0.0


def test_a_scan_into_space_the_map_does_not_have_is_no_measurement():
    """The westmost 2.5 m of the room known, the rest unknown: looking west the scan fits; looking east most
    beams end in the unknown part without crossing a mapped wall: low, but the map cannot judge it."""
    m = make_map()
    data = m.data.copy()
    data[:, int(2.5 / m.resolution):] = -1
    part = OccupancyMap(data, m.resolution, m.origin)
    cfg = IntegrityConfig()
    ag = MapAgreement(cfg, part, MOUNT, 0.1)
    west, east = np.array([1.5, 5.5, np.pi]), np.array([1.5, 5.5, 0.0])
    scan_w, scan_e = make_scan(m, west), make_scan(m, east)
    t = 0.0
    for _ in range(MapAgreement.MIN_SAMPLES):
        t += cfg.agreement_period_s
        assert ag.check(t, scan_w, west, good=True) is not None
    assert ag.measure(scan_e, east) < cfg.agreement_low * ag.expected()
    assert ag.check(t + cfg.agreement_period_s, scan_e, east, good=True) is None
    assert ag.unmapped_checks == 1 and ag.low_for(t + cfg.agreement_period_s) == 0.0
    # the same scan where the map has walls in the way (turned round: the pose wrong, not the map short): low
    assert ag.check(t + 2 * cfg.agreement_period_s, scan_e, west, good=True) < cfg.agreement_low * ag.expected()
    assert ag.low_checks == 1


@pytest.fixture(scope="module")
def kidnapped():
    """The paper's first leg and a turn; at 6 s the robot is carried 15 s ahead along its route (about 10 m,
    round the corner); the odometry does not see it."""
    from fgloc.sim import run_scenario

    return run_scenario({"route": [[2.5, 3.0], [27.5, 3.0], [27.5, 17.0]],
                         "faults": {"kidnap": {"time": 6.0, "skip_s": 15.0}}}, seed=0)


def test_amcl_and_the_smoother_recover_from_a_kidnapping(kidnapped):
    """Before the monitor AMCL tracked on at the old place and the smoother followed it: ok poses 12.5 m off
    to the end (agreement_low 1e-6 here: 137 ok poses > 0.25 m off)."""
    sim = kidnapped
    msgs = [(t, m) for t, m in sim.messages if t != "/ground_truth" and getattr(m, "stamp", 0.0) < 16.0]
    loc = Localizer(sim.map, sim.laser_mount, "smoother", "amcl", initial_pose=sim.ground_truth.poses[0])
    est = Session(loc).run(msgs)
    status = np.array(loc.monitor.at(est.stamps)[0])
    err = np.hypot(*(est.poses[:, :2] - sim.ground_truth.interpolate(est.stamps)[:, :2]).T)
    assert loc.stats["agreement_lost"] >= 1
    (v,) = [v for v in loc.stats["status"]["verdicts"] if v["kind"] == "agreement"]
    assert v["message"].startswith("the scan stopped fitting the map at the fused pose") and not v["unusable"]
    assert float(err[status == "ok"].max()) < 0.1  # measured 0.010 m
    assert (status[err > 1.0] != "ok").all() and (status == "lost").sum() >= 10  # measured 36 lost
    on = loc.online_trajectory()
    on_err = np.hypot(*(on.poses[:, :2] - sim.ground_truth.interpolate(on.stamps)[:, :2]).T)
    after = on.stamps >= 6.0
    bad = np.nonzero(after & (on_err >= 0.2))[0]
    assert len(bad) and bad[-1] + 1 < len(on.stamps)
    assert float(on.stamps[bad[-1] + 1]) - 6.0 < 5.0  # recovered (the online pose within 0.2 m for good)
    # one placement the odometry did not drive to: a kidnapping, not a map that does not fit
    assert loc.map_jumps is not None and loc.map_jumps.events == 1
    assert not [v for v in loc.stats["status"]["verdicts"] if v["kind"] == "map_mismatch"]
