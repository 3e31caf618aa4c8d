"""fuse (fuse_optimizers' fixed-lag smoother / batch optimizer with fuse_models) parameters -> an fgloc config.

What carries over:

==========================================  ===============================================
fuse                                        fgloc
==========================================  ===============================================
``sensor_models`` of type                   ``sources.inputs.NAME`` (odometry): vx, vy, vyaw;
``fuse_models::Odometry2D`` (``topic``,     x, y, yaw as increments (``differential``)
``*_dimensions``, ``differential``)
``fuse_models::Imu2D``                      ``sources.inputs.NAME`` (imu): yaw, vyaw
``fuse_models::Pose2D``                     ``sources.inputs.NAME`` (pose): x, y, yaw
``fuse_models::Twist2D``                    ``sources.inputs.NAME`` (twist): vx, vy, vyaw
``Odometry2DPublisher``'s                   ``sources.base_frame``; a pose source's ``frame_id``
``base_link_frame_id``, ``world_frame_id``  (map or odom)
``Unicycle2D`` ``process_noise_diagonal``   ``ekf.q_xy`` (x, y), ``q_theta`` (yaw), ``q_v`` (vx,
(x y yaw vx vy vyaw ax ay, per second)      vy), ``q_w`` (vyaw)
``Unicycle2DIgnition`` ``initial_sigma``    ``pipeline.initial_sigma_xy_m`` / ``_yaw_deg``
==========================================  ===============================================

Everything else is one note line: accelerations, the optimizer's lag and rates, loss functions,
queue and throttle settings, the ignition's initial state (``--initial-pose`` says it on a map).
"""

from __future__ import annotations

import math
from typing import Any

from fgloc.porting.common import as_bool, find_params

#: fuse_models sensor types -> fgloc source types
SOURCE_TYPES = {"Odometry2D": "odometry", "Imu2D": "imu", "Pose2D": "pose", "Twist2D": "twist"}
#: a sensor's parameters read here (the others are noted)
READ = {"topic", "position_dimensions", "orientation_dimensions", "linear_velocity_dimensions",
        "angular_velocity_dimensions", "differential", "type", "motion_models", "ignition"}
#: the process noise's 8 variables (fuse_models::Unicycle2D)
NOISE8 = ("x", "y", "yaw", "vx", "vy", "vyaw", "ax", "ay")


def looks_like_fuse(d: Any) -> bool:
    """A fuse optimizer's parameters: ``sensor_models`` naming ``fuse_models::`` plugins."""
    if not isinstance(d, dict) or "sensor_models" not in d:
        return False
    return "fuse_models::" in str(d["sensor_models"]) or "motion_models" in d or "publishers" in d


def _models(v: Any) -> dict[str, dict[str, Any]]:
    """``{name: {type, ...}}`` of a ``sensor_models`` / ``motion_models`` / ``publishers`` value (a
    mapping, or ROS 1 fuse's list of ``{name, type}``)."""
    if isinstance(v, dict):
        return {str(k): dict(m) if isinstance(m, dict) else {"type": str(m)} for k, m in v.items()}
    if isinstance(v, list):
        return {str(m["name"]): dict(m) for m in v if isinstance(m, dict) and "name" in m}
    return {}


def _section(p: dict[str, Any], name: str) -> dict[str, Any]:
    """A model's own parameters: the mapping under its name beside ``sensor_models`` (none: ``{}``)."""
    v = p.get(name)
    return dict(v) if isinstance(v, dict) else {}


def _dims(p: dict[str, Any], key: str) -> list[str]:
    v = p.get(key) or []
    return [str(x).strip().lower() for x in ([v] if isinstance(v, str) else v)]


