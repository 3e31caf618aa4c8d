"""Writing YAML summaries (effective configs, metrics, scenario parameters) with numpy values."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import yaml


def yaml_ready(obj: Any, leaf: Callable[[Any], Any] | None = None) -> Any:
    """``obj`` with numpy scalars and arrays turned into plain Python, dict keys into strings.

    ``leaf``: instead, each value that is not a dict, list, tuple or array goes through
    ``leaf`` (an array's items too), e.g. :func:`fgloc.view.feed.json_ready`'s rules."""
    t = type(obj)
    if t is int or t is str or t is float or t is bool or obj is None:  # most values: plain already
        return obj if leaf is None else leaf(obj)
    if isinstance(obj, dict):
        return {str(k): yaml_ready(v, leaf) for k, v in obj.items()}
    if isinstance(obj, _SEQUENCES):
        return [yaml_ready(v, leaf) for v in obj]
    if isinstance(obj, np.ndarray):
        return obj.tolist() if leaf is None else yaml_ready(obj.tolist(), leaf)
    if leaf is not None:
        return leaf(obj)
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


_SEQUENCES = (list, tuple)


def write_yaml(path: str | Path, obj: Any) -> Path:
    """Write ``obj`` (numpy values allowed) as block-style YAML, keys in insertion order."""
    path = Path(path)
    path.write_text(yaml.safe_dump(yaml_ready(obj), sort_keys=False))
    return path
