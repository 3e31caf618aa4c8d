"""The ``ros2:`` config section (``fgloc live --ros2``, ``fgloc replay --ros2``).

Names and defaults follow nav2's AMCL where it has the parameter (``global_frame_id``,
``odom_frame_id``, ``scan_topic``, ``map_topic``, ``transform_tolerance``, ``tf_broadcast``), so a
nav2 stack sees the same names.  The odometry / IMU / pose topics are the ``sources:`` section's
(a config ported with ``fgloc config from-robot-localization`` or ``from-nav2`` works as it is).
Kept apart from the node (no DDS import) so that composing the config costs nothing.
"""

from __future__ import annotations

from dataclasses import dataclass

from fgloc.config.schema import setting


@dataclass(frozen=True)
class Ros2Config:
    """``ros2:`` fgloc as a ROS 2 peer over DDS (a drop-in for nav2's AMCL)."""

    domain_id: int | None = setting(None, "DDS domain; null = $ROS_DOMAIN_ID, else 0", min=0, max=232)
    interface: str | None = setting(None, "network interface (name such as eth0, or its address) DDS uses; "
                                    "null = Cyclone DDS's choice or $CYCLONEDDS_URI")
    node_name: str = setting("fgloc", "the ROS 2 node fgloc shows as (ros2 node list), on ros_discovery_info")
    node_namespace: str = setting("/", "the node's namespace")
    ros_distro: str | None = setting(None, "ROS 2 distribution of the other nodes (humble or older: 24-byte GIDs "
                                     "and no type hashes; iron and later: 16-byte GIDs, RIHS01 type hashes); "
                                     "null = $ROS_DISTRO, else jazzy")
    scan_topic: str = setting("/scan", "sensor_msgs/LaserScan input (nav2 AMCL's scan_topic)")
    map_topic: str = setting("/map", "nav_msgs/OccupancyGrid input, transient local (nav2 AMCL's map_topic); "
                             "--map FILE instead of it")
    first_map_only: bool = setting(False, "localize on the first map received only (nav2 AMCL's first_map_only); "
                                   "else each new map from the next scan on, the pose re-initialized where it was")
    initial_pose_topic: str = setting("/initialpose", "geometry_msgs/PoseWithCovarianceStamped that "
                                      "re-initializes the pose (RViz's 2D Pose Estimate)")
    pose_topic: str = setting("/amcl_pose", "the fused pose, PoseWithCovarianceStamped, transient local")
    status_topic: str = setting("/fgloc/status", "per-source health and pose status "
                                "(diagnostic_msgs/DiagnosticArray)")
    global_frame_id: str = setting("map", "the map frame (nav2 AMCL's global_frame_id)")
    odom_frame_id: str = setting("odom", "the odometry frame (nav2 AMCL's odom_frame_id)")
    tf_broadcast: bool = setting(True, "publish map -> odom on /tf (nav2 AMCL's tf_broadcast)")
    transform_tolerance_s: float = setting(1.0, "map -> odom is stamped this far after its scan (nav2 AMCL's "
                                           "transform_tolerance)", min=0)
    tf_at_match: bool = setting(True, "publish map -> odom right after each scan's match (the prediction updated "
                                "with its fix, as nav2's AMCL after its update), then again from the back-end's "
                                "estimate there once it is made (a smoother waits for the odometry / IMU past the "
                                "scan), stamped 1 us later; false: only the latter. /amcl_pose carries that "
                                "estimate either way")
    status_period_s: float = setting(1.0, "period of /fgloc/status", gt=0)
    sensor_reliability: str = setting("best_effort", "QoS of the scan / odometry / IMU subscriptions: "
                                      "best_effort (ROS 2's sensor data QoS: matches every publisher) or reliable",
                                      choices=("best_effort", "reliable"))
    reorder_s: float = setting(0.0, "odometry / IMU messages wait this long past their stamps (host clock) to be "
                               "handed on in stamp order across topics; 0: as they come, sorted among those "
                               "received together (a scan's pose waits for the odometry past its stamp: a hold "
                               "here delays it as long)", min=0)
    startup_buffer_s: float = setting(30.0, "messages kept while waiting for the map and the laser mount "
                                      "(fused once they are there)", gt=0)
    mount_wait_s: float = setting(2.0, "after the first scan, wait this long for a transform to its frame; "
                                  "then assume the laser at the robot centre (said)", min=0)
