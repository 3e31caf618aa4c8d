"""robot_localization (ekf_node / ukf_node) parameters -> an fgloc config.

What carries over:

==========================================  ===============================================
robot_localization                          fgloc
==========================================  ===============================================
``odomN`` + ``odomN_config``                ``sources.inputs.odomN`` (odometry): vx, vy, vyaw;
                                            x, y, yaw as increments (``differential``)
``imuN`` + ``imuN_config``                  ``sources.inputs.imuN`` (imu): yaw, vyaw; roll, pitch
                                            (with ``two_d_mode: false``: the odometry levelled)
``poseN`` + ``poseN_config``                ``sources.inputs.poseN`` (pose): x, y, yaw
``twistN`` + ``twistN_config``              ``sources.inputs.twistN`` (twist): vx, vy, vyaw
``*_differential``                          ``differential`` (on pose variables, as r_l)
``poseN_rejection_threshold`` (Mahalanobis  ``gate`` (its square: fgloc gates on the squared
distance)                                   distance)
``world_frame`` (map or odom)               a pose source's ``frame_id``
``base_link_frame``                         ``sources.base_frame`` (the mounts are from it)
``odom_frame`` (other than ``odom``)        ``ros2.odom_frame_id``
``process_noise_covariance`` (15 x 15,      ``ekf.q_xy`` (x, y), ``q_theta`` (yaw), ``q_v``
per second, as r_l scales it by dt)         (vx, vy), ``q_w`` (vyaw)
``initial_estimate_covariance``             ``pipeline.initial_sigma_xy_m`` / ``_yaw_deg``
``two_d_mode: true``                        (fgloc is planar)
==========================================  ===============================================

Everything else is one note line: 3-D components (z, roll and pitch in two_d_mode, rates,
accelerations), ``_relative`` (fgloc
estimates each heading source's offset anyway), odometry and IMU rejection thresholds (fgloc
weights those by the noise they show), queue sizes, ``nodelay``, ``sensor_timeout``,
control input, tf and debug settings.
"""

from __future__ import annotations

import math
import re
from typing import Any

import numpy as np

from fgloc.porting.common import as_bool, find_params

# the 15-element state: x y z roll pitch yaw vx vy vz vroll vpitch vyaw ax ay az
PLANAR = {0: "x", 1: "y", 5: "yaw", 6: "vx", 7: "vy", 11: "vyaw"}
NAMES15 = ("x", "y", "z", "roll", "pitch", "yaw", "vx", "vy", "vz", "vroll", "vpitch", "vyaw", "ax", "ay", "az")
SENSOR = re.compile(r"^(odom|imu|pose|twist)(\d+)$")
IGNORED_QUIETLY = {"use_sim_time"}
#: the parameters of a robot_localization filter node (ekf_node / ukf_node), for "did you mean"
FILTER_PARAMS = (
    "frequency", "sensor_timeout", "two_d_mode", "transform_time_offset", "transform_timeout", "print_diagnostics",
    "debug", "debug_out_file", "map_frame", "odom_frame", "base_link_frame", "base_link_frame_output",
    "world_frame", "publish_tf", "publish_acceleration", "permit_corrected_publication", "reset_on_time_jump",
    "predict_to_current_time", "smooth_lagged_data", "history_length", "use_control", "stamped_control",
    "control_timeout", "control_config", "acceleration_limits", "deceleration_limits", "acceleration_gains",
    "deceleration_gains", "process_noise_covariance", "initial_estimate_covariance",
    "dynamic_process_noise_covariance", "initial_state", "tf_prefix", "silent_tf_failure", "disabled_at_startup",
    "gravitational_acceleration", "alpha", "kappa", "beta", "use_sim_time")
#: the per-sensor parameters (``odom0_config`` ...)
SENSOR_SUFFIXES = ("config", "differential", "relative", "queue_size", "nodelay", "rejection_threshold",
                   "pose_rejection_threshold", "twist_rejection_threshold",
                   "linear_acceleration_rejection_threshold", "angular_velocity_rejection_threshold",
                   "remove_gravitational_acceleration", "pose_use_child_frame")
#: GPS: what fgloc would need to fuse a sensor_msgs/NavSatFix (docs/porting.md, "GPS")
GPS_NEEDS = ("sensor_msgs/NavSatFix (GPS) is not read by fgloc: fusing it needs a datum that turns latitude / "
             "longitude into the map frame (navsat_transform_node's job, with magnetic_declination_radians and "
             "yaw_offset) and the antenna's mount; fgloc fuses positions given as "
             "geometry_msgs/PoseWithCovarianceStamped in the map frame (a source of type: pose) "
             "(docs/porting.md, GPS)")
