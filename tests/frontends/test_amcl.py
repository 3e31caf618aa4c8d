"""AMCL: tracking, global localization (paper hall and Willow Garage), NEES, bad input, motion noise, KLD."""

from __future__ import annotations

import numpy as np
import pytest

from fgloc.frontends.amcl import AMCL, AMCL_DEFAULTS, kld_limit, sample_motion, wall_surface_field
from fgloc.geometry import between, wrap_angle
from fgloc.maps import OccupancyMap
from fgloc.types import LaserScan, Odometry

from .conftest import odom_poses_at


def _run(amcl: AMCL, scans, truth, deltas, n=None):
    """Feed scans; returns (index, MatchResult) for every fix."""
    out = []
    for i, s in enumerate(scans[:n]):
        r = amcl.match(s, truth[0], deltas[i])
        assert r.ok or r.reason
        if r.ok:
            out.append((i, r))
    return out


def _errors(fixes, truth):
    e = np.array([r.pose - truth[i] for i, r in fixes])
    e[:, 2] = wrap_angle(e[:, 2])
    return e


@pytest.fixture(scope="module")
def paper_tracking(paper_scans):
    d = paper_scans
    a = AMCL.from_config(d.map, d.laser_mount, {})
    a.reset(d.truth[0])
    return _run(a, d.scans, d.truth, d.odom_deltas)


def test_tracks_paper_run_under_5cm(paper_scans, paper_tracking):
    e = _errors(paper_tracking, paper_scans.truth)
    rmse = float(np.sqrt(np.mean(np.sum(e[:, :2] ** 2, axis=1))))
    assert len(paper_tracking) > 300  # one fix per 0.1 m of the 78 m route
    assert rmse < 0.05, rmse


def test_nees_paper_run(paper_scans, paper_tracking):
    e = _errors(paper_tracking, paper_scans.truth)
    nees = [float(ei @ np.linalg.solve(r.cov, ei)) for ei, (_, r) in zip(e, paper_tracking, strict=True)]
    assert 1.0 <= float(np.mean(nees)) <= 6.0, np.mean(nees)


def _global_convergence_time(occ_map, mount, scans, truth, deltas, cfg, hold_s=5.0):
    """Seconds from the first scan until the first fix within 0.2 m of the truth after which
    every fix of the next ``hold_s`` seconds stays within 0.2 m (inf if never)."""
    a = AMCL.from_config(occ_map, mount, cfg)
    a.reset(None)
    t0 = scans[0].stamp
    t_conv = None
    for i, s in enumerate(scans):
        r = a.match(s, truth[0], deltas[i])
        if not r.ok:
            continue
        good = np.hypot(*(r.pose[:2] - truth[i, :2])) < 0.2
        if t_conv is None and good:
            t_conv = s.stamp - t0
        elif t_conv is not None and not good:
            t_conv = None
        if t_conv is not None and s.stamp - t0 > t_conv + hold_s:
            return t_conv, a
    return np.inf, a


def test_global_localization_paper(paper_scans):
    d = paper_scans
    t, a = _global_convergence_time(d.map, d.laser_mount, d.scans, d.truth, d.odom_deltas,
                                    {})
    assert t <= 10.0, t
    assert len(a.particles) <= a.max_particles  # KLD shrank the cloud from 60000


def test_global_localization_willow():
    from fgloc.config import scenario_path
    from fgloc.sim import run_scenario

    sim = run_scenario(str(scenario_path("willow")), seed=0)
    scans = [m for _, m in sim.messages if isinstance(m, LaserScan)]
    odoms = [m for tp, m in sim.messages if isinstance(m, Odometry) and tp != "/ground_truth"]
    st = np.array([s.stamp for s in scans])
    truth = sim.ground_truth.interpolate(st)
    od = odom_poses_at(odoms, st)
    deltas = [None] + [between(od[i - 1], od[i]) for i in range(1, len(scans))]
    t, _ = _global_convergence_time(sim.map, sim.laser_mount, scans, truth, deltas,
                                    {"robot_model_type": "differential"})
    assert t <= 10.0, t


def _box_map() -> OccupancyMap:
    g = np.zeros((100, 140), dtype=np.int16)
    g[0, :] = g[-1, :] = 100
    g[:, 0] = g[:, -1] = 100
    g[30:45, 60:70] = 100
    return OccupancyMap(g, 0.05)


