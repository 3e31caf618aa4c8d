"""A robot that drives laps for as long as asked: the long-running input of the soak bench and the
memory tests.

:func:`lap_world` is a room (the tests' room: walls, an inner wall, a box, a pillar, a shelf) and a
circular drive in it whose one lap of sensor data is ray-cast once: ``/odom`` 50 Hz (noisy twist),
``/imu`` 20 Hz (compass), ``/scan`` 25 Hz (541 beams, 270 deg).  :meth:`LapWorld.messages` repeats
the lap with its stamps moved on, for any duration, without holding more than one lap: an hour of
input costs what 25 s do.  :func:`feed_live` pushes such a stream through a live runner's own
ingest path (:meth:`fgloc.live.runner.LiveRunner.process`, as the sensor threads' queue would),
as fast as the localizer goes: the accelerated equivalent of hours of ``fgloc live``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from fgloc.geometry import compose
from fgloc.maps import OccupancyMap
from fgloc.types import CompassHeading, LaserScan, Odometry, StaticTransform

SCAN_HZ, ODOM_HZ, IMU_HZ = 25.0, 50.0, 20.0


def room_map() -> OccupancyMap:
    """11 x 17 m, 5 cm cells, with an inner wall, a box, a pillar and a shelf."""
    data = np.full((220, 340), -1, dtype=np.int16)
    data[10:210, 10:330] = 100
    data[12:208, 12:328] = 0
    data[12:120, 120:122] = 100  # inner wall
    data[150:162, 60:84] = 100  # box
    data[80:92, 200:212] = 100  # pillar
    data[170:176, 240:290] = 100  # shelf
    return OccupancyMap(data, 0.05, origin=np.array([-1.0, -2.0, 0.0]))


@dataclass
class LapWorld:
    """One lap of a circular drive (its messages, relative stamps from 0) and the map."""

    map: OccupancyMap
    mount: StaticTransform
    lap_s: float
    center: np.ndarray
    radius_m: float
    speed_mps: float
    lap: list[tuple[float, str, Any]]  # (stamp in the lap, topic, message stamped in the lap)

    def pose(self, t: float, t0: float = 0.0) -> np.ndarray:
        """The ground truth at stamp ``t`` of a stream starting at ``t0``."""
        a = (t - t0) * self.speed_mps / self.radius_m
        return np.array([self.center[0] + self.radius_m * math.sin(a),
                         self.center[1] - self.radius_m * math.cos(a), a])

    def messages(self, duration_s: float, t0: float = 0.0) -> Iterator[tuple[str, Any]]:
        """``(topic, message)`` in stamp order for ``duration_s``, stamps from ``t0``: the lap again and
        again (each message a new object with its stamp moved on)."""
        k = 0
        while True:
            base = t0 + k * self.lap_s
            for s, topic, m in self.lap:
                t = base + s
                if t - t0 >= duration_s:
                    return
                yield topic, _restamped(m, t)
            k += 1


def _restamped(m: Any, t: float) -> Any:
    if isinstance(m, Odometry):
        return Odometry(t, m.twist)
    if isinstance(m, CompassHeading):
        return CompassHeading(t, m.yaw_rad, m.yaw_rate_radps)
    assert isinstance(m, LaserScan)
    return LaserScan(t, m.angle_min, m.angle_increment, m.range_min, m.range_max, m.ranges,
                     time_increment=m.time_increment, scan_time=m.scan_time)


def lap_world(radius_m: float = 1.8, speed_mps: float = 0.5, seed: int = 0) -> LapWorld:
    """A circle of ``radius_m`` around (12.5, 2.5) in :func:`room_map` at ``speed_mps``, turning left."""
    occ = room_map()
    mount = StaticTransform("base_link", "laser", np.array([0.15, 0.0, 0.0]))
    center = np.array([12.5, 2.5])
    w = speed_mps / radius_m
    lap_s = 2 * math.pi / w
    # a whole number of scan periods, so the scans keep their phase lap after lap
    lap_s = round(lap_s * SCAN_HZ) / SCAN_HZ
    w = 2 * math.pi / lap_s
    speed_mps = w * radius_m
    world = LapWorld(occ, mount, lap_s, center, radius_m, speed_mps, [])
    rng = np.random.default_rng(seed)
    ang = math.radians(-135.0) + math.radians(0.5) * np.arange(541)
    twist = np.array([speed_mps, 0.0, w])
    out: list[tuple[float, str, Any]] = []
    for k in range(int(round(lap_s * ODOM_HZ))):
        t = k / ODOM_HZ
        out.append((t, "/odom", Odometry(t, twist + rng.normal(0, 0.005, 3))))
    for k in range(int(round(lap_s * IMU_HZ))):
        t = k / IMU_HZ + 0.003
        yaw = math.remainder(world.pose(t)[2] + 0.3 + rng.normal(0, 0.005), 2 * math.pi)
        out.append((t, "/imu", CompassHeading(t, yaw, w)))
    for k in range(int(round(lap_s * SCAN_HZ))):
        t = k / SCAN_HZ + 0.001
        lp = compose(world.pose(t), mount.pose)
        r = occ.raycast(lp[:2], lp[2] + ang, 20.0)
        r32 = (r + rng.normal(0, 0.008, len(r)) * np.isfinite(r)).astype(np.float32)
        out.append((t, "/scan", LaserScan(t, math.radians(-135.0), math.radians(0.5), 0.05, 20.0, r32,
                                          time_increment=1 / 18000, scan_time=1 / SCAN_HZ)))
    out.sort(key=lambda x: x[0])
    world.lap = out
    return world


KINDS = {"/odom": "odom", "/imu": "imu", "/scan": "scan"}


def feed_live(runner: Any, messages: Iterator[tuple[str, Any]],
              every_s: float = 0.0, on_progress: Callable[[float], None] | None = None) -> int:
    """Push ``messages`` through ``runner.process`` (the live runner's ingest: health, recording,
    reorder, fusion), arrival = stamp; ``on_progress(stamp)`` every ``every_s`` of stream time.
    Returns the number of messages."""
    n = 0
    next_t: float | None = None
    for topic, m in messages:
        t = float(m.stamp)
        runner.process(KINDS[topic], m, t)
        n += 1
        if on_progress is not None and (next_t is None or t >= next_t):
            on_progress(t)
            next_t = t + every_s
    runner.flush_reorder(all_=True)
    return n
