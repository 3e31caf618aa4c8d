"""The one fgloc configuration: every section composed, loaded from YAML, written back.

:class:`FglocConfig` holds one typed section per concern; each section class lives in
the module that uses it, with the only copy of its defaults.  ``load_config(path)``
overlays a user YAML file on the defaults and checks it (types, ranges, unknown keys and
section names with a "did you mean" suggestion): every problem is one
:class:`~fgloc.errors.ConfigError` line naming the file and the key.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import yaml

from fgloc.backends.ekf import EKFConfig
from fgloc.backends.smoother import BatchConfig, SmootherConfig
from fgloc.config.schema import load_yaml, parse, section, to_yaml
from fgloc.errors import ConfigError, read_user_text
from fgloc.frontends.factory import FrontendsConfig
from fgloc.live.config import HealthConfig, LaserConfig, RobotParams, SerialConfig
from fgloc.localization.config import PipelineConfig
from fgloc.localization.monitor import IntegrityConfig
from fgloc.localization.sources import SourcesConfig, parse_sources
from fgloc.ros2.config import Ros2Config


@dataclass(frozen=True)
class FglocConfig:
    """Everything ``fgloc run``, ``fgloc live``, ``fgloc bench`` and the library read."""

    pipeline: PipelineConfig = section(PipelineConfig, "the localizer: tracking, relocalization, odometry handling")
    sources: SourcesConfig = section(SourcesConfig, "per-source inputs, robot_localization style (odometry, IMU, "
                                     "pose topics and what each contributes)")
    integrity: IntegrityConfig = section(IntegrityConfig, "no jumps and a status for every pose: the jump gate and "
                                         "the consistency monitor")
    frontends: FrontendsConfig = section(FrontendsConfig, "scan-to-map front-ends (--frontend picks one)")
    ekf: EKFConfig = section(EKFConfig, "the paper's EKF back-end (--backend ekf), state [x, y, theta, v, w]")
    smoother: SmootherConfig = section(SmootherConfig, "the fixed-lag iSAM2 smoother (--backend smoother, the "
                                       "default); Pose2 keyframes at scan times")
    batch: BatchConfig = section(BatchConfig, "the batch smoother (--backend batch): the smoother's factors over "
                                 "the whole run, Levenberg-Marquardt at the end")
    robot: RobotParams = section(RobotParams, "fgloc live: the robot's drive geometry (wheel counts -> twist)")
    serial: SerialConfig = section(SerialConfig, "fgloc live: the STM32 serial link")
    laser: LaserConfig = section(LaserConfig, "fgloc live: the SICK laser")
    health: HealthConfig = section(HealthConfig, "fgloc live: sensor health monitoring")
    ros2: Ros2Config = section(Ros2Config, "fgloc live --ros2 / fgloc replay --ros2: a ROS 2 peer over DDS")


SECTIONS = tuple(f.name for f in fields(FglocConfig))

HEADER = """fgloc configuration.  Every key is listed with its default; keep only the keys you
change (the others keep their defaults).  Units are in the names (_m, _s, _deg, _hz);
angles are in degrees unless the key says rad.  Check a file with
`fgloc config show --config FILE`."""


def parse_config(data: Any, source: str = "config", base: FglocConfig | None = None) -> FglocConfig:
    """A :class:`FglocConfig` from a mapping of sections (as read from YAML), overlaid on ``base``."""
    if isinstance(data, FglocConfig):
        return data
    if data is None:
        return base or FglocConfig()
    if not isinstance(data, Mapping):
        raise ConfigError(f"{source}: config must be a mapping of sections ({', '.join(SECTIONS)})")
    for key in data:
        if key not in SECTIONS:
            from fgloc.config.schema import unknown_key_error

            raise unknown_key_error(source, "", str(key), SECTIONS, what="section")
    cfg = parse(FglocConfig, data, source=source, base=base)
    if data.get("sources"):
        check_sources(cfg.sources, source)
    return cfg


def check_sources(sources: SourcesConfig, source: str = "config") -> None:
    """The ``sources:`` section's entries checked when the config is read (a typo is an error
    naming the file then, not when a run starts): the parsers that use them raise the errors."""
    if sources.inputs:
        parse_sources(sources, source=source)
    if sources.static_transforms:
        from fgloc.frames.static import parse_static_transforms

        parse_static_transforms(sources.static_transforms, source=source)


def read_yaml(path: str | Path) -> Any:
    p = Path(path)
    text = read_user_text(p, "config file", ConfigError)
    try:
        return load_yaml(text)
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        problem = getattr(e, "problem", None) or (str(e) if mark is None else "")
        where += f" ({problem})" if problem else ""
        raise ConfigError(f"{p}: config does not parse as YAML{where}") from None


def load_config(path: str | Path | None = None, overrides: Mapping[str, Any] | None = None) -> FglocConfig:
    """The effective configuration: the defaults, overlaid with the YAML file ``path``, then ``overrides``."""
    cfg = FglocConfig()
    if path is not None:
        from fgloc.config import robot_config_path

        path = robot_config_path(path)  # a shipped robot's config by name (``--config husky``)
        cfg = parse_config(read_yaml(path), source=str(path), base=cfg)
    if overrides:
        cfg = parse_config(overrides, source="overrides", base=cfg)
    return cfg


def config_yaml(cfg: FglocConfig | None = None, comments: bool = True, header: str = HEADER) -> str:
    """``cfg`` (default: the defaults) as YAML, every key documented when ``comments``."""
    return to_yaml(cfg or FglocConfig(), comments=comments, header=header if comments else "")
