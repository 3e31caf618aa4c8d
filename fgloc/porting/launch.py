"""A ROS 1 launch file (``.launch`` / ``.test`` XML) read as the converters' input.

robot_localization and amcl users often keep the node's parameters in the launch file itself
(``<param>``, ``<rosparam param=...>`` and ``<rosparam>`` blocks inside the ``<node>``), beside
the ``static_transform_publisher`` nodes that publish the sensor mounts the recorded logs then
lack (r_l's own ``test1.bag``: the IMU mount).  :func:`read_launch` returns

* ``{node name: parameters}``, the layout of a ROS 1 parameter YAML, for
  :func:`~fgloc.porting.from_robot_localization` / :func:`~fgloc.porting.from_nav2` (``--node``
  picks one when several match);
* the ``static_transform_publisher`` nodes' (``tf`` / ``tf2_ros``) transforms on the robot as
  ``sources.static_transforms`` entries (:mod:`fgloc.frames.static`), each on the frame it is
  published from: a mount on the robot's base (``base_link``, ``base_footprint`` or a node's own
  name for it, robot_localization's ``base_link_frame`` / amcl's ``base_frame_id``, e.g.
  ``mustang_base``; the robot_localization converter carries its own over as
  ``sources.base_frame``) or a link of a chain to one (``base_link -> plate``);
* notes: what could not be read (a ``<rosparam command="load" file=...>``, transforms from or to
  a world frame such as ``odom -> wheel_odometry``).

``$(arg name)`` takes the ``<arg>``'s ``default`` / ``value``; other substitutions (``$(find
pkg)``, ``$(env ...)``) are left as they are.  Nothing is executed.
"""

from __future__ import annotations

import re
import shlex
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import yaml

from fgloc.errors import ConfigError
from fgloc.frames.static import ROBOT_FRAMES, entry_of_publisher_args
from fgloc.frames.tf import is_world_frame

PUBLISHERS = ("static_transform_publisher",)


def is_launch_xml(path: str | Path, text: str | None = None) -> bool:
    """A ROS 1 launch file: by its suffix, or XML whose root is ``<launch>``."""
    p = Path(path)
    if p.suffix.lower() in (".launch", ".test"):
        return True
    head = (text if text is not None else "")[:2000].lstrip()
    return head.startswith("<") and "<launch" in head


def _value(text: str, typ: str | None) -> Any:
    if typ == "str":
        return text
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError:
        return text


#: parameters naming a node's robot (body) frame: robot_localization's, amcl's
BASE_FRAME_PARAMS = ("base_link_frame", "base_frame_id")


def _robot_frames(root: ET.Element, sub: Any) -> tuple[str, ...]:
    """``base_link``, ``base_footprint`` and the robot frame any node names (``base_link_frame``...)."""
    out = list(ROBOT_FRAMES)
    for node in root.iter("node"):
        for p in node:
            if p.tag == "param" and p.get("name") in BASE_FRAME_PARAMS:
                v = sub(p.get("value") or p.text or "").strip().lstrip("/")
                if v and v not in out:
                    out.append(v)
    return tuple(out)


def read_launch(path: str | Path, text: str) -> tuple[dict[str, dict[str, Any]], list[dict[str, Any]], list[str]]:
    """``(node parameters, static transform entries, notes)`` of a ROS 1 launch file (module doc)."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError as e:
        raise ConfigError(f"{path}: launch file does not parse as XML ({e})") from None
    if root.tag != "launch":
        raise ConfigError(f"{path}: not a ROS 1 launch file (root element <{root.tag}>, expected <launch>)")
    args: dict[str, str] = {}
    for a in root.iter("arg"):
        v = a.get("value", a.get("default"))
        if a.get("name") and v is not None:
            args[a.get("name", "")] = v

    def sub(s: str) -> str:
        return re.sub(r"\$\(arg\s+([^)\s]+)\)", lambda m: args.get(m.group(1), m.group(0)), s)

    nodes: dict[str, dict[str, Any]] = {}
    tfs: list[dict[str, Any]] = []
    notes: list[str] = []
    robot = _robot_frames(root, sub)
    for node in root.iter("node"):
        typ = node.get("type", "")
        name = node.get("name") or typ or "node"
        if typ in PUBLISHERS:
            entry = entry_of_publisher_args(shlex.split(sub(node.get("args", ""))))
            if entry is None:
                notes.append(f"{name} ({typ}): arguments {node.get('args')!r} not read")
            elif is_world_frame(entry["parent"]) or is_world_frame(entry["child"]):
                notes.append(f"{name} ({typ}): {entry['parent']} -> {entry['child']} is not a sensor mount on "
                             "the robot; not carried over")
            else:  # a mount, or a link of a chain to one (base_footprint -> base_link, base_link -> plate)
                if entry["parent"] not in robot and entry["child"] not in robot:
                    notes.append(f"{name} ({typ}): {entry['parent']} -> {entry['child']}: carried over as a "
                                 "link of a chain to the robot's base frame (unused if none reaches it)")
                tfs.append(entry)
            continue
        params: dict[str, Any] = {}
        for p in node:
            if p.tag == "param" and p.get("name"):
                raw = p.get("value") or p.text or ""
                params[p.get("name", "")] = _value(sub(raw), p.get("type"))
            elif p.tag == "rosparam":
                if p.get("command", "load") != "load":
                    continue
                if p.get("file"):
                    notes.append(f"{name}: <rosparam file={p.get('file')!r}> not read (convert that file itself)")
                    continue
                val = _value(sub(p.text or ""), None)
                if p.get("param"):
                    params[p.get("param", "")] = val
                elif isinstance(val, dict):
                    params.update(val)
        if params:
            nodes[name] = params
    return nodes, tfs, notes
