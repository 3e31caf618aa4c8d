import numpy as np
import pytest

from fgloc.geometry import (
    between,
    compose,
    from_matrix,
    interpolate_poses,
    inverse,
    mahalanobis2_2x2,
    mahalanobis2_3x3,
    quaternion_to_yaw,
    to_matrix,
    transform_points,
    wrap_angle,
    wrap_scalar,
    yaw_to_quaternion,
)


def test_wrap_angle_range_and_values():
    a = np.linspace(-20, 20, 1001)
    w = wrap_angle(a)
    assert np.all(w >= -np.pi) and np.all(w < np.pi)
    assert np.allclose(np.cos(w), np.cos(a)) and np.allclose(np.sin(w), np.sin(a))
    assert wrap_angle(np.pi) == pytest.approx(-np.pi)
    assert wrap_angle(3 * np.pi / 2) == pytest.approx(-np.pi / 2)


def test_compose_matches_matrices():
    rng = np.random.default_rng(1)
    for _ in range(50):
        a = rng.uniform(-5, 5, 3)
        b = rng.uniform(-5, 5, 3)
        c = compose(a, b)
        m = to_matrix(a) @ to_matrix(b)
        assert np.allclose(c, from_matrix(m) * [1, 1, 1], atol=1e-12) or np.allclose(
            c[:2], from_matrix(m)[:2]
        )
        assert np.isclose(np.cos(c[2]), m[0, 0]) and np.isclose(np.sin(c[2]), m[1, 0])


def test_inverse_and_between():
    rng = np.random.default_rng(2)
    a = rng.uniform(-5, 5, (20, 3))
    b = rng.uniform(-5, 5, (20, 3))
    ident = compose(a, inverse(a))
    assert np.allclose(ident, 0, atol=1e-12)
    assert np.allclose(compose(a, between(a, b))[:, :2], b[:, :2])
    assert np.allclose(wrap_angle(compose(a, between(a, b))[:, 2] - b[:, 2]), 0, atol=1e-12)


def test_transform_points_known():
    pts = transform_points([1.0, 2.0, np.pi / 2], [[1.0, 0.0], [0.0, 1.0]])
    assert np.allclose(pts, [[1.0, 3.0], [0.0, 2.0]])


def test_quaternion_roundtrip():
    yaw = np.linspace(-3.1, 3.1, 17)
    q = yaw_to_quaternion(yaw)
    assert np.allclose(np.linalg.norm(q, axis=1), 1)
    assert np.allclose(quaternion_to_yaw(q[:, 0], q[:, 1], q[:, 2], q[:, 3]), yaw)


def test_interpolate_across_wrap():
    stamps = np.array([0.0, 1.0])
    poses = np.array([[0.0, 0.0, np.deg2rad(170)], [2.0, 0.0, np.deg2rad(-170)]])
    p = interpolate_poses(stamps, poses, [0.5, -1.0, 5.0])
    assert np.allclose(p[0, :2], [1.0, 0.0])
    assert abs(wrap_angle(p[0, 2] - np.pi)) < 1e-9  # through 180 deg, not through 0
    assert np.allclose(p[1], poses[0]) and np.allclose(p[2], poses[1])


def test_scalar_variants_give_the_array_versions_bits():
    """The scalar variants for hot paths (inverse1, between_values / between1, compose_values / compose1,
    exp_values) are the
    array functions' operations in the same order: the same numbers (bit for bit here, where
    numpy's and libm's cos / sin agree; to 1e-12 at worst)."""
    from fgloc.geometry import between1, between_values, compose1, compose_values, exp, exp_values, inverse1

    rng = np.random.default_rng(3)
    for _ in range(200):
        a = np.array([*rng.uniform(-50, 50, 2), rng.uniform(-np.pi, np.pi)])
        b = np.array([*rng.uniform(-50, 50, 2), rng.uniform(-np.pi, np.pi)])
        assert np.allclose(inverse1(a), inverse(a), atol=1e-12, rtol=0)
        assert np.allclose(between_values(a, b), between(a, b), atol=1e-12, rtol=0)
        assert np.array_equal(between1(a, b), np.array(between_values(a, b)))
        assert np.array_equal(compose1(a, b), np.array(compose_values(a, b)))
        assert np.allclose(compose_values(a, b), compose(a, b), atol=1e-12, rtol=0)
        tw, dt = rng.uniform(-2, 2, 3), float(rng.uniform(0.001, 0.5))
        assert np.array_equal(np.array(exp_values(tw, dt)), exp(tw * dt))


