"""The QoS profiles ROS 2 nodes use, and their DDS form as rmw_cyclonedds_cpp builds it.

Each profile names where it comes from (rmw's ``qos_profiles.h``, tf2_ros' ``qos.hpp``, nav2's
``nav2_ros_common/qos_profiles.hpp`` and the AMCL / map_server nodes).  :func:`to_dds` turns a
profile into Cyclone DDS QoS the way ``rmw_cyclonedds_cpp``'s ``create_readwrite_qos`` does:
keep-last history of the depth, reliability, durability (transient local with a durability
service of the same history), liveliness automatic with an infinite lease, no auto-dispose of
unregistered instances, and the XCDR1 data representation only (what its sertype allows:
a writer that offered XCDR2 would not match a ROS 2 reader).

One difference, on purpose: a reliable writer here waits at most ``max_blocking_s`` when its
history is full of unacknowledged samples (rmw_cyclonedds waits forever), so a subscriber that
stalls never stalls fgloc; the sample is then dropped and counted.  ``max_blocking_time`` is not
part of DDS's requested/offered matching, so peers see the same profile.

Which side matches which: a best-effort reader matches every writer; a reliable reader only a
reliable writer; a transient-local reader only a transient-local writer (DDS 2.2.3).
:func:`compatible` says it with the policy that fails, as DDS's incompatible-QoS status does.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

RELIABLE, BEST_EFFORT = "reliable", "best_effort"
VOLATILE, TRANSIENT_LOCAL = "volatile", "transient_local"


@dataclass(frozen=True)
class Profile:
    """A ROS 2 QoS profile (history is always keep-last here)."""

    reliability: str
    durability: str
    depth: int
    origin: str = ""  # where ROS 2 defines it

    def with_depth(self, depth: int) -> Profile:
        return Profile(self.reliability, self.durability, int(depth), self.origin)


#: rmw_qos_profile_sensor_data (rclcpp::SensorDataQoS): laser scans, odometry, IMU
SENSOR_DATA = Profile(BEST_EFFORT, VOLATILE, 5, "rmw_qos_profile_sensor_data")
#: rmw_qos_profile_default (rclcpp::QoS(10)); also ros2 bag play's default and nav2's StandardTopicQoS
DEFAULT = Profile(RELIABLE, VOLATILE, 10, "rmw_qos_profile_default")
#: tf2_ros::DynamicBroadcasterQoS / DynamicListenerQoS (/tf)
TF = Profile(RELIABLE, VOLATILE, 100, "tf2_ros DynamicBroadcasterQoS / DynamicListenerQoS")
#: tf2_ros::StaticBroadcasterQoS (/tf_static publisher)
TF_STATIC_PUB = Profile(RELIABLE, TRANSIENT_LOCAL, 1, "tf2_ros StaticBroadcasterQoS")
#: tf2_ros::StaticListenerQoS (/tf_static subscriber)
TF_STATIC_SUB = Profile(RELIABLE, TRANSIENT_LOCAL, 100, "tf2_ros StaticListenerQoS")
#: nav2::qos::LatchedPublisherQoS: map_server's /map, AMCL's /amcl_pose
LATCHED_PUB = Profile(RELIABLE, TRANSIENT_LOCAL, 1, "nav2 LatchedPublisherQoS")
#: nav2::qos::LatchedSubscriptionQoS(3): AMCL's /map subscription
MAP_SUB = Profile(RELIABLE, TRANSIENT_LOCAL, 3, "nav2 LatchedSubscriptionQoS(3) (AMCL's map)")
#: nav2::qos::StandardTopicQoS: AMCL's /initialpose subscription (RViz publishes it reliable)
INITIAL_POSE_SUB = Profile(RELIABLE, VOLATILE, 10, "nav2 StandardTopicQoS (AMCL's initialpose)")
#: rclcpp::ClockQoS (/clock)
CLOCK = Profile(BEST_EFFORT, VOLATILE, 1, "rclcpp ClockQoS")

PROFILES = {"sensor_data": SENSOR_DATA, "default": DEFAULT, "tf": TF, "tf_static_pub": TF_STATIC_PUB,
            "tf_static_sub": TF_STATIC_SUB, "latched_pub": LATCHED_PUB, "map_sub": MAP_SUB,
            "initial_pose_sub": INITIAL_POSE_SUB, "clock": CLOCK}

MAX_BLOCKING_S = 0.005  # a reliable writer waits at most this for room in its history, then drops


def compatible(offered: Profile, requested: Profile) -> str | None:
    """None when a writer offering ``offered`` matches a reader requesting ``requested``; else the
    DDS policy that fails (``RELIABILITY`` or ``DURABILITY``)."""
    if requested.reliability == RELIABLE and offered.reliability != RELIABLE:
        return "RELIABILITY"
    if requested.durability == TRANSIENT_LOCAL and offered.durability != TRANSIENT_LOCAL:
        return "DURABILITY"
    return None


def to_dds(profile: Profile, max_blocking_s: float = MAX_BLOCKING_S, user_data: bytes | None = None) -> Any:
    """Cyclone DDS QoS of ``profile`` (see the module docstring); ``user_data``: the endpoint's
    USER_DATA (rmw_cyclonedds_cpp puts the type hash there, :mod:`fgloc.ros2.typehash`)."""
    from cyclonedds.qos import Policy, Qos
    from cyclonedds.util import duration

    depth = max(1, int(profile.depth))
    rel = Policy.Reliability.Reliable(duration(seconds=max_blocking_s)) if profile.reliability == RELIABLE \
        else Policy.Reliability.BestEffort
    policies = [
        Policy.History.KeepLast(depth),
        rel,
        Policy.Liveliness.Automatic(duration(infinite=True)),
        Policy.WriterDataLifecycle(autodispose=False),
        Policy.DataRepresentation(use_cdrv0_representation=True),
    ]
    if profile.durability == TRANSIENT_LOCAL:
        policies += [Policy.Durability.TransientLocal,
                     Policy.DurabilityService(cleanup_delay=0, history=Policy.History.KeepLast(depth),
                                              max_samples=-1, max_instances=-1, max_samples_per_instance=-1)]
    else:
        policies.append(Policy.Durability.Volatile)
    if user_data:
        policies.append(Policy.Userdata(bytes(user_data)))
    return Qos(*policies)
