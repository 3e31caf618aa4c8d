"""The back-end contract (fgloc.backends.contract): every shipped back-end implements what it
declares, a back-end that does not declare an input refuses it, and the estimates it reports are
the ones its methods give."""

from __future__ import annotations

import numpy as np
import pytest

from fgloc.backends import BACKENDS, make_backend
from fgloc.backends.contract import Backend, Capability, Estimates
from fgloc.types import Trajectory

INPUTS = {Capability.GYRO: "add_gyro", Capability.VELOCITY: "add_velocity",
          Capability.RELATIVE_YAW: "add_relative_yaw", Capability.ODOMETRY_CLOCK: "set_odometry_timing_unknown"}
ESTIMATES = {Capability.ODOM_SCALES: "odom_scales", Capability.GYRO_BIAS: "gyro_bias",
             Capability.LATENCY: "latency_estimate"}


@pytest.mark.parametrize("name", BACKENDS)
def test_every_declared_capability_is_implemented(name):
    be = make_backend(name)
    assert isinstance(be, Backend)
    for cap, method in {**INPUTS, **ESTIMATES}.items():
        own = getattr(type(be), method) is not getattr(Backend, method)
        assert own == (cap in be.capabilities), (name, cap)
    # one odometry model or the other: a velocity state, or increments on the odometry's clock
    assert (Capability.MEASURES_VELOCITY in be.capabilities) != (Capability.ODOMETRY_CLOCK in be.capabilities)


class _Minimal(Backend):
    """The least a back-end implements: no capability."""

    name = "minimal"

    def __init__(self) -> None:
        super().__init__()
        self.t: float | None = None
        self.pose = np.zeros(3)

    @property
    def initialized(self) -> bool:
        return self.t is not None

    @property
    def encoder_sigmas(self) -> tuple[float, float, float]:
        return (0.01, 0.01, 0.02)

    def initialize(self, t, pose, cov=None):
        self.t, self.pose = float(t), np.asarray(pose, dtype=float)

    def set_compass_offset(self, offset):
        pass

    def add_odometry(self, t, twist, twist_cov):
        pass

    def add_compass(self, t, yaw, yaw_var, rate, rate_var):
        pass

    def add_keyframe(self, t, fix):
        return False

    def predict(self, t):
        return self.pose, np.eye(3)

    def current(self, covariance=True):
        return None if self.t is None else (self.t, self.pose, np.eye(3))

    def finish(self):
        return Trajectory(np.zeros(0), np.zeros((0, 3)))


def test_a_backend_without_capabilities_refuses_their_inputs_and_reports_neutral_estimates():
    be = _Minimal()
    assert be.capabilities == frozenset()
    with pytest.raises(NotImplementedError, match="minimal back-end takes no gyro"):
        be.add_gyro(0.0, 0.1, 1e-4)
    with pytest.raises(NotImplementedError, match="further odometry"):
        be.add_velocity(0.0, np.zeros(3), np.eye(3), (True, True, True), "vo")
    with pytest.raises(NotImplementedError, match="differential orientation"):
        be.add_relative_yaw(0.0, 0.1, 1e-4)
    assert be.odom_scales().tolist() == [1.0, 1.0] and be.gyro_bias("imu") == 0.0 and be.latency_estimate() == 0.0
    assert be.estimates() == Estimates() and be.estimates().as_dict() == {}
    assert be.source_health() == {} and be.source_noise("odom") is None
    assert be.motion_summary(0.0).startswith("differential")


@pytest.mark.parametrize("name", ["ekf", "smoother"])
def test_estimates_are_what_the_methods_report(name):
    """Fed a turning robot with a biased gyro and a compass, the record gathers the methods' values
    (the gyro's bias under its source's name) and the health of each stream it saw."""
    be = make_backend(name)
    be.initialize(0.0, np.zeros(3), np.diag([1e-4, 1e-4, 1e-4]))
    for k in range(1, 301):
        t = k * 0.02
        be.add_odometry(t, np.array([0.5, 0.0, 0.3]), None)
        be.add_gyro(t, 0.3 + 0.01, 1e-6, "imu")
        if k % 5 == 0:
            be.add_compass(t, float(0.3 * t + 0.2), 1e-4, None, float("nan"))
            be.add_keyframe(t, None)
    est = be.estimates()
    assert est.gyro_bias_radps == {"imu": be.gyro_bias("imu")}
    assert (est.odom_speed_scale, est.odom_yaw_rate_scale) == tuple(be.odom_scales().tolist())
    assert est.latency_s == be.latency_estimate() == 0.0
    assert est.compass_offset_rad == be.compass_offset()
    assert {"odom", "imu.gyro"} <= set(be.source_health())
    assert be.source_health()["odom"].accepted == 300
    noise = be.source_noise("imu.gyro")
    assert noise is not None and noise.k_claimed >= 0.0
    assert be.source_noise("no such stream") is None


def test_backends_are_selected_by_capability():
    """The registry answers which back-ends have a capability; a name is checked against it (the
    live commands need Capability.LIVE: the batch smoother keeps every factor to the end)."""
    from fgloc.backends import REGISTRY, backend_names, check_backend
    from fgloc.errors import ConfigError

    assert backend_names() == BACKENDS == tuple(REGISTRY)
    assert backend_names(Capability.LIVE) == ("ekf", "smoother")
    assert backend_names(Capability.MEASURES_VELOCITY) == ("ekf",)
    assert check_backend(" Smoother ", Capability.LIVE) == "smoother"
    with pytest.raises(ConfigError, match=r"--backend batch: expected ekf or smoother"):
        check_backend("batch", Capability.LIVE)
    with pytest.raises(ConfigError, match=r"unknown back-end 'smother' \(choose ekf, smoother or batch\).*smoother"):
        check_backend("smother")
    for name, cls in REGISTRY.items():
        assert type(make_backend(name)) is cls and cls.name == name
