"""The laser mount from a log's tf when its frames carry a tf prefix or namespace (a multi-robot
log: ``tb3_0/base_footprint -> tb3_0/base_link -> tb3_0/base_scan``): found as with plain names,
where it was "no transform base_link -> tb3_0/base_scan ...; assuming the laser at the robot
centre" (a wrong mount, 0.35 m here).  ROS 1's leading ``/`` (``/base_link -> /laser``, scans in
``laser``, or the other way) was read right before and still is.  The logs are written here."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from fgloc.frames.tf import is_base_frame
from fgloc.io import open_log
from fgloc.io.mcap_writer import LogWriter
from fgloc.types import LaserScan, Odometry, StaticTransform

N = 5


def _write(path, base: str, link: str, laser: str, scan_frame: str, flip: bool = False):
    chain = [StaticTransform(base, link, np.array([0.0, 0.0, 0.0]), 0.01),
             StaticTransform(link, laser, np.array([0.35, -0.02, 0.1]), 0.17)]
    with LogWriter(path) as w:
        w.write("/tf_static", chain, stamp=100.0)
        for i in range(N):
            t = 100.0 + 0.1 * i
            w.write("/odom", Odometry(stamp=t, twist=np.zeros(3), pose=np.array([0.01 * i, 0.0, 0.0]),
                                      child_frame_id=base))
            w.write("/scan", LaserScan(stamp=t + 0.001, angle_min=-1.0, angle_increment=0.01, range_min=0.1,
                                       range_max=10.0, ranges=np.full(201, 2.0, np.float32), frame_id=scan_frame))
    return path


@pytest.mark.parametrize("base, link, laser, scan_frame", [
    ("tb3_0/base_footprint", "tb3_0/base_link", "tb3_0/base_scan", "tb3_0/base_scan"),   # tf prefix
    ("/robot1/base_link", "/robot1/laser_mount", "/robot1/laser", "robot1/laser"),     # namespace, ROS 1 slashes
    ("/base_link", "/laser_mount", "/laser", "laser"),                                 # ROS 1's leading /
    ("base_link", "laser_mount", "laser", "/laser"),                                   # ... on the scans only
])
def test_prefixed_frames_give_the_mount(tmp_path, caplog, base, link, laser, scan_frame):
    log = _write(tmp_path / "log.mcap", base, link, laser, scan_frame)
    with caplog.at_level(logging.WARNING):
        mount = open_log(log).laser_mount()
    assert "robot centre" not in caplog.text
    assert mount.pose == pytest.approx([0.35, -0.02, 0.1])
    assert mount.z == pytest.approx(0.17 if is_base_frame(link) else 0.18)   # the chain stops at base_link


def test_only_the_robots_own_frames_are_bases():
    assert is_base_frame("tb3_0/base_link") and is_base_frame("/base_footprint") and is_base_frame("a/b/base_link")
    assert not is_base_frame("odom") and not is_base_frame("tb3_0/odom") and not is_base_frame("base_link_x")
