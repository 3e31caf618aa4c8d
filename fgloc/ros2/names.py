"""ROS 2 names on the DDS wire, as rmw_cyclonedds_cpp and rmw_fastrtps_cpp spell them.

* A ROS topic ``/X`` is the DDS topic ``rt/X`` (prefix ``rt`` glued to the fully qualified
  name); services use ``rq`` (requests) and ``rr`` (replies).  A relative name is resolved in
  the node's namespace first (``scan`` in ``/`` is ``/scan``).  A topic created with
  ``avoid_ros_namespace_conventions`` has no prefix (not used by fgloc).
* A ROS type ``pkg/msg/Type`` is the DDS type ``pkg::msg::dds_::Type_``.

Both directions are here, with the rmw's rules for telling a ROS name from another DDS
application's (a DDS topic without a ROS prefix, a type without ``dds_::`` and the trailing
underscore, are not ROS's and are returned unchanged by the demangling functions).
"""

from __future__ import annotations

TOPIC_PREFIX = "rt"
REQUEST_PREFIX = "rq"
REPLY_PREFIX = "rr"
PREFIXES = (TOPIC_PREFIX, REQUEST_PREFIX, REPLY_PREFIX)


def resolve(name: str, namespace: str = "/") -> str:
    """A ROS name made fully qualified: ``scan`` -> ``/scan``, ``/a//b/`` -> ``/a/b``
    (``~`` private names are not supported: fgloc is not a named node's parameter space)."""
    name = name.strip()
    if not name:
        raise ValueError("empty topic name")
    if name.startswith("~"):
        raise ValueError(f"{name}: private (~) names are not supported; give the full name")
    if not name.startswith("/"):
        ns = namespace.strip("/")
        name = (f"/{ns}/" if ns else "/") + name
    parts = [p for p in name.split("/") if p]
    if not parts:
        raise ValueError(f"{name!r} is not a topic name")
    return "/" + "/".join(parts)


def dds_topic(ros_topic: str, namespace: str = "/", prefix: str = TOPIC_PREFIX) -> str:
    """``/scan`` -> ``rt/scan`` (the rmw's ``prefix + fully qualified name``)."""
    return prefix + resolve(ros_topic, namespace)


def ros_topic(dds_name: str) -> str | None:
    """``rt/scan`` -> ``/scan``; None when the DDS topic is not a ROS topic (no ``rt/`` prefix)."""
    if dds_name.startswith(TOPIC_PREFIX + "/") and len(dds_name) > len(TOPIC_PREFIX) + 1:
        return dds_name[len(TOPIC_PREFIX):]
    return None


def dds_type(ros_type: str) -> str:
    """``sensor_msgs/msg/LaserScan`` (or ``sensor_msgs/LaserScan``) -> ``sensor_msgs::msg::dds_::LaserScan_``."""
    parts = [p for p in ros_type.strip().split("/") if p]
    if len(parts) == 2:
        parts = [parts[0], "msg", parts[1]]
    if len(parts) != 3 or not all(parts):
        raise ValueError(f"{ros_type}: not a ROS type name (pkg/msg/Type)")
    pkg, sub, name = parts
    return f"{pkg}::{sub}::dds_::{name}_"


def ros_type(dds_name: str) -> str:
    """``sensor_msgs::msg::dds_::LaserScan_`` -> ``sensor_msgs/msg/LaserScan``; another DDS
    application's type name (no ``dds_::``, no trailing ``_``) comes back unchanged."""
    if not dds_name.endswith("_") or "dds_::" not in dds_name:
        return dds_name
    at = dds_name.find("dds_::")
    namespace = dds_name[:at].replace("::", "/")
    return namespace + dds_name[at + len("dds_::"):-1]