#: a navsat_transform_node's parameters (a file holding one beside the filter)
NAVSAT_PARAMS = ("magnetic_declination_radians", "yaw_offset", "zero_altitude", "broadcast_utm_transform",
                 "broadcast_cartesian_transform", "use_odometry_yaw", "wait_for_datum", "datum",
                 "publish_filtered_gps")


def _looks_like_rl(d: Any) -> bool:
    return isinstance(d, dict) and any(SENSOR.match(str(k)) for k in d) or \
        (isinstance(d, dict) and ("two_d_mode" in d or "process_noise_covariance" in d))


def _matrix(v: Any, n: int = 15) -> np.ndarray | None:
    try:
        a = np.asarray(v, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        return None
    if a.size == n * n:
        return a.reshape(n, n)
    if a.size == n:
        return np.diag(a)
    if n == 15 and a.size in (12 * 12, 12):  # hydro / groovy: 12 variables, the same first 12
        out = np.zeros((15, 15))
        out[:12, :12] = a.reshape(12, 12) if a.size == 144 else np.diag(a)
        return out
    return None


def _matrix_param(p: dict, key: str, used: set[str], notes: list[str]) -> np.ndarray | None:
    """Parameter ``key``'s 15 x 15 matrix (marked used), or None: absent, or not a matrix (a note)."""
    if key not in p:
        return None
    used.add(key)
    m = _matrix(p[key])
    if m is None:
        notes.append(f"{key}: not a 15 x 15 matrix; not carried over")
    return m


def from_robot_localization(data: Any, node: str | None = None, source: str = "r_l params"
                            ) -> tuple[dict[str, Any], list[str]]:
    """``(fgloc config sections, notes)`` for a robot_localization parameter file (ROS 1 or 2)."""
    name, p, others = find_params(data, _looks_like_rl, node, source)
    notes: list[str] = []
    if others:
        notes.append(f"converted node {name}; not converted: {', '.join(others)} (pick one with --node)")
    notes += [f"{n} (navsat_transform_node): {GPS_NEEDS}" for n in _navsat_nodes(data)]
    inputs: dict[str, dict[str, Any]] = {}
    used: set[str] = set()
    world = str(p.get("world_frame", p.get("odom_frame", "odom")))
    map_frame = str(p.get("map_frame", "map"))
    pose_frame = "map" if world == map_frame else "odom"
    sensors = sorted({(m.group(1), int(m.group(2))) for k in p if (m := SENSOR.match(str(k)))},
                     key=lambda s: (("odom", "imu", "pose", "twist").index(s[0]), s[1]))
    for kind, i in sensors:
        key = f"{kind}{i}"
        used.add(key)
        topic = str(p[key])
        if not topic.startswith("/"):
            topic = "/" + topic  # a relative ROS name as a recorded log shows it
        cfg_key = f"{key}_config"
        vec = p.get(cfg_key)
        used.add(cfg_key)
        if vec is None:
            used.update(f"{key}_{x}" for x in SENSOR_SUFFIXES)
            typo = [k for k in map(str, p) if k not in (cfg_key, key) and _suggest(k, [cfg_key])]
            used.update(typo[:1])
            notes.append(f"{key} ({topic}): no {cfg_key}, so robot_localization fuses nothing from it; skipped"
                         + (f" ({typo[0]}: did you mean {cfg_key}?)" if typo else ""))
            continue
        flags = [as_bool(v) for v in vec] if isinstance(vec, (list, tuple)) else [False] * 15
        if len(flags) == 12:  # hydro / groovy: the same first 12 variables, no accelerations
            flags += [False] * 3
        if len(flags) != 15:
            notes.append(f"{cfg_key}: {len(flags)} values, expected 15 (or 12 before indigo): source {key} skipped")
            continue
        levels = kind == "imu" and flags[3] and flags[4] and not as_bool(p.get("two_d_mode", False)) \
            and (flags[5] or flags[11])
        dropped = [NAMES15[j] for j in range(15) if flags[j] and j not in PLANAR and not (levels and j in (3, 4))]
        planar = [PLANAR[j] for j in sorted(PLANAR) if flags[j]]
        diff = as_bool(p.get(f"{key}_differential", False))
        used.add(f"{key}_differential")
        if dropped:
            notes.append(f"{cfg_key}: {', '.join(dropped)} not carried over (fgloc estimates x, y, yaw and their "
                         "rates in the plane" + (", no accelerations)" if any(d[0] == "a" for d in dropped) else ")"))
        entry: dict[str, Any] = {"type": {"odom": "odometry", "imu": "imu", "pose": "pose", "twist": "twist"}[kind],
                                 "topic": topic}
        if kind == "odom":
            twist = [c for c in planar if c.startswith("v")]
            pose = [c for c in planar if not c.startswith("v")]
            if pose:
                # fgloc integrates an odometry: its poses as increments (per axis, beside the twist
                # components of the other axes)
                same_axis = [c for c in twist if c[1:] in pose]
                use = pose + [c for c in twist if c not in same_axis]
                if not diff:
                    notes.append(f"{cfg_key}: absolute {', '.join(pose)} of an odometry fused as its increments "
                                 f"({key}_differential; the same while it is the only position source in "
                                 f"{world}; a position fix such as navsat_transform's /odometry/gps is not)")
                if same_axis:
                    notes.append(f"{cfg_key}: {', '.join(same_axis)} not fused beside the increments of "
                                 f"{', '.join(c[1:] for c in same_axis)} (one measurement per axis)")
                diff = True
            else:
                use = twist
                if diff:
                    notes.append(f"{key}_differential: true has no effect on velocities (robot_localization "
                                 "applies it to pose variables only)")
                    diff = False
            if not use:
                notes.append(f"{key}: contributes nothing fgloc can fuse; skipped")
                continue
            entry["use"] = use
        elif kind == "imu":
            use = [c for c in planar if c in ("yaw", "vyaw")]
            if flags[3] and flags[4] and not as_bool(p.get("two_d_mode", False)) and use:
                # r_l in 3-D turns the body velocity through the whole attitude: fgloc levels the
                # odometry with this IMU's roll and pitch
                use += ["roll", "pitch"]
            lin = [c for c in planar if c not in ("yaw", "vyaw")]
            if lin:
                notes.append(f"{cfg_key}: {', '.join(lin)} from an IMU not carried over")
            if not use:
                notes.append(f"{key}: contributes nothing fgloc can fuse; skipped")
                continue
            if diff and "yaw" not in use:
                notes.append(f"{key}_differential: true has no effect on a yaw rate (robot_localization applies "
                             "it to orientation only)")
                diff = False
            entry["use"] = use
        elif kind == "twist":
            # robot_localization takes a twist's velocities only (its pose variables are ignored)
            use = [c for c in planar if c.startswith("v")]
            if not use:
                notes.append(f"{key}: contributes nothing fgloc can fuse; skipped")
                continue
            if diff:
                notes.append(f"{key}_differential: true has no effect on velocities")
                diff = False
            entry["use"] = use
        else:
            use = [c for c in planar if c in ("x", "y", "yaw")]
            if not use:
                notes.append(f"{key}: contributes nothing fgloc can fuse; skipped")
                continue
            entry["use"] = use
            entry["frame_id"] = pose_frame
        if diff:
            entry["differential"] = True
            if kind == "pose":
                notes.append(f"{key}_differential: a differential pose source is counted, not fused, by fgloc")
        rel_key = f"{key}_relative"
        if rel_key in p:
            used.add(rel_key)
            if as_bool(p[rel_key]):
                notes.append(f"{rel_key}: not needed (fgloc estimates each heading source's offset)")
        for thr in ("rejection_threshold", "pose_rejection_threshold", "twist_rejection_threshold",
                    "linear_acceleration_rejection_threshold"):
            k = f"{key}_{thr}"
            if k not in p:
                continue
            used.add(k)
            v = float(p[k])
            if kind == "pose" and thr in ("rejection_threshold", "pose_rejection_threshold"):
                entry["gate"] = round(v * v, 6)
            else:
                notes.append(f"{k}: {v:g} not carried over (fgloc gates fixes, and weights odometry and IMU by "
                             "the noise they show against the other sources)")
        first_odom = next((n for n, e in inputs.items() if e["type"] == "odometry"), None)
        first_twist = next((n for n, e in inputs.items() if e["type"] in ("odometry", "twist")), None)
        if kind == "twist" and first_twist is not None:
            notes.append(f"{key} ({topic}): fgloc integrates one twist source, the first ({first_twist}); {key}'s "
                         "velocities are measurements in a back-end that takes a further odometry source")
        if kind == "odom" and first_odom is not None:
            notes.append(f"{key} ({topic}): fgloc integrates one odometry source, the first ({first_odom}); "
                         f"the EKF fuses {key}'s velocities as measurements, the smoother counts its messages as "
                         "skipped (robot_localization fuses both)")
        inputs[key] = entry
    out: dict[str, Any] = {}
    if inputs:
        out["sources"] = {"inputs": inputs}
    # filter-wide parameters
    pipeline: dict[str, Any] = {}
    ekf: dict[str, Any] = {}
    if "frequency" in p:
        used.add("frequency")
        notes.append(f"frequency: {p['frequency']}: not carried over (fgloc publishes the fused pose at every scan; "
                     "without scans its keyframes are pipeline.odom_keyframe_interval_s apart)")
    if "two_d_mode" in p:
        used.add("two_d_mode")
        if not as_bool(p["two_d_mode"]):
            notes.append("two_d_mode: false: fgloc is planar (z, roll, pitch are not estimated)")
    q = _matrix_param(p, "process_noise_covariance", used, notes)
    if q is not None:
        d = np.diag(q)
        ekf.update({"q_xy": float(max(d[0], d[1])), "q_theta": float(d[5]), "q_v": float(max(d[6], d[7])),
                    "q_w": float(d[11])})
    p0 = _matrix_param(p, "initial_estimate_covariance", used, notes)
    if p0 is not None:
        sxy = math.sqrt(max(p0[0, 0], p0[1, 1], 1e-12))
        syaw = math.degrees(math.sqrt(max(p0[5, 5], 1e-12)))
        if sxy > 1e-3:
            pipeline["initial_sigma_xy_m"] = round(sxy, 6)
        if syaw > 1e-3:
            pipeline["initial_sigma_yaw_deg"] = round(syaw, 6)
        if sxy <= 1e-3 or syaw <= 1e-3:
            notes.append("initial_estimate_covariance: near-zero pose variances kept at fgloc's (an "
                         "--initial-pose prior needs some width)")
    for k in ("map_frame", "odom_frame", "world_frame", "base_link_frame"):
        used.add(k)
    base = str(p.get("base_link_frame") or "").strip().lstrip("/")
    if base:  # the robot's base frame, whatever its name: the sensors' mounts are from it (REP 105)
        out.setdefault("sources", {})["base_frame"] = base
    odom_frame = str(p.get("odom_frame") or "odom").strip().lstrip("/")
    if odom_frame != "odom":  # the odom -> base transform a ROS 2 peer reads
        out["ros2"] = {"odom_frame_id": odom_frame}
    if pipeline:
        out["pipeline"] = pipeline
    if ekf:
        out["ekf"] = ekf
    for k in sorted(p):
        ks = str(k)
        if ks in used or ks in IGNORED_QUIETLY:
            continue
        m = re.match(r"^(odom|imu|pose|twist)(\d+)_(.+)$", ks)
        why = _why(m.group(3) if m else ks)
        if why == "no fgloc equivalent":
            g = re.match(r"^gps(\d+)(_.*)?$", ks)
            known = [*FILTER_PARAMS, *(f"{k}_{x}" for k in map(str, p) if SENSOR.match(k) for x in SENSOR_SUFFIXES)]
            near = _suggest(ks, known)
            if g:
                why = GPS_NEEDS
            elif near:
                why = f"not a robot_localization parameter (did you mean {near}?)"
        notes.append(f"{ks}: {why}")
    return out, notes


def _suggest(name: str, known: list[str] | tuple[str, ...]) -> str | None:
    """The known parameter ``name`` is most likely a misspelling of, or None."""
    import difflib

    if name in known:
        return None
    hit = difflib.get_close_matches(name, known, n=1, cutoff=0.85)
    return hit[0] if hit else None


def _navsat_nodes(data: Any) -> list[str]:
    """Names of the navsat_transform_node parameter sets in a parameter file (a GPS setup)."""
    found: list[str] = []

    def walk(name: str, d: Any, depth: int) -> None:
        if not isinstance(d, dict) or depth > 4:
            return
        if sum(k in d for k in NAVSAT_PARAMS) >= 2:
            found.append(name or "(top level)")
            return
        for k, v in d.items():
            walk(f"{name}/{k}" if name else str(k), v, depth + 1)

    walk("", data, 0)
    return [n.removesuffix("/ros__parameters") for n in found]


def _why(param: str) -> str:
    if param in ("queue_size", "nodelay"):
        return "a ROS subscription setting"
    if param == "remove_gravitational_acceleration":
        return "fgloc does not fuse accelerations"
    if param in ("sensor_timeout",):
        return "fgloc integrates what arrives; fgloc live reports a silent sensor (health:)"
    if param in ("use_control", "stamped_control", "control_timeout", "control_config", "acceleration_limits",
                 "deceleration_limits", "acceleration_gains", "deceleration_gains"):
        return "fgloc has no control input"
    if param.startswith("transform_") or param in ("publish_tf", "publish_acceleration", "tf_prefix",
                                                   "permit_corrected_publication", "predict_to_current_time",
                                                   "silent_tf_failure", "reset_on_time_jump", "smooth_lagged_data",
                                                   "history_length"):
        return "an output / tf setting; fgloc writes the fused pose and, from the smoother, a smoothed trajectory"
    if param.startswith("debug") or param == "print_diagnostics":
        return "a debugging setting"
    if param in ("dynamic_process_noise_covariance", "use_control_input"):
        return "fgloc adapts each source's noise from its residuals instead"
    return "no fgloc equivalent"
