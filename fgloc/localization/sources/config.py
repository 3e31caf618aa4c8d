"""The ``sources:`` config section: :class:`SourcesConfig` and its checked form (:func:`parse_sources`).

Each source type (:data:`SOURCE_TYPES`) is declared by its handler module
(:class:`~fgloc.localization.sources.spec.SourceType`): a new type is a new module there and
one entry here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from fgloc.config.schema import setting, unknown_key_error
from fgloc.errors import ConfigError
from fgloc.localization.sources import imu, odometry, pose, twist
from fgloc.localization.sources.spec import POLICIES, TILT, SourceSpec, SourceType, fused_components

#: the source types by name (``sources.inputs.NAME.type``), in the order the errors list them
SOURCE_TYPES: dict[str, SourceType] = {t.name: t for t in (odometry.SOURCE, imu.SOURCE, pose.SOURCE, twist.SOURCE)}


@dataclass(frozen=True)
class SourcesConfig:
    """``sources:`` per-source inputs (see :mod:`fgloc.localization.sources`)."""

    inputs: dict = setting({}, "name -> {type: odometry|imu|pose|twist, topic, use: [x, y, yaw, vx, vy, vyaw], "
                           "differential, covariance: message|fixed|scaled|floor, sigmas, scale, gate, frame_id}; "
                           "empty: odom (/odom: vx, vy, vyaw) and imu (/imu: yaw, vyaw)")
    static_transforms: list[dict] = setting([], "mounts the log lacks: [{parent: base_link, child: imu_link, "
                                      "xyz: [x, y, z], rpy_deg: [roll, pitch, yaw] | xyzw: [qx, qy, qz, qw]}]; "
                                      "they win over the log's /tf_static (fgloc.frames.static)")
    base_frame: str = setting("", "the robot's base frame (REP 105; robot_localization's base_link_frame): the "
                              "sensors' mounts are the transforms from it; empty: the odometry's child_frame_id, "
                              "else base_link / base_footprint")
    level_by_imu: bool = setting(True, "the default layout (no inputs): the IMU's roll / pitch project the odometry's "
                                 "travel onto the horizontal plane (a ramp: v cos(pitch)) where its orientation "
                                 "carries them (a roll / pitch variance, if given, below the tilt bound's square) and "
                                 "the tilt is one a ground robot drives on (<= 30 deg); with inputs listed, an IMU's "
                                 "use: [..., roll, pitch] says it")


def parse_sources(cfg: SourcesConfig | dict | None, topics: Any = None, source: str = "config") -> list[SourceSpec]:
    """The sources of a ``sources:`` section (the default layout when it lists none); one-line
    :class:`ConfigError` naming the key for anything wrong.  ``topics`` renames the default
    layout's topics (``--odom-topic`` / ``--imu-topic``).  A dict is the section's ``inputs``."""
    inputs = (cfg.inputs if isinstance(cfg, SourcesConfig) else dict(cfg or {})) or {}
    if not inputs:
        level = cfg.level_by_imu if isinstance(cfg, SourcesConfig) else SourcesConfig.level_by_imu
        names = {"odom": "/odom", "imu": "/imu"}
        if isinstance(topics, dict):
            names.update({k: str(v) for k, v in topics.items() if k in names and v})
        elif topics is not None:
            names.update({k: str(getattr(topics, k)) for k in names if getattr(topics, k, None)})
        return [SourceSpec("odom", "odometry", names["odom"], SOURCE_TYPES["odometry"].default_use),
                SourceSpec("imu", "imu", names["imu"], SOURCE_TYPES["imu"].default_use + (TILT if level else ()))]
    out: list[SourceSpec] = []
    seen_topics: dict[str, str] = {}
    for name, d in inputs.items():
        where = f"{source}: sources.inputs.{name}"
        if not isinstance(d, dict):
            raise ConfigError(f"{where}: must be a mapping (type, topic, use, ...)")
        keys = ("type", "topic", "use", "differential", "covariance", "sigmas", "scale", "gate", "frame_id")
        unknown = set(d) - set(keys)
        if unknown:
            raise unknown_key_error(source, f"sources.inputs.{name}", sorted(unknown)[0], keys)
        typ = str(d.get("type", "")).lower()
        if typ not in SOURCE_TYPES:
            raise ConfigError(f"{where}.type: must be one of {', '.join(SOURCE_TYPES)}, got {d.get('type')!r}")
        kind = SOURCE_TYPES[typ]
        use = tuple(str(u).lower() for u in (d.get("use") or kind.default_use))
        allowed = kind.components
        bad = [u for u in use if u not in allowed]
        if bad:
            raise ConfigError(f"{where}.use: {bad[0]!r} is not one of {', '.join(allowed)}")
        if "roll" in allowed and (("roll" in use) != ("pitch" in use)):
            raise ConfigError(f"{where}.use: roll and pitch level the odometry together: use both or neither")
        pol = str(d.get("covariance", "message")).lower()
        if pol not in POLICIES:
            raise ConfigError(f"{where}.covariance: must be one of {', '.join(POLICIES)}, got {pol!r}")
        sig = tuple(float(s) for s in (d.get("sigmas") or ()))
        fused = fused_components(use)
        if pol in ("fixed", "floor") and len(sig) != len(fused):
            raise ConfigError(f"{where}.sigmas: {pol} needs one sigma per used component ({len(fused)}: "
                              f"{', '.join(fused)}), got {len(sig)}")
        if any(not (math.isfinite(s) and s > 0) for s in sig):
            raise ConfigError(f"{where}.sigmas: every sigma must be a positive number")
        gate = d.get("gate")
        if gate is not None and not (isinstance(gate, (int, float)) and gate > 0):
            raise ConfigError(f"{where}.gate: must be a positive number or null")
        topic = str(d.get("topic") or kind.default_topic)
        if topic in seen_topics:
            raise ConfigError(f"{where}.topic: {topic} is already source {seen_topics[topic]!r}")
        seen_topics[topic] = str(name)
        if d.get("differential") and not kind.differential:
            raise ConfigError(f"{where}.differential: a {typ} source has no poses whose increments it could use")
        out.append(SourceSpec(str(name), typ, topic, use, bool(d.get("differential", False)), pol, sig,
                              float(d.get("scale", 1.0)), None if gate is None else float(gate),
                              None if d.get("frame_id") is None else str(d["frame_id"])))
    return out


def source_topics(cfg: SourcesConfig | dict | None) -> dict[str, str]:
    """``{topic: type}`` of a ``sources:`` section's inputs (empty when it lists none: the
    default layout's topics are the command line's)."""
    inputs = (cfg.inputs if isinstance(cfg, SourcesConfig) else dict(cfg or {})) or {}
    if not inputs:
        return {}
    return {s.topic: s.type for s in parse_sources(cfg)}
