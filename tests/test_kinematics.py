import numpy as np
import pytest

from fgloc.errors import ConfigError
from fgloc.kinematics import (
    DiffDriveKinematics,
    MecanumKinematics,
    QuadratureEncoder,
    counts_to_twist,
    make_kinematics,
)


def test_mecanum_roundtrip_and_signs():
    k = MecanumKinematics(0.076, 0.25, 0.28)
    rng = np.random.default_rng(0)
    tw = rng.normal(0, 1, (100, 3))
    assert np.allclose(k.forward(k.inverse(tw)), tw)
    w = k.inverse([1.0, 0.0, 0.0])
    assert np.allclose(w, 1.0 / 0.076)  # pure forward: all wheels forward
    w = k.inverse([0.0, 1.0, 0.0])  # strafe left: FL and RR backwards
    assert w[0] < 0 and w[3] < 0 and w[1] > 0 and w[2] > 0


def test_diff_roundtrip():
    k = DiffDriveKinematics(0.08, 0.2)
    tw = np.array([[0.5, 0.0, 0.3], [-0.2, 0.0, -1.0]])
    assert np.allclose(k.forward(k.inverse(tw)), tw)
    assert k.inverse([0.0, 0.0, 1.0])[0] == pytest.approx(-0.2 / 0.08)


def test_encoder_quantization_bound():
    enc = QuadratureEncoder(500)
    assert enc.counts_per_rev == 2000
    ang = np.linspace(0, 50, 10001)
    err = ang - enc.counts_to_angle(enc.angle_to_counts(ang))
    assert err.min() >= 0 and err.max() < 2 * np.pi / 2000
    k = MecanumKinematics(0.076, 0.25, 0.28)
    tw = counts_to_twist(k, enc, enc.angle_to_counts(k.inverse([0.8, 0.0, 0.0]) * 0.02), 0.02)
    assert tw[0] == pytest.approx(0.8, abs=0.015)  # one count per wheel in 20 ms is ~0.012 m/s


def test_make_kinematics_errors():
    assert isinstance(make_kinematics({"drive": "diff", "wheel_radius_m": 0.1, "half_track_m": 0.2}),
                      DiffDriveKinematics)
    with pytest.raises(ConfigError, match="half_wheelbase_m"):
        make_kinematics({"drive": "mecanum", "wheel_radius_m": 0.1, "half_track_m": 0.2})
    with pytest.raises(ConfigError, match="unknown drive"):
        make_kinematics({"drive": "tank", "wheel_radius_m": 0.1, "half_track_m": 0.2})


def test_skid_steer_is_diff_drive_on_each_sides_mean():
    from fgloc.kinematics import SkidSteerKinematics

    k = make_kinematics({"drive": "skid", "wheel_radius_m": 0.165, "half_track_m": 0.28, "half_wheelbase_m": 0.26})
    assert isinstance(k, SkidSteerKinematics) and k.n_wheels == 4
    tw = np.array([[0.7, 0.0, 0.4], [-0.2, 0.0, -1.0]])
    assert np.allclose(k.forward(k.inverse(tw)), tw)
    w = k.inverse([0.0, 0.0, 1.0])  # turning left in place: left wheels back, right forward
    assert w[0] == w[2] == pytest.approx(-0.28 / 0.165) and w[1] == w[3] == pytest.approx(0.28 / 0.165)