def _scan(ranges) -> LaserScan:
    r = np.asarray(ranges, dtype=np.float32)
    return LaserScan(0.0, -2.35, 4.7 / (len(r) - 1), 0.05, 30.0, r)


def test_bad_input_gives_no_fix():
    m = _box_map()
    a = AMCL(m, None)
    pose = np.array([2.0, 3.0, 0.3])
    ang = -2.35 + 4.7 / 540 * np.arange(541) + pose[2]
    good = m.raycast(pose[:2], ang, 30.0)
    # off-map guess before initialisation
    r = a.match(_scan(good), np.array([50.0, 50.0, 0.0]))
    assert not r.ok and "off the map" in r.reason
    for bad in (np.full(541, np.nan), np.full(541, np.inf), np.full(541, -np.inf), np.zeros(541),
                np.where(np.arange(541) < 5, good, np.nan)):
        r = a.match(_scan(bad), pose)
        assert not r.ok and "valid beams" in r.reason
    r = a.match(_scan(good), pose, np.array([np.nan, 0, 0]))
    assert not r.ok and "odometry" in r.reason
    a.reset(pose, np.diag([0.01, 0.01, 0.003]))
    r = a.match(_scan(good), pose)
    assert r.ok and np.hypot(*(r.pose[:2] - pose[:2])) < 0.1
    r = a.match(_scan(good), pose, np.zeros(3))
    assert not r.ok and r.reason.startswith("waiting for motion (update_min_d ")


@pytest.mark.parametrize("model", ["differential", "omni"])
def test_motion_noise_matches_alphas(model):
    rng = np.random.default_rng(1)
    al = np.array([0.1, 0.2, 0.05, 0.05, 0.15])  # small a3: |trans| never folds
    n = 200000
    p0 = np.zeros((n, 3))
    delta = np.array([1.0, 0.0, 0.5]) if model == "differential" else np.array([0.6, 0.8, 0.5])
    p = sample_motion(p0, delta, model, al, rng)
    trans, rot = np.hypot(*delta[:2]), delta[2]
    if model == "differential":
        # rot1 = 0, rot2 = 0.5: yaw noise var = 2 * alpha2 trans^2 + alpha1 rot2^2
        assert np.std(p[:, 2]) == pytest.approx(np.sqrt(2 * al[1] * trans**2 + al[0] * rot**2), rel=0.02)
        d = np.hypot(p[:, 0], p[:, 1])
        assert np.std(d) == pytest.approx(np.sqrt(al[2] * trans**2 + al[3] * rot**2), rel=0.03)
        assert np.mean(p[:, 2]) == pytest.approx(rot, abs=0.01)
    else:
        assert np.std(p[:, 2]) == pytest.approx(np.sqrt(al[3] * rot**2 + al[1] * trans**2), rel=0.02)
        u = delta[:2] / trans
        along = p[:, :2] @ u
        across = p[:, :2] @ np.array([u[1], -u[0]])
        assert np.std(along) == pytest.approx(np.sqrt(al[2] * trans**2 + al[0] * rot**2), rel=0.02)
        assert np.std(across) == pytest.approx(np.sqrt(al[0] * rot**2 + al[4] * trans**2), rel=0.02)
        assert np.mean(along) == pytest.approx(trans, abs=0.01)


def test_kld_count_shrinks_as_cloud_converges():
    assert kld_limit(1, 0.05, 0.99, 10, 5000) == 5000
    ks = kld_limit(np.array([2, 10, 100, 1000]), 0.05, 0.99, 1, 10**6)
    assert np.all(np.diff(ks) > 0)
    m = _box_map()
    a = AMCL(m, None, global_particles=8000, min_particles=100, max_particles=2000)
    a.reset(None)
    pose = np.array([2.0, 3.0, 0.3])
    counts = [len(a.particles)]
    for k in range(8):
        p = pose + np.array([0.05 * k, 0.0, 0.0])
        ang = -2.35 + 4.7 / 540 * np.arange(541) + p[2]
        s = _scan(m.raycast(p[:2], ang, 30.0))
        a.match(s, p, None if k == 0 else np.array([0.05, 0.0, 0.0]))
        counts.append(len(a.particles))
    assert counts[0] == 8000  # spread over free space
    assert counts[-1] < 500 and counts[-1] <= min(counts)  # converged: few bins, few particles


def test_defaults_match_constructor():
    """The defaults live in AMCLConfig only (fgloc.config convention); AMCL_DEFAULTS is derived from it."""
    from fgloc.config.schema import to_dict
    from fgloc.frontends.amcl import AMCLConfig

    assert AMCL_DEFAULTS == to_dict(AMCLConfig()) and AMCL_DEFAULTS["max_particles"] == 2000


