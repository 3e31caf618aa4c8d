"""Synthetic noise-free (or noisy) inputs with a known trajectory, for the back-end tests."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from fgloc.geometry import compose1 as se2_compose
from fgloc.geometry import exp as se2_exp


@dataclass
class Synth:
    t_odo: np.ndarray
    twist: np.ndarray
    t_gt: np.ndarray
    gt: np.ndarray
    t_compass: np.ndarray
    compass: np.ndarray
    t_scan: np.ndarray
    fixes: np.ndarray
    offset: float


def make_synth(duration: float = 12.0, seed: int = 0, noise: bool = False, offset: float = 0.4,
               omni: bool = True) -> Synth:
    rng = np.random.default_rng(seed)
    dt = 0.002
    t = np.arange(0.0, duration + 1e-9, dt)
    vx = 0.8 * np.clip(t / 1.0, 0, 1)
    vy = 0.2 * np.sin(0.5 * t) if omni else np.zeros_like(t)
    w = 0.6 * np.sin(0.7 * t)
    pose = np.array([1.0, 2.0, 0.3])
    gt = [pose]
    for i in range(1, len(t)):
        # mid-point twist for accuracy
        u = np.array([vx[i - 1] + vx[i], vy[i - 1] + vy[i], w[i - 1] + w[i]]) / 2
        pose = se2_compose(pose, se2_exp(u * dt))
        gt.append(pose)
    gt_arr = np.array(gt)
    # odometry at 50 Hz: mean twist over the preceding 20 ms (as encoders report it)
    step = 10
    idx = np.arange(step, len(t), step)
    tw = []
    for i in idx:
        d = se2_compose(-0 * gt_arr[i - step], np.zeros(3))
        a, b = gt_arr[i - step], gt_arr[i]
        c, s = np.cos(a[2]), np.sin(a[2])
        dx, dy = b[0] - a[0], b[1] - a[1]
        rel = np.array([c * dx + s * dy, -s * dx + c * dy, np.angle(np.exp(1j * (b[2] - a[2])))])
        # exact twist whose exponential is rel
        th = rel[2]
        if abs(th) < 1e-9:
            u = rel.copy()
        else:
            A, B = np.sin(th) / th, (1 - np.cos(th)) / th
            M = np.array([[A, -B], [B, A]])
            u = np.concatenate([np.linalg.solve(M, rel[:2]), [th]])
        tw.append(u / (t[i] - t[i - step]))
        del d
    twist = np.array(tw)
    t_odo = t[idx]
    if noise:
        twist = twist + rng.normal(0, [0.01, 0.01, 0.01], twist.shape)
    ic = np.arange(0, len(t), 10)  # compass 50 Hz
    compass = np.angle(np.exp(1j * (gt_arr[ic, 2] + offset)))
    if noise:
        compass = compass + rng.normal(0, np.deg2rad(0.5), len(ic))
    isc = np.arange(0, len(t), 20)  # scans 25 Hz
    fixes = gt_arr[isc].copy()
    if noise:
        fixes = fixes + rng.normal(0, [0.02, 0.02, np.deg2rad(0.5)], fixes.shape)
    return Synth(t_odo, twist, t, gt_arr, t[ic], compass, t[isc], fixes, offset)


@pytest.fixture(scope="session")
def synth_clean() -> Synth:
    return make_synth(noise=False)


@pytest.fixture(scope="session")
def synth_noisy() -> Synth:
    return make_synth(noise=True, seed=1)


def feed(backend, s: Synth, fix_sigma=(0.02, 0.02, np.deg2rad(0.5)), fixes=True, init_cov=1e-4,
         late_every: int = 0):
    """Drive a back-end with a synthetic run (scans before odometry at equal stamps).

    ``late_every``: every n-th scan is delivered one scan late (out of order).
    """
    from fgloc.types import PoseFix

    ev = [(t, 0, i) for i, t in enumerate(s.t_odo)] + [(t, 1, i) for i, t in enumerate(s.t_compass)]
    for i, t in enumerate(s.t_scan):
        if i > 0:
            t_deliver = s.t_scan[min(i + 1, len(s.t_scan) - 1)] + 1e-4 if late_every and i % late_every == 0 else t
            ev.append((t_deliver, 2, i))
    ev.sort(key=lambda e: (e[0], -e[1]))
    backend.initialize(s.t_scan[0], s.fixes[0], np.eye(3) * init_cov)
    cov = np.diag(np.square(fix_sigma))
    for _, kind, i in ev:
        if kind == 0:
            backend.add_odometry(s.t_odo[i], s.twist[i], None)
        elif kind == 1:
            backend.add_compass(s.t_compass[i], s.compass[i], np.nan, None, np.nan)
        else:
            fix = PoseFix(s.t_scan[i], s.fixes[i], cov) if fixes else None
            backend.add_keyframe(s.t_scan[i], fix)
    return backend.finish()


def errors(traj, s: Synth) -> tuple[float, float]:
    """Position RMSE (m) and heading RMSE (deg) against the synthetic truth."""
    idx = np.searchsorted(s.t_gt, traj.stamps - 1e-9)
    gt = s.gt[np.clip(idx, 0, len(s.t_gt) - 1)]
    e = np.linalg.norm(traj.poses[:, :2] - gt[:, :2], axis=1)
    eh = np.angle(np.exp(1j * (traj.poses[:, 2] - gt[:, 2])))
    return float(np.sqrt(np.mean(e**2))), float(np.rad2deg(np.sqrt(np.mean(eh**2))))
