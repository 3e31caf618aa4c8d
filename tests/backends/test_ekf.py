"""The paper's EKF: eq. 3 Jacobian, predict and update against hand-computed values, gating, wrap."""

from __future__ import annotations

import numpy as np

from fgloc.backends.ekf import EKF, TH, EKFConfig, V, W, motion_jacobian, motion_model


def _numerical_jacobian(f, x, eps=1e-6):
    J = np.zeros((len(f(x)), len(x)))
    for i in range(len(x)):
        d = np.zeros(len(x))
        d[i] = eps
        a, b = f(x + d), f(x - d)
        diff = a - b
        diff[TH] = np.angle(np.exp(1j * diff[TH]))
        J[:, i] = diff / (2 * eps)
    return J


def test_eq3_jacobian_matches_paper_and_numerical():
    x = np.array([1.0, 2.0, 0.7, 0.8, 0.3])
    dt = 0.04
    F = motion_jacobian(x, dt)
    v, th = 0.8, 0.7
    expected = np.array([
        [1, 0, -v * dt * np.sin(th), dt * np.cos(th), 0],
        [0, 1, v * dt * np.cos(th), dt * np.sin(th), 0],
        [0, 0, 1, 0, dt],
        [0, 0, 0, 1, 0],
        [0, 0, 0, 0, 1],
    ])
    assert np.allclose(F, expected, atol=1e-15)
    assert np.allclose(F, _numerical_jacobian(lambda s: motion_model(s, dt), x), atol=1e-8)


def test_omni_jacobian_matches_numerical():
    x = np.array([1.0, -2.0, 2.9, 0.6, -0.3, 0.4])
    dt = 0.05
    J = _numerical_jacobian(lambda s: motion_model(s, dt, omni=True), x)
    assert np.allclose(motion_jacobian(x, dt, omni=True), J, atol=1e-8)


def test_predict_matches_hand_computation():
    ekf = EKF(EKFConfig(q_xy=0.01, q_theta=0.02, q_v=0.3, q_w=0.4))
    ekf.initialize(10.0, np.array([1.0, 2.0, 0.5]))
    ekf.x[V], ekf.x[W] = 0.8, 0.1
    ekf.P = np.diag([0.04, 0.09, 0.01, 0.25, 0.16])
    ekf.predict(10.1)
    # x = 1 + 0.8*0.1*cos(0.5) = 1.0702066; y = 2 + 0.08*sin(0.5) = 2.0383540; th = 0.51
    assert np.allclose(ekf.x, [1.0702066, 2.0383540, 0.51, 0.8, 0.1], atol=1e-7)
    # P_xx = 0.04 + (0.08 sin .5)^2 * 0.01 + (0.1 cos .5)^2 * 0.25 + 0.01*0.1
    s, c = np.sin(0.5), np.cos(0.5)
    pxx = 0.04 + (0.08 * s) ** 2 * 0.01 + (0.1 * c) ** 2 * 0.25 + 0.001
    pthth = 0.01 + 0.1**2 * 0.16 + 0.002
    pxth = (-0.08 * s) * 0.01 + 0.0  # F row x . P . F row th: -v dt sin * P_thth(1) ... + dt * P_thw (0)
    assert np.isclose(ekf.P[0, 0], pxx, atol=1e-12)
    assert np.isclose(ekf.P[2, 2], pthth, atol=1e-12)
    assert np.isclose(ekf.P[0, 2], pxth, atol=1e-12)
    assert np.isclose(ekf.P[3, 3], 0.25 + 0.03, atol=1e-12)


def test_map_update_matches_scalar_kalman():
    ekf = EKF(EKFConfig(gate_map=None, map_min_sigma_xy=0.0, map_min_sigma_theta_deg=0.0))
    ekf.initialize(0.0, np.array([1.0, 2.0, 0.3]))
    ekf.P = np.diag([0.04, 0.09, 0.01, 0.25, 0.16])
    z = np.array([1.2, 1.9, 0.35])
    R = np.diag([0.01, 0.01, 0.04])
    assert ekf.update_map(0.0, z, R)
    # diagonal P, H selects x, y, th: K_i = P_i / (P_i + R_i)
    kx, ky, kth = 0.04 / 0.05, 0.09 / 0.10, 0.01 / 0.05
    assert np.allclose(ekf.x[:3], [1.0 + kx * 0.2, 2.0 - ky * 0.1, 0.3 + kth * 0.05], atol=1e-12)
    assert np.allclose(np.diag(ekf.P)[:3], [0.04 * (1 - kx), 0.09 * (1 - ky), 0.01 * (1 - kth)], atol=1e-12)
    assert np.allclose(np.diag(ekf.P)[3:], [0.25, 0.16])


def test_encoder_and_compass_updates():
    ekf = EKF(EKFConfig(gate_compass=None))
    ekf.initialize(0.0, np.array([0.0, 0.0, 0.0]))
    ekf.P = np.diag([0.04, 0.04, 0.01, 1.0, 1.0])
    ekf.update_encoder(0.0, np.array([0.5, 0.0, 0.2]), np.diag([1.0, 1.0, 1.0]))
    assert np.allclose(ekf.x[[V, W]], [0.25, 0.1])  # K = 1/(1+1)
    ekf.update_compass(0.0, 0.1, 0.01, None)
    assert np.isclose(ekf.x[TH], 0.05)  # K = 0.01/(0.01+0.01)


def test_heading_innovation_is_wrapped():
    ekf = EKF(EKFConfig(gate_compass=None))
    ekf.initialize(0.0, np.array([0.0, 0.0, np.pi - 0.01]))
    ekf.P = np.diag([0.04, 0.04, 0.01, 1.0, 1.0])
    ekf.update_compass(0.0, -np.pi + 0.01, 0.01, None)  # 0.02 rad ahead, across the cut
    assert np.isclose(abs(ekf.x[TH]), np.pi, atol=1e-9) or np.isclose(ekf.x[TH], -np.pi, atol=1e-9)


def test_gating_rejects_outlier_and_counts_it():
    ekf = EKF(EKFConfig())
    ekf.initialize(0.0, np.array([0.0, 0.0, 0.0]), np.diag([0.01, 0.01, 0.001]))
    assert not ekf.update_map(0.0, np.array([3.0, 0.0, 0.0]), np.diag([0.01, 0.01, 0.001]))
    assert ekf.stats["gated"]["map"] == 1
    assert np.allclose(ekf.x[:3], 0.0)
    assert ekf.update_map(0.0, np.array([0.05, 0.0, 0.0]), np.diag([0.01, 0.01, 0.001]))


def test_old_stamp_is_applied_at_filter_time_never_backwards():
    ekf = EKF()
    ekf.initialize(5.0, np.zeros(3))
    ekf.update_encoder(4.0, np.array([0.5, 0.0, 0.0]), np.eye(3) * 0.01)
    assert ekf.t == 5.0 and ekf.stats["late"] == 1
