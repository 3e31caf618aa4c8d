"""Per-source inputs: IMU mounts (hand-computed), bad input counted, default layout unchanged."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fgloc.errors import ConfigError
from fgloc.localization.sources import SourceRouter, parse_sources
from fgloc.types import CompassHeading, Imu, Odometry, PoseFix, StaticTransform, Transform3D


class _Backend:
    capabilities: frozenset = frozenset()
    initialized = True
    encoder_sigmas = (0.01, 0.01, 0.02)
    stats: dict = {}

    def __init__(self):
        self.keyframes = []

    def predict(self, t):
        return np.zeros(3), np.eye(3) * 0.01

    def add_keyframe(self, t, fix):
        self.keyframes.append(fix)
        return True

    def source_health(self):
        return {}

    def source_noise(self, name):
        return None


class _Loc:
    """Records what the router hands the localizer."""

    odom_mode = False
    frontend = None

    def __init__(self):
        self.compass: list[CompassHeading] = []
        self.odometry: list[Odometry] = []
        self.backend = _Backend()
        self.stats: dict = {}

    def on_compass(self, m):
        self.compass.append(m)

    def compass_values(self, t, yaw, yaw_var, rate, rate_var):
        self.compass.append(CompassHeading(t, yaw, rate, yaw_var, rate_var))

    def on_odometry(self, m):
        self.odometry.append(m)

    def odometry_values(self, t, tw, cov, pose, cov_finite=None):
        self.odometry.append(Odometry(t, tw, cov, pose))


def _mount(rpy_deg):
    r = Rotation.from_euler("xyz", np.deg2rad(rpy_deg))
    R = r.as_matrix()
    return Transform3D("base_link", "imu_link", np.array([0.1, 0.0, math.atan2(R[1, 0], R[0, 0])]), z=0.2,
                       rotation_xyzw=r.as_quat())


def _router(specs=None):
    loc = _Loc()
    return loc, SourceRouter(loc, parse_sources(specs))


@pytest.mark.parametrize("rpy,axis,sign", [((0, 0, 90), 2, 1.0), ((90, 0, 0), 1, 1.0), ((180, 0, 0), 2, -1.0)])
def test_imu_mounts_rotate_orientation_and_rate_into_base_link(rpy, axis, sign):
    loc, router = _router()
    router.on_tf([StaticTransform("base_link", "laser", np.zeros(3)), _mount(rpy)])
    base_yaw, w = 0.7, 0.3
    R_wb = Rotation.from_euler("z", base_yaw).as_matrix()
    R_bi = Rotation.from_euler("xyz", np.deg2rad(rpy)).as_matrix()
    q = Rotation.from_matrix(R_wb @ R_bi).as_quat()
    # hand computed: the base's yaw rate [0, 0, w] in the IMU's axes is R_bi^T [0, 0, w]:
    # yawed 90 deg -> z; turned 90 deg about x -> +y; upside down -> -z
    w_imu = np.zeros(3)
    w_imu[axis] = sign * w
    assert np.allclose(R_bi.T @ [0, 0, w], w_imu, atol=1e-12)
    cov = np.diag([1e-4, 2e-4, 3e-4])  # the IMU frame's: the base's yaw variance is the axis that maps to z
    msg = Imu(1.0, q, w_imu, cov, cov, frame_id="imu_link")
    router.on_message(router.specs[1], msg)
    (c,) = loc.compass
    assert c.yaw_rad == pytest.approx(base_yaw, abs=1e-9)
    assert c.yaw_rate_radps == pytest.approx(w, abs=1e-12)
    assert c.yaw_rate_var == pytest.approx(cov[axis, axis])


def test_a_reader_that_gives_only_yaw_still_undoes_a_yawed_mount():
    loc, router = _router()
    router.on_tf([_mount((0, 0, 90))])
    router.on_message(router.specs[1], CompassHeading(1.0, 0.7 + math.pi / 2, 0.3, 1e-4, 1e-6, frame_id="imu_link"))
    assert loc.compass[0].yaw_rad == pytest.approx(0.7) and loc.compass[0].yaw_rate_radps == pytest.approx(0.3)
    loc2, router2 = _router()
    router2.on_tf([_mount((90, 0, 0))])
    router2.on_message(router2.specs[1], CompassHeading(1.0, 0.7, 0.0, 1e-4, 1e-6, frame_id="imu_link"))
    assert loc2.compass[0].yaw_rate_radps is None  # z of a tilted IMU is not the yaw rate: dropped, said why
    assert any("tilted" in r for r in router2.state["imu"].health.skipped_reasons)


def test_bad_input_is_counted_and_skipped_never_raised():
    specs = {"wheels": {"type": "odometry", "topic": "/odom"},
             "imu": {"type": "imu", "topic": "/imu"},
             "mocap": {"type": "pose", "topic": "/pose", "frame_id": "map", "covariance": "fixed",
                       "sigmas": [0.01, 0.01, 0.01]}}
    loc, router = _router(specs)
    imu, odom, pose = (next(s for s in router.specs if s.name == n) for n in ("imu", "wheels", "mocap"))
    good_q = np.array([0.0, 0.0, 0.0, 1.0])
    router.on_message(imu, Imu(1.0, np.zeros(4), None))                           # all-zero quaternion
    router.on_message(imu, Imu(2.0, good_q * 1.5, None))                          # not unit length
    router.on_message(imu, Imu(3.0, good_q, None, np.diag([np.nan, 1.0, 1.0])))   # NaN covariance
    router.on_message(imu, Imu(4.0, None, np.zeros(3), None, np.diag([1.0, -1.0, 1.0])))  # negative
    router.on_message(odom, Odometry(1.0, np.zeros(3), np.diag([np.nan, 1.0, 1.0])))
    router.on_message(pose, PoseFix(1.0, np.zeros(3), np.eye(3) * 0.01, frame_id="odom"))  # another frame
    router.on_message(pose, PoseFix(2.0, np.zeros(3), np.eye(3) * 0.01, frame_id="map"))   # fine
    h = router.health()
    assert loc.compass == [] and loc.odometry == []
    reasons = h["imu"].skipped_reasons
    assert reasons["imu: orientation quaternion all zeros / not finite"] == 1
    assert reasons["imu: orientation quaternion not unit length"] == 1
    assert reasons["imu: orientation covariance with a NaN/inf diagonal"] == 1
    assert reasons["imu: angular velocity covariance with a negative diagonal"] == 1
    assert h["wheels"].skipped_reasons == {"covariance with a NaN or negative diagonal": 1}
    assert h["mocap"].skipped_reasons == {"pose in frame 'odom', not 'map'": 1} and h["mocap"].accepted == 1
    assert len(loc.backend.keyframes) == 1


def test_source_config_errors_are_one_line_naming_the_key():
    with pytest.raises(ConfigError, match=r"sources.inputs.imu0.use: 'vz' is not one of"):
        parse_sources({"imu0": {"type": "imu", "use": ["yaw", "vz"]}})
    with pytest.raises(ConfigError, match=r"sources.inputs.odom0.type"):
        parse_sources({"odom0": {"type": "wheel"}})
    with pytest.raises(ConfigError, match=r"sigmas: fixed needs one sigma per used component"):
        parse_sources({"odom0": {"type": "odometry", "covariance": "fixed", "sigmas": [0.1]}})
    default = parse_sources(None, {"odom": "/wheel_odom"})
    assert [(s.name, s.topic, s.use) for s in default] == [("odom", "/wheel_odom", ("vx", "vy", "vyaw")),
                                                            ("imu", "/imu", ("yaw", "vyaw", "roll", "pitch"))]


def test_default_layout_reproduces_direct_feeding_exactly():
    from fgloc.localization import Localizer, Session
    from fgloc.sim import simulate_paper

    sim = simulate_paper(seed=1, route=[[2.5, 3.0], [10.0, 3.0]])
    direct = Localizer(sim.map, sim.laser_mount, backend="ekf", initial_pose=sim.ground_truth.poses[0])
    for topic, m in sim.messages:
        if topic == "/odom":
            direct.on_odometry(m)
        elif topic == "/imu":
            direct.on_compass(m)
        elif topic == "/scan":
            direct.on_scan(m)
    a = direct.finish()
    loc = Localizer(sim.map, sim.laser_mount, backend="ekf", initial_pose=sim.ground_truth.poses[0])
    b = Session(loc).run(sim.messages)
    assert np.array_equal(a.stamps, b.stamps) and np.array_equal(a.poses, b.poses)
    h = loc.stats["sources"]
    assert h["odom"].accepted == len(sim.topic("/odom")) and h["imu"].accepted == len(sim.topic("/imu"))


def test_summary_lines_name_the_motion_model_and_each_source():
    from fgloc.backends.ekf import EKFConfig
    from fgloc.backends.ekf_backend import EKFBackend
    from fgloc.localization.sources import summary_lines
    from fgloc.localization.sources.report import SourceReport, StreamNoise
    from fgloc.localization.stats import RunStats

    ekf = EKFBackend(EKFConfig())
    assert ekf.motion_summary().startswith("differential")
    ekf.initialize(0.0, np.zeros(3))
    ekf.add_odometry(0.1, np.array([0.5, 0.3, 0.0]), None)  # lateral velocity: a mecanum base
    assert ekf.motion_summary().startswith("omni") and "lateral velocity" in ekf.motion_summary()
    stats = RunStats(motion_model=ekf.motion_summary(), sources={
        "odom": SourceReport("odometry", topic="/odom", use=["vx", "vyaw"], accepted=10, skipped=2,
                             yaw_rate_scale=2.31, noise={"noise": StreamNoise(1.0, shown_vs_claimed=4.0)}),
        "imu": SourceReport("imu", topic="/imu", use=["yaw"], accepted=7, gyro_bias_radps=0.002,
                            stream_gated={"gyro": 3}),
        "scan": SourceReport("pose", accepted=5, gated=1, latency_s=0.035)})
    lines = summary_lines(stats)
    assert lines[0].startswith("motion model: omni")
    assert lines[1] == ("odom (odometry /odom: vx vyaw): 10 accepted, 2 skipped; yaw-rate scale 2.310 "
                        "(reported / true); yaw noise 4.00x claimed")
    assert lines[2] == "imu (imu /imu: yaw): 7 accepted, 3 gated; gyro bias 0.00200 rad/s"
    assert lines[3] == "scan: 5 accepted, 1 gated; latency 35.0 ms"


def test_messages_dispatched_by_kind_go_through_the_first_source():
    from fgloc.localization import Localizer, Session
    from fgloc.sim import simulate_paper

    sim = simulate_paper(seed=1, route=[[2.5, 3.0], [6.0, 3.0]])
    loc = Localizer(sim.map, sim.laser_mount, backend="ekf", initial_pose=sim.ground_truth.poses[0])
    session = Session(loc)
    for topic, m in sim.messages:
        session.dispatch({"/odom": "odom", "/imu": "imu", "/scan": "scan"}.get(topic, ""), m)
    t_end = sim.topic("/imu")[-1].stamp + 0.01
    session.dispatch("imu", CompassHeading(t_end, 0.1, 0.0, -1.0, 1e-4))  # negative yaw variance: rate used
    session.finish()
    h = loc.stats["sources"]
    assert h["odom"].accepted == len(sim.topic("/odom")) and h["imu"].accepted == len(sim.topic("/imu")) + 1
    assert h["imu"].skipped == 1 and loc.stats["skipped_reasons"] == {
        "imu: imu: orientation covariance with a NaN or negative diagonal": 1}


def test_differential_odometry_takes_the_velocity_of_an_axis_it_fuses_as_a_velocity():
    # robot_localization's ekf.yaml odom0: x, y (converted to increments) and vyaw
    loc, router = _router({"odom0": {"type": "odometry", "use": ["x", "y", "vyaw"], "differential": True}})
    spec = router.specs[0]
    c = np.diag([0.01, 0.01, 0.04])
    router.on_message(spec, Odometry(1.0, np.array([0.5, 0.0, 9.9]), c, np.array([0.0, 0.0, 0.0]), c * 0.01))
    router.on_message(spec, Odometry(1.5, np.array([0.5, 0.0, 0.2]), c, np.array([0.25, 0.0, 0.0]), c * 0.01))
    (m,) = loc.odometry  # the first message only starts the increments
    assert m.twist[0] == pytest.approx(0.5) and m.twist[2] == pytest.approx(0.2)  # x: poses (no turn), w: twist
    # robot_localization's covariance of the increments: the two poses' summed, times dt
    assert m.twist_cov[2, 2] == pytest.approx(0.04) and m.twist_cov[0, 0] == pytest.approx((1e-4 + 1e-4) * 0.5)


def test_differential_covariance_is_robot_localizations_in_the_earlier_pose_frame():
    """(C_prev + C) dt with the xy block turned into the earlier pose's body frame (hand computed:
    heading 90 deg swaps x and y); the yaw variance is not turned."""
    loc, router = _router({"odom0": {"type": "odometry", "use": ["x", "y", "yaw"], "differential": True}})
    spec = router.specs[0]
    c1, c2 = np.diag([1e-4, 4e-4, 1e-5]), np.diag([2e-4, 6e-4, 3e-5])
    router.on_message(spec, Odometry(1.0, np.zeros(3), None, np.array([0.0, 0.0, math.pi / 2]), c1))
    router.on_message(spec, Odometry(1.1, np.zeros(3), None, np.array([0.0, 0.1, math.pi / 2]), c2))
    (m,) = loc.odometry
    assert m.twist == pytest.approx([1.0, 0.0, 0.0], abs=1e-12)  # 0.1 m along the heading in 0.1 s
    np.testing.assert_allclose(np.diag(m.twist_cov), [(4e-4 + 6e-4) * 0.1, (1e-4 + 2e-4) * 0.1, 4e-5 * 0.1])


def test_an_implausible_tilt_keeps_the_base_z_rate():
    """A mount that makes the base upside down (a left-handed IMU made 'consistently incorrect' with
    roll 180 deg, r_l's groovy test1.bag): the odometry is not levelled, and the yaw rate is the
    base's own z rate R_bi w (here -w_z), not the heading rate of an upside-down body (+w_z)."""
    loc, router = _router({"wheels": {"type": "odometry", "topic": "/odom", "use": ["vx", "vyaw"]},
                           "imu0": {"type": "imu", "topic": "/imu", "use": ["vyaw", "roll", "pitch"]}})
    router.on_tf([_mount((180, 0, 0))])
    specs = {s.name: s for s in router.specs}
    q = Rotation.from_euler("z", 0.4).as_quat()  # the sensor upright in its world: the base upside down
    router.on_message(specs["imu0"], Imu(1.0, q, np.array([0.0, 0.0, 0.25]), np.eye(3) * 1e-4, np.eye(3) * 1e-6,
                                         frame_id="imu_link"))
    router.on_message(specs["wheels"], Odometry(1.01, np.array([1.0, 0.0, -0.25]), np.diag([1e-4, 1e-4, 4e-4])))
    assert loc.compass[0].yaw_rate_radps == pytest.approx(-0.25)
    np.testing.assert_allclose(loc.odometry[0].twist, [1.0, 0.0, -0.25])
    assert router.health()["wheels"].tilt_implausible == 1


def test_faults_of_a_field_the_source_does_not_use_are_not_counted():
    """A gyro-only source (vyaw): a zero quaternion is no fault of its; a source using yaw counts it."""
    for use, skipped in ((["vyaw"], 0), (["yaw", "vyaw"], 1)):
        loc, router = _router({"imu0": {"type": "imu", "topic": "/imu", "use": use}})
        router.on_message(router.specs[0], Imu(1.0, np.zeros(4), np.array([0.0, 0.0, 0.1]), None, np.eye(3) * 1e-6))
        assert router.health()["imu0"].skipped == skipped
        assert loc.compass[0].yaw_rate_radps == pytest.approx(0.1) and loc.compass[0].yaw_rad is None


def test_imu_roll_pitch_level_the_odometry_and_give_the_heading_rate():
    """An IMU fusing roll and pitch (r_l's imuN_config in 3-D) levels the odometry: the body
    velocity projected onto the ground plane (hand-computed: roll 5 deg, pitch 10 deg, twist
    vx 1, vy 0.2 -> [cos p + 0.2 sin r sin p, 0.2 cos r]); its yaw rate is the heading's rate
    (sin r w_y + cos r w_z) / cos p; without roll / pitch in use nothing changes."""
    r, p = math.radians(5.0), math.radians(10.0)
    q = Rotation.from_euler("ZYX", [0.3, p, r]).as_quat()
    w = np.array([0.0, 0.05, 0.2])
    for use, levelled in ((["yaw", "vyaw", "roll", "pitch"], True), (["yaw", "vyaw"], False)):
        loc, router = _router({"wheels": {"type": "odometry", "topic": "/odom", "use": ["vx", "vy", "vyaw"]},
                               "imu0": {"type": "imu", "topic": "/imu", "use": use}})
        specs = {s.name: s for s in router.specs}
        router.on_message(specs["imu0"], Imu(1.0, q, w, np.eye(3) * 1e-4, np.eye(3) * 1e-6, frame_id="base_link"))
        router.on_message(specs["wheels"], Odometry(1.02, np.array([1.0, 0.2, 0.1]), np.diag([1e-4, 1e-4, 4e-4])))
        router.on_message(specs["wheels"], Odometry(1.7, np.array([1.0, 0.2, 0.1]), np.diag([1e-4, 1e-4, 4e-4])))
        tw = loc.odometry[0].twist
        rate = loc.compass[0].yaw_rate_radps
        if levelled:
            assert tw[0] == pytest.approx(math.cos(p) + 0.2 * math.sin(r) * math.sin(p), abs=1e-12)
            assert tw[1] == pytest.approx(0.2 * math.cos(r), abs=1e-12)
            assert rate == pytest.approx((math.sin(r) * 0.05 + math.cos(r) * 0.2) / math.cos(p), abs=1e-12)
            var_x = 1e-4 * (math.cos(p) ** 2 + (math.sin(r) * math.sin(p)) ** 2)
            assert loc.odometry[0].twist_cov[0, 0] == pytest.approx(var_x)
            h = router.health()["wheels"]
            assert h.levelled == 1 and h.tilt_max_deg == pytest.approx(10.0, abs=1e-6)
            np.testing.assert_allclose(loc.odometry[1].twist, [1.0, 0.2, 0.1])  # 0.68 s later: too old to level
        else:
            np.testing.assert_allclose(tw, [1.0, 0.2, 0.1])
            assert rate == pytest.approx(0.2)
    with pytest.raises(ConfigError, match="roll and pitch"):
        parse_sources({"imu0": {"type": "imu", "use": ["yaw", "roll"]}})
    with pytest.raises(ConfigError, match="is not one of"):
        parse_sources({"o": {"type": "odometry", "use": ["vx", "pitch"]}})


def test_a_differential_source_out_of_order_skips_the_message_not_the_increment():
    """A message stamped before the previous one (r_l's groovy test1.bag: 378 of /my_odometry2imu's)
    is counted and skipped; the next increment spans from the newest message, so the whole turn
    arrives (it reset the reference and lost the increment before: hand computed 0.3 rad)."""
    loc, router = _router({"imu0": {"type": "imu", "topic": "/imu", "use": ["yaw"], "differential": True}})
    spec = router.specs[0]
    for t, yaw in ((1.0, 0.0), (1.1, 0.1), (1.05, 0.05), (1.2, 0.2), (1.3, 0.3)):
        router.on_message(spec, Imu(t, Rotation.from_euler("z", yaw).as_quat(), None, np.eye(3) * 1e-4))
    rates = [(c.stamp, c.yaw_rate_radps) for c in loc.compass if c.yaw_rate_radps is not None]
    assert [t for t, _ in rates] == [1.1, 1.2, 1.3]
    assert sum(r * 0.1 for _, r in rates) == pytest.approx(0.3)
    assert router.health()["imu0"].skipped_reasons == {
        "imu: differential: stamp not after the previous message's (out of order)": 1}
    loc, router = _router({"odom0": {"type": "odometry", "use": ["x", "y"], "differential": True}})
    for t, x in ((1.0, 0.0), (1.1, 0.1), (1.05, 0.05), (1.2, 0.2)):
        router.on_message(router.specs[0], Odometry(t, np.zeros(3), None, np.array([x, 0.0, 0.0]), np.eye(3) * 1e-4))
    assert [m.twist[0] for m in loc.odometry] == pytest.approx([1.0, 1.0])


def test_an_imu_mounted_through_a_chain_of_transforms():
    """base_link -> imu_plate (yawed 90 deg) -> imu_link (turned 90 deg about x), as a URDF's
    robot_state_publisher gives it: the composed rotation turns the IMU into base_link
    (hand computed: R_bi = Rz(90) Rx(90) maps the base's z rate onto the IMU's +y)."""
    loc, router = _router()
    plate = Rotation.from_euler("z", 90, degrees=True)
    imu = Rotation.from_euler("x", 90, degrees=True)
    router.on_tf([Transform3D("base_link", "imu_plate", np.array([0.1, 0.0, math.pi / 2]), 0.1, plate.as_quat()),
                  Transform3D("/imu_plate", "/imu_link", np.zeros(3), 0.05, imu.as_quat())])
    R_bi = (plate * imu).as_matrix()
    assert np.allclose(R_bi.T @ [0, 0, 1], [0, 1, 0], atol=1e-12)
    base_yaw, w = -0.4, 0.3
    q = Rotation.from_matrix(Rotation.from_euler("z", base_yaw).as_matrix() @ R_bi).as_quat()
    router.on_message(router.specs[1], Imu(1.0, q, np.array([0.0, w, 0.0]), np.eye(3) * 1e-4, np.eye(3) * 1e-6,
                                           frame_id="imu_link"))
    (c,) = loc.compass
    assert c.yaw_rad == pytest.approx(base_yaw, abs=1e-9) and c.yaw_rate_radps == pytest.approx(w, abs=1e-12)
    assert router.health()["imu"].mount is None  # found: no 'no transform: identity'


def test_a_pose_sources_gate_judges_against_a_fresh_marginal():
    """A pose source's Mahalanobis gate compares the pose with the prediction's covariance; the
    smoother's marginal is computed only when asked, so without an output asking the gate judged
    against the start prior (1 m here): a pose 0.3 m off passed after 3 s of 1 cm poses standing
    still.  It is gated now."""
    from fgloc.backends.smoother import SlidingWindowSmoother

    specs = {"mocap": {"type": "pose", "topic": "/pose", "frame_id": "map", "covariance": "fixed",
                       "sigmas": [0.01, 0.01, 0.01], "gate": 16.27}}
    loc, router = _router(specs)
    sm = SlidingWindowSmoother()
    sm.initialize(0.0, np.zeros(3), np.diag([1.0, 1.0, 0.1]))
    loc.backend = sm  # type: ignore[assignment]
    mocap = router.specs[0]
    for i in range(1, 31):
        t = i * 0.1
        for j in range(5):
            sm.add_odometry(t - 0.08 + 0.02 * j, np.zeros(3), None)
        router.on_message(mocap, PoseFix(t, np.zeros(3), np.eye(3), frame_id="map"))
    sm.add_odometry(3.1, np.zeros(3), None)
    router.on_message(mocap, PoseFix(3.1, np.array([0.3, 0.0, 0.0]), np.eye(3), frame_id="map"))
    h = router.health()["mocap"]
    assert h.accepted == 30 and h.gated == 1


@pytest.mark.parametrize("specs", [None, {"odom0": {"type": "odometry", "use": ["vx", "vy", "vyaw"]}}])
def test_each_unusable_twist_variance_gets_its_own_default(specs):
    """An AR.Drone's odometry: vx / vy variance 0.09, its placeholder yaw rate's 0: the back-end is
    handed 0.09 for vx / vy and the default (0.02 rad/s)^2 for the yaw rate; a driver's 1e6 "not
    estimated" is replaced the same way, its correlations dropped."""
    loc, router = _router(specs)
    spec = router.specs[0]
    drone = np.diag([0.09, 0.09, 0.0])
    router.on_message(spec, Odometry(1.0, np.array([0.4, 0.1, 0.0]), drone, None, None))
    placeholder = np.array([[0.09, 0.0, 0.5], [0.0, 1e6, 0.0], [0.5, 0.0, 0.04]])
    router.on_message(spec, Odometry(1.1, np.array([0.4, 0.1, 0.0]), placeholder, None, None))
    a, b = loc.odometry
    np.testing.assert_allclose(a.twist_cov, np.diag([0.09, 0.09, 0.02**2]), rtol=1e-12)
    np.testing.assert_allclose(b.twist_cov, [[0.09, 0.0, 0.5], [0.0, 0.01**2, 0.0], [0.5, 0.0, 0.04]], rtol=1e-12)