def test_grey_wall_map_needs_unknown_edges(shared_data):
    """The raw 2010 Willow Garage map stores most walls as grey (unknown) pixels: only ~544 cells are
    occupied at the 0.65 threshold.  With field_walls=occupied+unknown_edge AMCL tracks on it anyway."""
    from fgloc.config import scenario_path
    from fgloc.sim import run_scenario

    raw = OccupancyMap.load(shared_data / "maps" / "willow-2010-02-18-0.10.yaml")
    assert raw.occupied.sum() < 1000
    sim = run_scenario(str(scenario_path("willow")), seed=0)
    scans = [m for _, m in sim.messages if isinstance(m, LaserScan)][:400]
    odoms = [m for tp, m in sim.messages if isinstance(m, Odometry) and tp != "/ground_truth"]
    st = np.array([s.stamp for s in scans])
    truth = sim.ground_truth.interpolate(st)
    od = odom_poses_at(odoms, st)
    deltas = [None] + [between(od[i - 1], od[i]) for i in range(1, len(scans))]
    a = AMCL(raw, sim.laser_mount, robot_model_type="differential", field_walls="occupied+unknown_edge")
    a.reset(truth[0])
    e = _errors(_run(a, scans, truth, deltas), truth)
    assert len(e) > 50
    assert float(np.sqrt(np.mean(np.sum(e[:, :2] ** 2, axis=1)))) < 0.1


#: nav2_bringup's default amcl parameters (nav2_params.yaml), in fgloc's key names
NAV2_DEFAULTS = {
    "robot_model_type": "differential", "alpha1": 0.2, "alpha2": 0.2, "alpha3": 0.2, "alpha4": 0.2, "alpha5": 0.2,
    "laser_model_type": "likelihood_field", "z_hit": 0.5, "z_rand": 0.5, "sigma_hit": 0.2, "laser_max_beams": 60,
    "laser_likelihood_max_dist": 2.0, "laser_max_range": 100.0, "min_particles": 500, "max_particles": 2000,
    "pf_err": 0.05, "pf_z": 0.99, "resample_interval": 1, "recovery_alpha_slow": 0.0, "recovery_alpha_fast": 0.0,
    "update_min_d": 0.25, "update_min_a": 0.2,
}


def test_nav2_defaults_give_a_fix_per_update(paper_scans):
    """With nav2's defaults the cloud stays 0.3-0.6 m wide: a gate on a width in metres (0.25 m) gave
    0-4 fixes per log.  Convergence is judged by the filter's own clusters: every update gives a fix,
    the estimate is refined on the scan, and its covariance is the scan fit's (NEES near 3)."""
    d = paper_scans
    a = AMCL.from_config(d.map, d.laser_mount, NAV2_DEFAULTS)
    a.reset(d.truth[0])
    fixes, updates = [], 0
    for i, s in enumerate(d.scans):
        r = a.match(s, d.truth[0], d.odom_deltas[i])
        updates += bool(r.info.get("updated"))
        if r.ok:
            fixes.append((i, r))
    assert updates > 250 and len(fixes) >= 0.95 * updates
    assert float(np.median([r.info["std_xy"] for _, r in fixes])) > 0.25  # the wide cloud nav2 keeps
    e = _errors(fixes, d.truth)
    assert float(np.sqrt(np.mean(np.sum(e[:, :2] ** 2, axis=1)))) < 0.04
    nees = [float(ei @ np.linalg.solve(r.cov, ei)) for ei, (_, r) in zip(e, fixes, strict=True)]
    assert 1.0 <= float(np.median(nees)) <= 6.0


def test_estimate_mean_is_the_cluster_mean(paper_scans):
    d = paper_scans
    a = AMCL.from_config(d.map, d.laser_mount, {**NAV2_DEFAULTS, "estimate": "mean"})
    a.reset(d.truth[0])
    fixes = _run(a, d.scans, d.truth, d.odom_deltas, n=600)
    assert len(fixes) > 40 and not any(r.info["refined"] for _, r in fixes)
    # the weak nav2 sensor model leaves the cloud mean lagging by ~0.1 m; the cloud covariance says so
    e = _errors(fixes, d.truth)
    nees = [float(ei @ np.linalg.solve(r.cov, ei)) for ei, (_, r) in zip(e, fixes, strict=True)]
    assert float(np.median(nees)) < 3.0