def test_with_rotation_keeps_the_arc_and_replaces_the_turn():
    """with_rotation: the increment of the same constant twist with another rotation and a scaled
    speed (a skid steer's wheels report twice the gyro's turn)."""
    from fgloc.geometry import exp, log, with_rotation

    d = exp(np.array([1.0, 0.1, 0.6]))
    out = with_rotation(d, 0.3, speed_gain=0.5)
    assert np.allclose(log(out), [0.5, 0.05, 0.3], atol=1e-12)
    assert np.allclose(with_rotation(d, 0.6), d, atol=1e-12)


def test_mahalanobis_2x2_is_the_solved_one_and_inf_when_singular():
    rng = np.random.default_rng(3)
    for _ in range(200):
        a = rng.normal(size=(2, 2))
        S = a @ a.T + np.diag(rng.uniform(1e-6, 1.0, 2))
        e = rng.normal(size=2)
        want = float(e @ np.linalg.solve(S, e))
        assert mahalanobis2_2x2(e[0], e[1], S[0, 0], S[0, 1], S[1, 0], S[1, 1]) == pytest.approx(want, rel=1e-9)
    assert mahalanobis2_2x2(1.0, 0.0, 1.0, 1.0, 1.0, 1.0) == np.inf      # singular
    assert mahalanobis2_2x2(1.0, 0.0, np.nan, 0.0, 0.0, 1.0) == np.inf   # not finite
    assert mahalanobis2_2x2(1.0, 0.0, -1.0, 0.0, 0.0, 1.0) == np.inf     # indefinite: negative


def test_wrap_scalar_is_wrap_angle_bit_for_bit():
    rng = np.random.default_rng(5)
    vals = np.concatenate([rng.normal(0.0, 10.0, 20000), rng.uniform(-1e17, 1e17, 2000),
                           np.arange(-40, 41) * np.pi / 2,
                           [0.0, -0.0, np.pi, -np.pi, 1e300, -1e300, 5e-324, -5e-324,
                            np.nextafter(np.pi, 0.0), np.nextafter(-np.pi, 0.0)]])
    want = wrap_angle(vals)
    got = np.array([wrap_scalar(float(v)) for v in vals])
    assert np.array_equal(got.view(np.int64), want.view(np.int64))
    with np.errstate(invalid="ignore"):
        assert np.isnan(wrap_angle(np.inf))
    assert np.isnan(wrap_scalar(np.inf)) and np.isnan(wrap_scalar(-np.inf)) and np.isnan(wrap_scalar(np.nan))


def test_mahalanobis_3x3_is_the_solved_one_and_inf_when_singular():
    rng = np.random.default_rng(4)
    for _ in range(200):
        a = rng.normal(size=(3, 3))
        S = a @ a.T + np.diag(rng.uniform(1e-6, 1.0, 3))
        e = rng.normal(size=3)
        want = float(e @ np.linalg.solve(S, e))
        assert mahalanobis2_3x3(e[0], e[1], e[2], S.reshape(9).tolist()) == pytest.approx(want, rel=1e-9)
    assert mahalanobis2_3x3(1.0, 0.0, 0.0, [1.0, 1.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 1.0]) == np.inf  # singular
    assert mahalanobis2_3x3(1.0, 0.0, 0.0, [np.nan, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]) == np.inf  # not finite
