"""``fgloc config from-robot-localization`` / ``from-fuse`` / ``from-nav2``: port a ROS parameter file.

Usage::

    fgloc config from-robot-localization ekf.yaml -o fgloc.yaml [--node ekf_filter_node]
    fgloc config from-robot-localization robot.launch -o fgloc.yaml   # ROS 1 launch XML: + its static tfs
    fgloc config from-fuse fuse_params.yaml -o fgloc.yaml
    fgloc config from-nav2 nav2_params.yaml -o fgloc.yaml

The converted config is checked (``fgloc.config.parse_config``) and written with one comment
line per parameter that could not be carried over; the same lines are printed.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer


def convert_file(kind: str, path: Path, node: str | None = None) -> tuple[dict[str, Any], list[str], str]:
    """``(config sections, notes, YAML text)`` of a robot_localization (``kind='rl'``), fuse (``'fuse'``)
    or nav2 file."""
    import yaml

    from fgloc.config import parse_config
    from fgloc.config.loader import read_yaml
    from fgloc.errors import ConfigError
    from fgloc.porting import from_fuse, from_nav2, from_robot_localization
    from fgloc.porting.launch import is_launch_xml, read_launch

    tfs: list[dict[str, Any]] = []
    launch_notes: list[str] = []
    text = path.read_text(errors="replace") if path.is_file() else ""
    if is_launch_xml(path, text):  # a ROS 1 launch file: the node's params and the mounts it publishes
        data, tfs, launch_notes = read_launch(path, text)
    else:
        data = read_yaml(path)
    conv = {"rl": from_robot_localization, "fuse": from_fuse}.get(kind, from_nav2)
    try:
        cfg, notes = conv(data, node=node, source=str(path))
    except ConfigError:
        if kind == "fuse" or not _is_fuse(data):
            raise
        raise ConfigError(f"{path}: a fuse configuration (fuse_optimizers' sensor_models), not "
                          f"{'robot_localization' if kind == 'rl' else 'nav2 amcl'}'s: fgloc config from-fuse "
                          f"{path} converts it") from None
    notes += launch_notes
    if tfs:  # static_transform_publisher mounts: the logs recorded with this launch file lack them
        cfg.setdefault("sources", {})["static_transforms"] = tfs
    parse_config(cfg, source=f"{path} (converted)")  # every value must be a valid fgloc setting
    what = {"rl": "robot_localization", "fuse": "fuse"}.get(kind, "nav2 amcl")
    head = [f"fgloc config converted from {what} parameters: {path.name}"]
    head += [f"WARNING: {w}" for w in conversion_warnings(kind, cfg)]
    head += usage_notes(cfg)
    head += [f"not carried over: {n}" for n in notes]
    text = "\n".join(f"# {line}" for line in head) + "\n" + (yaml.safe_dump(cfg, sort_keys=False) if cfg else "{}\n")
    return cfg, notes, text


def _is_fuse(data: Any) -> bool:
    """Whether a parameter file holds a fuse optimizer's parameters (another converter's input)."""
    from fgloc.errors import ConfigError
    from fgloc.porting.common import find_params
    from fgloc.porting.fuse import looks_like_fuse

    try:
        find_params(data, looks_like_fuse)
    except ConfigError:
        return False
    return True


def _used(cfg: dict[str, Any]) -> set[str]:
    inputs = ((cfg.get("sources") or {}).get("inputs") or {}).values()
    return {c for s in inputs for c in (s.get("use") or ())}


def _moves(cfg: dict[str, Any]) -> bool:
    """Whether a converted r_l config has a source of translation (else it is an error: a typo or a
    sensor fgloc does not read left the robot without motion)."""
    return bool(_used(cfg) & {"x", "y", "vx", "vy"})


def conversion_warnings(kind: str, cfg: dict[str, Any]) -> list[str]:
    """What the converted config cannot do that the ROS node did: no source of heading left."""
    if kind not in ("rl", "fuse"):
        return []
    inputs = ((cfg.get("sources") or {}).get("inputs") or {}).values()
    used = _used(cfg)
    out = []
    if inputs and not used & {"yaw", "vyaw"}:
        out.append("no source of heading left: without scans and a map the heading is the first one")
    return out


def usage_notes(cfg: dict[str, Any]) -> list[str]:
    """How to use what was converted when a flag, not the config, picks it: AMCL's settings take
    effect with ``--frontend amcl`` (the default front-end is native)."""
    if "amcl" in (cfg.get("frontends") or {}):
        return ["frontends.amcl is used with --frontend amcl (fgloc run, fgloc live); the default front-end, "
                "native, does not read it"]
    return []


def _write(kind: str, path: Path, output: Path | None, node: str | None, force: bool) -> None:
    import sys

    from fgloc.errors import ConfigError
    from fgloc.io.outputs import write_text_output

    cfg, notes, text = convert_file(kind, path, node)
    for n in notes:
        print(f"not carried over: {n}")
    if kind in ("rl", "fuse") and not _moves(cfg):  # nothing written: a config that cannot move the robot
        why = [n for n in notes if "skipped" in n or "did you mean" in n or "not read by fgloc" in n]
        raise ConfigError(f"{path}: the converted config has no source of motion (no input fgloc reads gives x, y, "
                          "vx or vy)" + (f": {why[0]}" if why else "")
                          + (f" (and {len(why) - 1} more above)" if len(why) > 1 else ""))
    for w in conversion_warnings(kind, cfg):
        print(f"fgloc: warning: {path}: {w}", file=sys.stderr)
    if output is None:
        print(text, end="")
    else:
        write_text_output(output, text, force=force, what="config", command="config")
        print(f"wrote {output} ({len(notes)} parameter(s) not carried over)")
        for n in usage_notes(cfg):  # printed to stdout, the same line heads the YAML as a comment
            print(n)


def register(app: typer.Typer) -> None:
    group = next((g.typer_instance for g in app.registered_groups if g.name == "config"), None)
    if group is None:  # the config group is the architect's: create it if it is not there yet
        group = typer.Typer(help="The configuration.", no_args_is_help=True)
        app.add_typer(group, name="config")

    @group.command("from-robot-localization")
    def from_rl(
        params: Path = typer.Argument(..., help="robot_localization ekf/ukf parameter YAML (ROS 1 or ROS 2), or a "
                                      "ROS 1 launch file (its static_transform_publisher mounts are carried too)"),
        output: Path | None = typer.Option(None, "-o", "--output", help="fgloc config to write (default: print)"),
        node: str | None = typer.Option(None, "--node", help="which filter node, when the file has several"),
        force: bool = typer.Option(False, "--force", help="overwrite an existing file"),
    ) -> None:
        """Convert robot_localization parameters into an fgloc config (sources, noise, start)."""
        _write("rl", params, output, node, force)

    @group.command("from-fuse")
    def from_fuse_cmd(
        params: Path = typer.Argument(..., help="fuse parameter YAML (ROS 1 or ROS 2): a fixed-lag smoother's "
                                      "sensor_models, motion_models and publishers"),
        output: Path | None = typer.Option(None, "-o", "--output", help="fgloc config to write (default: print)"),
        node: str | None = typer.Option(None, "--node", help="which optimizer node, when the file has several"),
        force: bool = typer.Option(False, "--force", help="overwrite an existing file"),
    ) -> None:
        """Convert fuse (fuse_models) parameters into an fgloc config (sources, noise, start)."""
        _write("fuse", params, output, node, force)

    @group.command("from-nav2")
    def from_nav2_cmd(
        params: Path = typer.Argument(..., help="nav2 params YAML (its amcl: section) or a ROS 1 amcl YAML"),
        output: Path | None = typer.Option(None, "-o", "--output", help="fgloc config to write (default: print)"),
        node: str | None = typer.Option(None, "--node", help="the AMCL node's name, when not amcl"),
        force: bool = typer.Option(False, "--force", help="overwrite an existing file"),
    ) -> None:
        """Convert nav2's AMCL parameters into fgloc's AMCL front-end config."""
        _write("nav2", params, output, node, force)
