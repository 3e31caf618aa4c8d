"""ROS 2 message definitions (``ros2msg``) for the types fgloc logs and publishes, as rosbag2 stores them.

The field lines are those of the ROS 2 (Humble .. Jazzy) ``.msg`` files (comments left out;
same-package types written relative, defaults kept).  :func:`full_text` concatenates a type
and all its dependencies exactly as ``rosbag2_cpp::LocalMessageDefinitionSource`` does: the
root definition first, then for each dependency (sorted, depth-first, each once) a newline,
a line of 80 ``=``, a line ``MSG: pkg/Type`` and that type's text.
"""

from __future__ import annotations

import re

SEPARATOR = "=" * 80

MSG_TEXT: dict[str, str] = {
    "builtin_interfaces/Time": "int32 sec\nuint32 nanosec\n",
    "std_msgs/Header": "builtin_interfaces/Time stamp\nstring frame_id\n",
    "geometry_msgs/Point": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/Vector3": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/Quaternion": "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
    "geometry_msgs/Pose": "Point position\nQuaternion orientation\n",
    "geometry_msgs/PoseWithCovariance": "Pose pose\nfloat64[36] covariance\n",
    "geometry_msgs/PoseWithCovarianceStamped": "std_msgs/Header header\nPoseWithCovariance pose\n",
    "geometry_msgs/Twist": "Vector3  linear\nVector3  angular\n",
    "geometry_msgs/TwistWithCovariance": "Twist twist\nfloat64[36] covariance\n",
    "geometry_msgs/TwistWithCovarianceStamped": "std_msgs/Header header\nTwistWithCovariance twist\n",
    "geometry_msgs/Transform": "Vector3 translation\nQuaternion rotation\n",
    "geometry_msgs/TransformStamped": "std_msgs/Header header\nstring child_frame_id\nTransform transform\n",
    "nav_msgs/Odometry": (
        "std_msgs/Header header\nstring child_frame_id\n"
        "geometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist\n"
    ),
    "sensor_msgs/LaserScan": (
        "std_msgs/Header header\n"
        "float32 angle_min\nfloat32 angle_max\nfloat32 angle_increment\n"
        "float32 time_increment\nfloat32 scan_time\n"
        "float32 range_min\nfloat32 range_max\n"
        "float32[] ranges\nfloat32[] intensities\n"
    ),
    "sensor_msgs/LaserEcho": "float32[] echoes\n",
    "sensor_msgs/MultiEchoLaserScan": (
        "std_msgs/Header header\n"
        "float32 angle_min\nfloat32 angle_max\nfloat32 angle_increment\n"
        "float32 time_increment\nfloat32 scan_time\n"
        "float32 range_min\nfloat32 range_max\n"
        "LaserEcho[] ranges\nLaserEcho[] intensities\n"
    ),
    "sensor_msgs/Imu": (
        "std_msgs/Header header\n"
        "geometry_msgs/Quaternion orientation\nfloat64[9] orientation_covariance\n"
        "geometry_msgs/Vector3 angular_velocity\nfloat64[9] angular_velocity_covariance\n"
        "geometry_msgs/Vector3 linear_acceleration\nfloat64[9] linear_acceleration_covariance\n"
    ),
    "tf2_msgs/TFMessage": "geometry_msgs/TransformStamped[] transforms\n",
    # what fgloc publishes live (fgloc.ros2): a map, the simulated clock, its status
    "nav_msgs/MapMetaData": (
        "builtin_interfaces/Time map_load_time\nfloat32 resolution\nuint32 width\nuint32 height\n"
        "geometry_msgs/Pose origin\n"
    ),
    "nav_msgs/OccupancyGrid": "std_msgs/Header header\nMapMetaData info\nint8[] data\n",
    "rosgraph_msgs/Clock": "builtin_interfaces/Time clock\n",
    "diagnostic_msgs/KeyValue": "string key\nstring value\n",
    "diagnostic_msgs/DiagnosticStatus": (
        "byte OK=0\nbyte WARN=1\nbyte ERROR=2\nbyte STALE=3\n"
        "byte level\nstring name\nstring message\nstring hardware_id\nKeyValue[] values\n"
    ),
    "diagnostic_msgs/DiagnosticArray": "std_msgs/Header header\nDiagnosticStatus[] status\n",
}

