"""Topic roles, their ROS 2 types, and the choice of a log's topics for each role.

==================  ============================================  ==========================
topic (default)     ROS 2 type                                    fgloc type
==================  ============================================  ==========================
``/scan``           ``sensor_msgs/msg/LaserScan``                 :class:`LaserScan`
``/odom``           ``nav_msgs/msg/Odometry``                     :class:`Odometry`
``/imu``            ``sensor_msgs/msg/Imu``                       :class:`Imu`
``/tf_static``      ``tf2_msgs/msg/TFMessage``                    ``list[Transform3D]``
``/tf``             ``tf2_msgs/msg/TFMessage``                    ``list[Transform3D]``
``/ground_truth``   ``nav_msgs/msg/Odometry`` (map frame)         :class:`Odometry`
``/fused_pose``     ``geometry_msgs/msg/PoseWithCovarianceStamped``  :class:`PoseFix`
==================  ============================================  ==========================
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from fgloc.errors import LogError

log = logging.getLogger(__name__)

LASER_SCAN = "sensor_msgs/msg/LaserScan"
#: a multi-echo laser's scan (urg_node's ``echoes``, cartographer's ``horizontal_laser_2d``): read
#: as a :class:`~fgloc.types.LaserScan` of its first echoes (:func:`fgloc.io.ros.multi_echo_scan_from_ros`)
MULTI_ECHO_SCAN = "sensor_msgs/msg/MultiEchoLaserScan"
ODOMETRY = "nav_msgs/msg/Odometry"
IMU = "sensor_msgs/msg/Imu"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
POSE_COV_STAMPED = "geometry_msgs/msg/PoseWithCovarianceStamped"
TWIST_COV_STAMPED = "geometry_msgs/msg/TwistWithCovarianceStamped"
READ_TYPES = (LASER_SCAN, MULTI_ECHO_SCAN, ODOMETRY, IMU, TF_MESSAGE, POSE_COV_STAMPED, TWIST_COV_STAMPED)
#: other names of these types, with the same fields: ROS 1 before Hydro (2013) published tf as
#: ``tf/tfMessage`` (the same ``geometry_msgs/TransformStamped[] transforms`` and md5 as tf2's)
TYPE_ALIASES = {"tf/msg/tfMessage": TF_MESSAGE}


@dataclass
class Topics:
    """Topic names of each role; every one can be renamed on the command line."""

    scan: str = "/scan"
    odom: str = "/odom"
    imu: str = "/imu"
    tf_static: str = "/tf_static"
    tf: str = "/tf"
    ground_truth: str = "/ground_truth"
    fused: str = "/fused_pose"

    def roles(self) -> dict[str, str]:
        """``{topic name: role}``."""
        return {getattr(self, f.name): f.name for f in fields(self)}


ROLE_TYPES = {
    "scan": LASER_SCAN,
    "odom": ODOMETRY,
    "imu": IMU,
    "tf_static": TF_MESSAGE,
    "tf": TF_MESSAGE,
    "ground_truth": ODOMETRY,
    "fused": POSE_COV_STAMPED,
}


#: other types a role reads (the scan role: a multi-echo scan's first echoes)
ROLE_ALSO = {"scan": (MULTI_ECHO_SCAN,)}


def role_reads(role: str, type_name: str) -> bool:
    """Whether a topic of ``type_name`` (any spelling) serves ``role`` (``ROLE_TYPES``, ``ROLE_ALSO``)."""
    t = normalize_type(type_name)
    return t == ROLE_TYPES[role] or t in ROLE_ALSO.get(role, ())


def estimator_output(topic: str) -> bool:
    """Whether ``topic`` is named as a state estimator's output rather than a sensor's: robot_localization's
    ``odometry/filtered`` (``_map``), its dual-EKF ``odometry/local`` / ``odometry/global`` and
    navsat_transform's ``odometry/gps``, ``odom/filtered``, ``odom_filtered``, robot_pose_ekf's
    ``odom_combined``.  A log that recorded such a filter with its inputs has two Odometry topics; the
    wheels' own is the one to fuse (the filter's already holds the IMU), the filter's the peer to compare with."""
    parts = resolve_name(topic).strip("/").split("/")
    last = parts[-1]
    if last == "filtered" or last.startswith("filtered_") or last.endswith("_filtered") or last == "odom_combined":
        return True
    return len(parts) >= 2 and parts[-2] == "odometry" and last in ("local", "global", "gps")


#: name parts of a simulator's or a motion capture's truth published as nav_msgs/Odometry: Gazebo's p3d
#: plugin (``/ground_truth/state``, ``/ground_truth_odom``, ``/gazebo_odom``), Stage's
#: ``/base_pose_ground_truth``, ``/odom_gt``, a motion capture's odometry (``/vicon/...``, ``/mocap/...``)
_TRUTH_PARTS = ("ground_truth", "groundtruth", "gazebo_odom", "odom_gazebo", "mocap", "vicon", "optitrack", "vrpn")


def truth_output(topic: str) -> bool:
    """Whether ``topic`` is named as a simulator's or a motion capture's truth rather than a sensor's:
    a name part holding ``ground_truth`` (Gazebo's p3d ``/ground_truth/state``, ``/ground_truth_odom``,
    Stage's ``/base_pose_ground_truth``), ``gazebo_odom``, ``gt`` (``/odom_gt``, ``/gt/odom``,
    ``/gt_odom``), or a motion capture's name (mocap, vicon, optitrack, vrpn).  A simulated log that
    recorded the truth beside the wheels has two Odometry topics; the wheels' is the one to fuse, the
    truth the reference to evaluate against."""
    for part in resolve_name(topic).strip("/").lower().split("/"):
        if any(k in part for k in _TRUTH_PARTS):
            return True
        words = part.split("_")
        if "gt" in words or "truth" in words:
            return True
    return False