def from_fuse(data: Any, node: str | None = None, source: str = "fuse params") -> tuple[dict[str, Any], list[str]]:
    """``(fgloc config sections, notes)`` for a fuse parameter file (ROS 1 or 2)."""
    name, p, others = find_params(data, looks_like_fuse, node, source)
    notes: list[str] = []
    if others:
        notes.append(f"converted node {name}; not converted: {', '.join(others)} (pick one with --node)")
    sensors, motions, pubs = (_models(p.get(k)) for k in ("sensor_models", "motion_models", "publishers"))
    out: dict[str, Any] = {}
    world = "odom"
    for pname, spec in pubs.items():
        cfg = {**spec, **_section(p, pname)}
        if str(spec.get("type", "")).endswith("Odometry2DPublisher"):
            world = str(cfg.get("world_frame_id", "odom")).strip("/") or "odom"
            base = str(cfg.get("base_link_frame_id", "")).strip("/")
            if base:
                out.setdefault("sources", {})["base_frame"] = base
            notes.append(f"{pname}: fuse's output ({cfg.get('topic', 'odometry/filtered')}): a log that recorded it "
                         f"is the peer to compare with (fgloc eval OUT/trajectory.tum LOG:/"
                         f"{str(cfg.get('topic', 'odometry/filtered')).strip('/')} --align-start)")
        else:
            notes.append(f"{pname} ({spec.get('type')}): a publisher; fgloc writes its own outputs")
    inputs: dict[str, dict[str, Any]] = {}
    pipeline: dict[str, Any] = {}
    for sname, spec in sensors.items():
        cfg = {**spec, **_section(p, sname)}
        typ = str(cfg.get("type", "")).split("::")[-1]
        if typ == "Unicycle2DIgnition":
            sig = [float(x) for x in (cfg.get("initial_sigma") or [])]
            if len(sig) >= 3:
                pipeline["initial_sigma_xy_m"] = round(max(sig[0], sig[1]), 6)
                pipeline["initial_sigma_yaw_deg"] = round(math.degrees(sig[2]), 6)
            state = [float(x) for x in (cfg.get("initial_state") or [])]
            if len(state) >= 3 and any(state[:3]):
                notes.append(f"{sname}: initial_state {state[0]:g} {state[1]:g} {state[2]:g} rad: on a map, "
                             f"fgloc run --initial-pose {state[0]:g} {state[1]:g} {math.degrees(state[2]):g}")
            continue
        kind = SOURCE_TYPES.get(typ)
        if kind is None:
            notes.append(f"{sname} ({cfg.get('type')}): "
                         + ("fgloc does not fuse accelerations" if typ == "Acceleration2D" else "no fgloc equivalent"))
            continue
        topic = "/" + str(cfg.get("topic", sname)).strip("/")
        pos = [d for d in _dims(cfg, "position_dimensions") if d in ("x", "y")]
        yaw = ["yaw"] if "yaw" in _dims(cfg, "orientation_dimensions") else []
        vel = ["v" + d for d in _dims(cfg, "linear_velocity_dimensions") if d in ("x", "y")]
        vyaw = ["vyaw"] if "yaw" in _dims(cfg, "angular_velocity_dimensions") else []
        diff = as_bool(cfg.get("differential", False))
        if _dims(cfg, "linear_acceleration_dimensions"):
            notes.append(f"{sname}: linear_acceleration_dimensions not carried over (fgloc does not fuse "
                         "accelerations)")
        entry: dict[str, Any] = {"type": kind, "topic": topic}
        if kind == "odometry":
            pose = pos + yaw
            use = pose + [v for v in vel + vyaw if v[1:] not in pose]
            if pose and not diff:
                notes.append(f"{sname}: absolute {', '.join(pose)} of an odometry fused as its increments")
            diff = bool(pose)
        elif kind == "imu":
            use = yaw + vyaw
            diff = diff and bool(yaw)
        elif kind == "twist":
            use, diff = vel + vyaw, False
        else:
            use = pos + yaw
            entry["frame_id"] = "map" if world == "map" else "odom"
        if not use:
            notes.append(f"{sname}: contributes nothing fgloc can fuse; skipped")
            continue
        entry["use"] = use
        if diff:
            entry["differential"] = True
        first = next((n for n, e in inputs.items() if e["type"] == kind), None)
        if kind in ("odometry", "twist") and first is not None:
            notes.append(f"{sname} ({topic}): fgloc integrates one {kind} source, the first ({first})")
        inputs[sname] = entry
        frames = sorted(k for k in cfg if k not in READ and k.endswith("_frame"))
        rest = sorted(k for k in cfg if k not in READ and k not in frames)
        if frames:
            notes.append(f"{sname}: {', '.join(frames)}: fgloc turns each message from its own frame_id "
                         "through the log's tf (sources.static_transforms for a mount the log lacks)")
        if rest:
            notes.append(f"{sname}: {', '.join(rest)}: no fgloc equivalent (fgloc weighs each source by the noise "
                         "it shows; subscription settings are fgloc's own)")
    if inputs:
        out.setdefault("sources", {})["inputs"] = inputs
    ekf: dict[str, Any] = {}
    for mname, spec in motions.items():
        cfg = {**spec, **_section(p, mname)}
        q = [float(x) for x in (cfg.get("process_noise_diagonal") or [])]
        if str(cfg.get("type", "")).endswith("Unicycle2D") and len(q) == len(NOISE8):
            ekf.update({"q_xy": max(q[0], q[1]), "q_theta": q[2], "q_v": max(q[3], q[4]), "q_w": q[5]})
            notes.append(f"{mname}: process noise of ax, ay not carried over (fgloc's EKF has no acceleration)")
        else:
            notes.append(f"{mname} ({cfg.get('type')}): no fgloc equivalent")
    for k in ("lag_duration", "optimization_frequency", "transaction_timeout", "solver_options"):
        if k in p:
            notes.append(f"{k}: the optimizer's setting; fgloc's smoother is iSAM2 over every keyframe "
                         "(no lag window), its EKF a filter")
    if pipeline:
        out["pipeline"] = pipeline
    if ekf:
        out["ekf"] = ekf
    return out, notes
