"""Synthetic noise-free (or noisy) inputs with a known trajectory, for the back-end tests."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fgloc.backends.contract import Capability
from fgloc.geometry import compose1 as se2_compose
from fgloc.geometry import exp as se2_exp
from fgloc.localization.sources import SourceRouter, parse_sources
from fgloc.types import Imu, Odometry

_METHODS = {Capability.GYRO: "add_gyro", Capability.VELOCITY: "add_velocity",
            Capability.RELATIVE_YAW: "add_relative_yaw"}


def without_capability(monkeypatch: pytest.MonkeyPatch, cls: type, cap: Capability) -> None:
    """``cls`` (a back-end class) as a back-end without the input capability ``cap``: not declared,
    and its method gone for a caller that still asks with ``getattr``."""
    monkeypatch.setattr(cls, "capabilities", cls.capabilities - {cap})  # type: ignore[attr-defined]
    monkeypatch.setattr(cls, _METHODS[cap], None)


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


# ---------------------------------------------- a differential AHRS beside a gyro with a scale error
AHRS_SPECS = {
    "odom0": {"type": "odometry", "topic": "/wheels", "use": ["x", "y"], "differential": True},
    "imu0": {"type": "imu", "topic": "/gyro", "use": ["vyaw"]},
    "imu1": {"type": "imu", "topic": "/ahrs", "use": ["yaw"], "differential": True},
}
GYRO_SCALE = 0.88        # the gyro reports 88 % of the turn (and claims a placeholder 1 (rad/s)^2)
AHRS_OFFSET = 1.3        # the AHRS's heading frame is 1.3 rad from the odom frame
AHRS_DURATION_S, AHRS_SPEED, AHRS_START_S = 42.0, 1.0, 2.0   # standing still for START_S (the localizer starts)


def _ahrs_yaw_rate(t: float) -> float:
    """Yaw rate: 4 s turns of +-0.5 rad/s between 6 s straight stretches."""
    ph = (t - AHRS_START_S) % 20.0 if t >= AHRS_START_S else -1.0
    return 0.5 if 2.0 <= ph < 6.0 else (-0.5 if 12.0 <= ph < 16.0 else 0.0)


@lru_cache(maxsize=1)
def differential_ahrs_log() -> tuple[tuple[tuple[float, str, object], ...], np.ndarray]:
    """``(messages, final true pose)`` for :data:`AHRS_SPECS`: truth by Euler steps of 1 ms; wheel
    poses 20 Hz (no yaw fused), gyro and AHRS 100 Hz, every 25th AHRS message stamped 0.2 ms after
    the one before (a driver's stamp jitter).  40 m driven, 8 rad turned."""
    rng = np.random.default_rng(0)
    out: list[tuple[float, str, object]] = []
    x = y = th = 0.0
    dt = 0.001
    ahrs_i = 0
    for k in range(1, int(AHRS_DURATION_S / dt) + 1):
        t = k * dt
        w = _ahrs_yaw_rate(t)
        v = AHRS_SPEED if t >= AHRS_START_S else 0.0
        x += v * math.cos(th) * dt
        y += v * math.sin(th) * dt
        th += w * dt
        if k % 50 == 0:
            out.append((t, "/wheels", Odometry(t, np.array([v, 0.0, w]), np.diag([1e-4, 1e-4, 1e6]),
                                               np.array([x, y, th]), np.diag([1e-4, 1e-4, 1e6]))))
        if k % 10 == 0:
            g = GYRO_SCALE * w + rng.normal(0.0, 0.002)
            out.append((t, "/gyro", Imu(t, None, np.array([0.0, 0.0, g]), None, np.eye(3), frame_id="base_link")))
            ahrs_i += 1
            stamp = t - 0.0098 if ahrs_i % 25 == 0 else t
            q = Rotation.from_euler("z", th + AHRS_OFFSET + rng.normal(0.0, 0.0005)).as_quat()
            out.append((stamp, "/ahrs", Imu(stamp, q, None, np.eye(3) * 1e-4, None, frame_id="base_link")))
    out.sort(key=lambda m: m[0])
    return tuple(out), np.array([x, y, th])


def route(loc, spec_dict: dict, msgs) -> None:
    """Hand ``(stamp, topic, message)`` triples to ``loc`` through a SourceRouter of ``spec_dict``."""
    specs = parse_sources(spec_dict)
    router = SourceRouter(loc, specs)
    by_topic = {s.topic: s for s in specs}
    for _, topic, m in msgs:
        router.on_message(by_topic[topic], m)


def skid_steer_turns(dt: float = 0.01):
    """The drive of the relative-yaw runaway tests: four 90 deg turns at 0.7 rad/s between 3 s straights,
    stepped every ``dt``; yields ``(k, t, true heading, true turn rate)`` per step (k from 1)."""
    th, k = 0.0, 0
    for dur, w in [(3.0, 0.0), (math.pi / 2 / 0.7, 0.7)] * 4 + [(3.0, 0.0)]:
        for _ in range(round(dur / dt)):
            k += 1
            th += w * dt
            yield k, k * dt, th, w


def drive_skid_turns(backend, feed_heading, scrub: float, speed: float, rng) -> tuple[float, float]:
    """:func:`skid_steer_turns` into ``backend``: ``feed_heading(t, true heading)`` at every step (100 Hz),
    the odometry at 50 Hz (``speed`` on the straights, ``scrub`` times the turn rate, 0.02 rad/s noise from
    ``rng``), a keyframe at 25 Hz.  Returns the largest online heading error (deg) from the second turn on
    and the true heading at the end (rad)."""
    odom_cov = np.diag([1e-4, 1e-4, 0.02**2])
    worst, turns, prev_w, th = 0.0, 0, 0.0, 0.0
    for k, t, th, w in skid_steer_turns():
        if w > 0.0 and prev_w == 0.0:
            turns += 1
        prev_w = w
        feed_heading(t, th)
        if k % 2 == 0:
            backend.add_odometry(t, np.array([0.0 if w else speed, 0.0, scrub * w + float(rng.normal(0.0, 0.02))]),
                                 odom_cov)
        if k % 4 == 0:
            backend.add_keyframe(t, None)
            cur = backend.current(covariance=False)
            if cur is not None and turns >= 2:
                worst = max(worst, abs(math.degrees(math.remainder(float(cur[1][2]) - th, math.tau))))
    return worst, th