def peer_output(topic: str) -> str | None:
    """What a topic named as no sensor's is: ``"a filter's output"`` (:func:`estimator_output`), ``"a
    ground truth"`` (:func:`truth_output`), else None."""
    if estimator_output(topic):
        return "a filter's output"
    if truth_output(topic):
        return "a ground truth"
    return None


def normalize_type(name: str) -> str:
    """``sensor_msgs/LaserScan`` (ROS 1 style) -> ``sensor_msgs/msg/LaserScan``; an alias
    (``tf/tfMessage``) -> the type fgloc reads it as (``TYPE_ALIASES``)."""
    parts = name.split("/")
    full = f"{parts[0]}/msg/{parts[1]}" if len(parts) == 2 else name
    return TYPE_ALIASES.get(full, full)


def resolve_name(name: str) -> str:
    """A topic name as ROS resolves it in the root namespace, where recorders and fgloc's defaults
    live: ``scan`` -> ``/scan`` (a relative name), ``/scan/`` -> ``/scan``; ``""`` stays ``""``."""
    name = name.strip()
    if not name:
        return name
    name = "/" + name.strip("/")
    return name


def choose_topics(available: dict[str, str], topics: Topics, path: str | Path) -> dict[str, str]:
    """``{source topic: role}`` for the roles whose topic (or a unique same-type topic) exists.

    ``available`` is ``{topic: type}`` of a log.  A topic named explicitly (not the default)
    that is not in the log is an error; when a role's default topic is absent but exactly one
    topic of that role's type is (other than the ones named), that one is used and logged
    (never for tf, ground truth or fused poses).
    """
    chosen: dict[str, str] = {}
    default = Topics()
    named = {getattr(topics, g.name) for g in fields(Topics)}
    for f in fields(Topics):
        role, name = f.name, getattr(topics, f.name)
        want = ROLE_TYPES[role]
        if role_reads(role, available.get(name, "")):
            chosen[name] = role
            continue
        if name in available:
            log.warning("topic %s has type %s, expected %s for %s; skipped", name, available[name], want, role)
            continue
        if name != getattr(default, role):
            have = ", ".join(sorted(available)) or "none"
            raise LogError(f"{path}: {role} topic '{name}' not in log (topics: {have})")
        if role in ("tf", "tf_static", "ground_truth", "fused"):
            continue  # never guessed
        same = [t for t, ty in available.items()
                if role_reads(role, ty) and t not in chosen and t not in named]
        if role == "odom" and len(same) > 1:  # the wheels' odometry beside a filter's output or a ground truth
            same = [t for t in same if peer_output(t) is None]
        if len(same) == 1:
            log.info("using %s (%s) as the %s topic", same[0], want, role)
            chosen[same[0]] = role
    return chosen


def pick_topics(src: Any, path: str | Path, wanted: dict[str, tuple[str, bool]]) -> dict[str, str]:
    """``{role: topic}`` for ``wanted`` ``{role: (topic, named)}`` (roles of :class:`fgloc.io.topics.Topics`):
    the rule ``fgloc import`` follows (:func:`fgloc.io.topics.choose_topics`).  A topic the user
    named is kept as it is (the caller checks it exists); a role's default topic that the log lacks
    is replaced by the log's only topic of that role's type, with a warning saying so."""
    types = {t: ty for t, ty in src.topic_types().items() if src.has(t)}
    default = Topics()
    guess = {role: t for t, role in choose_topics(types, default, path).items()}
    out: dict[str, str] = {}
    for role, (topic, named) in wanted.items():
        g = guess.get(role)
        if named or src.has(topic) or topic != getattr(default, role) or g is None or g == topic:
            out[role] = topic
            continue
        others = sorted(t for t, ty in types.items() if t != g and role_reads(role, ty))
        if others:  # the others are filters' outputs or ground truths (choose_topics)
            kinds = sorted({str(peer_output(t)) for t in others})
            named_as = ("filters' outputs" if kinds == ["a filter's output"] else
                        "ground truths" if kinds == ["a ground truth"] else "filters' outputs or ground truths")
            ref = next((t for t in others if truth_output(t)), others[0])
            log.warning("%s: no %s topic; using %s (%s); the log's other topics of that type are named as %s "
                        "(%s), to compare with: fgloc eval OUT/trajectory.tum %s:%s%s", path, topic, g, types[g],
                        named_as, ", ".join(others), path, ref, " --align-start" if truth_output(ref) else "")
        elif estimator_output(g):
            log.warning("%s: no %s topic; using %s (%s), the log's only topic of that type, named as a filter's "
                        "output (robot_localization's?): an estimate that may hold the IMU already, not the wheels' "
                        "own odometry", path, topic, g, types[g])
        elif truth_output(g):
            log.warning("%s: no %s topic; using %s (%s), the log's only topic of that type, named as a ground "
                        "truth (a simulator's or a motion capture's): not the wheels' own odometry, an error-free "
                        "motion", path, topic, g, types[g])
        else:
            log.warning("%s: no %s topic; using %s (%s), the log's only topic of that type", path, topic, g, types[g])
        out[role] = g
    return out