def test_two_modes_are_not_converged_one_wide_mode_is(paper_scans):
    d = paper_scans
    a = AMCL.from_config(d.map, d.laser_mount, {"estimate": "mean"})
    rng = np.random.default_rng(4)
    p = d.truth[100]
    # one wide Gaussian (0.4 m, 8 deg): one connected cluster of 0.5 m / 10 deg bins -> a fix with that width
    a.reset(p, np.diag([0.4**2, 0.4**2, np.radians(8) ** 2]))
    a._force_update = False
    r = a.match(d.scans[100], p, np.zeros(3))
    assert r.reason.startswith("waiting for motion (update_min_d")  # nothing moved: no update, no fix
    a2 = AMCL.from_config(d.map, d.laser_mount, {"estimate": "mean", "fix_without_update": True})
    a2.reset(p, np.diag([0.4**2, 0.4**2, np.radians(8) ** 2]))
    a2._force_update = False
    r = a2.match(d.scans[100], p, np.zeros(3))
    assert r.ok and r.info["cluster_share"] > 0.99 and r.info["std_xy"] > 0.3
    # two tight blobs 3 m apart, equal weight: the heaviest cluster holds half -> not converged
    blob = rng.normal(0, 0.05, (1000, 3))
    a2.particles = np.vstack([p + blob, p + [3.0, 0.0, 0.0] + blob])
    a2.weights = np.full(2000, 1 / 2000)
    r = a2.match(d.scans[100], p, np.zeros(3))
    assert not r.ok and "not converged" in r.reason and 0.4 < r.info["cluster_share"] < 0.6


def test_clusters_join_across_the_heading_wrap():
    from fgloc.frontends.amcl import bin_clusters

    n_yaw = 36
    keys = np.array([[0, 0, 0], [0, 0, 35], [5, 5, 10], [0, 1, 1]], dtype=np.int64)
    labels, wsum = bin_clusters(keys, np.array([0.1, 0.2, 0.3, 0.4]), n_yaw)
    assert labels[0] == labels[1] == labels[3] != labels[2]  # -pi and +pi neighbours, diagonal neighbour
    assert sorted(np.round(wsum, 6)) == [0.3, 0.7]


def test_paper_fixes_are_unbiased(paper_scans, paper_tracking):
    """The fixes' mean error in the robot's frame is within a few mm: the likelihood field's zero
    lies on the wall surface, not half a cell inside the walls (which pulls the pose towards the
    walls the laser sees: +7.9 mm ahead, +4.3 mm left, 24 mm RMSE on this run before)."""
    e = _errors(paper_tracking, paper_scans.truth)
    yaw = np.array([paper_scans.truth[i][2] for i, _ in paper_tracking])
    ahead = np.cos(yaw) * e[:, 0] + np.sin(yaw) * e[:, 1]
    left = -np.sin(yaw) * e[:, 0] + np.cos(yaw) * e[:, 1]
    assert abs(float(ahead.mean())) < 0.003 and abs(float(left.mean())) < 0.003, (ahead.mean(), left.mean())
    assert float(np.sqrt(np.mean(ahead**2 + left**2))) < 0.012


def test_wall_surface_field_crosses_zero_on_the_face():
    walls = np.zeros((20, 20), dtype=bool)
    walls[:, 8:12] = True  # a wall 4 cells thick
    f = wall_surface_field(walls, 0.05, 2.0)
    row = f[10]
    assert row[7] == pytest.approx(0.025) and row[8] == pytest.approx(-0.025)  # zero midway: on the face
    assert row[9] == pytest.approx(-0.075) and row[6] == pytest.approx(0.075)  # not flat inside the wall
    assert wall_surface_field(walls, 0.05, 2.0, 0.025)[10, 8] == pytest.approx(0.0)  # surface on the centres


def test_refined_fix_is_where_the_beams_end():
    """A scan ray-cast on the grid ends on the wall cells' faces: refined from 5 cm off on a field whose
    surface is on the faces, the fix lands on the pose within a millimetre; with the surface through the
    boundary cells' centres (half a cell deeper) it is pulled towards the walls the laser sees."""
    m = _box_map()
    pose = np.array([2.02, 2.51, 0.3])
    scan = _scan(m.raycast(pose[:2], -2.35 + 4.7 / 540 * np.arange(541) + pose[2], 30.0))
    err = {}
    for depth_cells in (0.0, 0.5):
        a = AMCL(m, None, surface_depth_cells=depth_cells, laser_max_beams=541)
        pts, _ = a.pre(scan)
        fix, refined = a._refine(pose + np.array([0.04, -0.03, 0.01]), np.diag([1e-3, 1e-3, 1e-3]), pts, 30.0)
        assert refined
        err[depth_cells] = (float(np.hypot(*(fix[:2] - pose[:2]))), abs(float(wrap_angle(fix[2] - pose[2]))))
    assert err[0.0][0] < 0.001 and err[0.0][1] < 0.001, err
    assert err[0.5][0] > 0.005, err


