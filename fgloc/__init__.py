"""fgloc: indoor mobile-robot localization without ROS.

The paper's EKF, GTSAM fixed-lag and batch smoothers, AMCL / KISS-ICP / native
scan-to-map front-ends, ROS 2 MCAP logs, map_server maps and TUM trajectories.
"""

__version__ = "0.1.0"