_FIELD_TYPE = re.compile(r"(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+")
_PRIMITIVES = {
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
    "int32", "uint32", "int64", "uint64", "string",
}


def short_name(type_name: str) -> str:
    """``sensor_msgs/msg/LaserScan`` -> ``sensor_msgs/LaserScan``."""
    parts = type_name.split("/")
    return f"{parts[0]}/{parts[-1]}" if len(parts) == 3 else type_name


def _deps(name: str) -> list[str]:
    pkg = name.split("/")[0]
    out = set()
    for m in _FIELD_TYPE.finditer(MSG_TEXT[name]):
        t = m.group(1)
        if t in _PRIMITIVES:
            continue
        out.add(t if "/" in t else f"{pkg}/{t}")
    return sorted(out)


def full_text(type_name: str) -> str:
    """The complete ``ros2msg`` definition of ``type_name`` (``pkg/msg/Type`` or ``pkg/Type``)."""
    seen: set[str] = set()

    def rec(name: str) -> str:
        text = MSG_TEXT[name]
        for dep in _deps(name):
            if dep not in seen:
                seen.add(dep)
                text += f"\n{SEPARATOR}\nMSG: {dep}\n" + rec(dep)
        return text

    return rec(short_name(type_name))


def _sections(text: str, root: str) -> dict[str, tuple[str, ...]]:
    """``{pkg/Type: (normalized field lines)}`` of a ``ros2msg`` definition (comments, blank
    lines, constants and default values dropped; relative types made absolute)."""
    out: dict[str, tuple[str, ...]] = {}
    name, lines = short_name(root), list[str]()
    for raw in text.splitlines() + [SEPARATOR]:
        line = raw.split("#", 1)[0].strip()
        if line.startswith("=" * 10):
            out[name] = tuple(lines)
            name, lines = "", []
            continue
        if not line:
            continue
        if line.startswith("MSG:"):
            name = short_name(line[4:].strip())
            continue
        tok = line.split()
        if len(tok) < 2 or "=" in tok[1] or (len(tok) > 2 and tok[2].startswith("=")):
            continue  # a constant: no bytes on the wire
        typ, field = tok[0], tok[1]
        base, arr = (typ.split("[", 1) + [""])[:2]
        if base not in _PRIMITIVES and "/" not in base and base != "Header":
            base = f"{name.split('/')[0]}/{base}"
        elif base == "Header":
            base = "std_msgs/Header"
        lines.append(f"{short_name(base)}{'[' + arr if arr else ''} {field}")
    return out


def is_standard(type_name: str, encoding: str, data: bytes) -> bool:
    """Does a schema define the standard layout of ``type_name`` (one of :data:`MSG_TEXT`'s)?

    An empty schema or one that is not ``ros2msg`` counts as standard: the reader then decodes
    it with the standard definition anyway.  Otherwise every type the definition reaches must
    have exactly the standard fields (comments, constants and defaults aside)."""
    if short_name(type_name) not in MSG_TEXT:
        return False
    if encoding != "ros2msg" or not bytes(data).strip():
        return True
    try:
        got = _sections(bytes(data).decode(), type_name)
    except UnicodeDecodeError:
        return False
    want = _sections(full_text(type_name), type_name)
    return all(got.get(k) == v for k, v in want.items()) and set(got) <= set(want) | {""}


def fields(type_name: str) -> dict[str, list[tuple[str, str, str]]]:
    """Every type ``type_name`` reaches, ``{pkg/Type: [(field type, array suffix, field name)]}``,
    from :data:`MSG_TEXT` (constants and defaults dropped; nested types absolute, ``pkg/Type``;
    the suffix is ``""``, ``"[]"``, ``"[N]"`` or ``"[<=N]"``)."""
    out: dict[str, list[tuple[str, str, str]]] = {}
    for name, lines in _sections(full_text(type_name), type_name).items():
        if not name:
            continue
        rows = []
        for line in lines:
            typ, field = line.rsplit(" ", 1)
            base, _, arr = typ.partition("[")
            rows.append((base, "[" + arr if arr else "", field))
        out[name] = rows
    return out