def test_auto_surface_depth_learns_where_the_beams_end():
    """Scans ray-cast on the grid end on the wall cells' faces: from half a cell, the learnt surface depth
    goes to the faces and the refined fix onto the pose."""
    m = _box_map()
    a = AMCL(m, None, laser_max_beams=541)
    assert a.auto_depth and a.depth_m == pytest.approx(0.025)
    rng = np.random.default_rng(0)
    n_refined = 0
    for _ in range(60):
        pose = np.array([rng.uniform(1.5, 2.5), rng.uniform(1.0, 4.0), rng.uniform(-np.pi, np.pi)])
        scan = _scan(m.raycast(pose[:2], -2.35 + 4.7 / 540 * np.arange(541) + pose[2], 30.0))
        pts, _ = a.pre(scan)
        fix, refined = a._refine(pose + np.array([0.02, -0.02, 0.01]), np.diag([1e-3, 1e-3, 1e-3]), pts, 30.0)
        n_refined += refined
    assert n_refined >= 55 and a.depth_m < 0.003, (n_refined, a.depth_m)  # measured 59, 0.0004 m
    assert np.hypot(*(fix[:2] - pose[:2])) < 0.002


def _box_moved(shift_cells: int) -> OccupancyMap:
    """:func:`_box_map` with its inner box moved ``shift_cells`` cells along x."""
    g = np.zeros((100, 140), dtype=np.int16)
    g[0, :] = g[-1, :] = 100
    g[:, 0] = g[:, -1] = 100
    g[30:45, 60 + shift_cells:70 + shift_cells] = 100
    return OccupancyMap(g, 0.05)


def test_measured_refine_scale_ignores_moved_furniture():
    """The box moved 0.15 m since the map was made: its beams end 0.15 m (3 sigma_hit) from the map's
    surface and still pull a fit with sigma_hit; refitted with the sigma the scan's inliers show, the
    fix lands on the pose (the walls decide)."""
    m, world = _box_moved(0), _box_moved(3)
    for pose in (np.array([2.02, 3.31, -0.3]), np.array([1.5, 1.8, 0.1]), np.array([4.6, 1.2, 2.8])):
        scan = _scan(world.raycast(pose[:2], -2.35 + 4.7 / 540 * np.arange(541) + pose[2], 30.0))
        err = {}
        for scale in ("sigma_hit", "measured"):
            a = AMCL(m, None, surface_depth_cells=0.0, laser_max_beams=541, refine_scale=scale)
            pts, _ = a.pre(scan)
            fix, refined = a._refine(pose + np.array([0.02, -0.02, 0.01]), np.diag([1e-3, 1e-3, 1e-3]), pts, 30.0)
            assert refined
            err[scale] = float(np.hypot(*(fix[:2] - pose[:2])))
        assert err["measured"] < 0.001 and err["sigma_hit"] > 0.005, err  # 0.2 / 0.05 / 0.2 mm against 7 / 72 / 87 mm


def test_measured_refine_scale_keeps_nav2_model_as_is():
    """nav2's likelihood_field (sum pz^3) is no likelihood: no EM on its sigma, the fit is sigma_hit's."""
    m, world = _box_moved(0), _box_moved(3)
    pose = np.array([1.5, 1.8, 0.1])
    scan = _scan(world.raycast(pose[:2], -2.35 + 4.7 / 540 * np.arange(541) + pose[2], 30.0))
    fixes = []
    for scale in ("sigma_hit", "measured"):
        a = AMCL(m, None, surface_depth_cells=0.0, laser_max_beams=541, refine_scale=scale,
                 laser_model_type="likelihood_field")
        pts, _ = a.pre(scan)
        fixes.append(a._refine(pose + np.array([0.02, -0.02, 0.01]), np.diag([1e-3, 1e-3, 1e-3]), pts, 30.0)[0])
    assert np.array_equal(fixes[0], fixes[1])
