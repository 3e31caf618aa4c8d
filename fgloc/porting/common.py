"""Shared helpers of the parameter-file converters."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from fgloc.errors import ConfigError


def find_params(data: Any, looks_right: Callable[[Mapping[str, Any]], bool], node: str | None = None,
                source: str = "params") -> tuple[str, dict[str, Any], list[str]]:
    """The parameter mapping of one node in a ROS 1 (flat, or ``node: {params}``) or ROS 2
    (``node: {ros__parameters: {params}}``) file: ``(node name, params, other matching nodes)``.

    ``looks_right(mapping)`` says whether a mapping is the parameters looked for; ``node``
    picks one by name when several match (a dual-EKF file).
    """
    if not isinstance(data, Mapping):
        raise ConfigError(f"{source}: not a YAML mapping of parameters")
    found: list[tuple[str, dict[str, Any]]] = []

    def walk(name: str, d: Mapping[str, Any], depth: int) -> None:
        if depth > 4:
            return
        if "ros__parameters" in d and isinstance(d["ros__parameters"], Mapping):
            if looks_right(d["ros__parameters"]):
                found.append((name, dict(d["ros__parameters"])))
            return
        if looks_right(d):
            found.append((name, dict(d)))
            return
        for k, v in d.items():
            if isinstance(v, Mapping):
                walk(str(k) if not name else f"{name}/{k}", v, depth + 1)

    walk("", data, 0)
    if not found:
        raise ConfigError(f"{source}: no parameters of the expected node found")
    if node is not None:
        pick = [f for f in found if f[0].split("/")[-1] == node or f[0] == node]
        if not pick:
            raise ConfigError(f"{source}: no node {node!r} (found: {', '.join(n or '(top level)' for n, _ in found)})")
        name, params = pick[0]
    else:
        name, params = found[0]
    others = [n or "(top level)" for n, _ in found if n != name]
    return name or "(top level)", params, others


def as_bool(v: Any) -> bool:
    if isinstance(v, str):
        return v.strip().lower() in ("true", "t", "1", "yes")
    return bool(v)
