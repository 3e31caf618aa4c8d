"""Writing YAML summaries (effective configs, metrics, scenario parameters) with numpy values."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import yaml


def yaml_ready(obj: Any) -> Any:
    """``obj`` with numpy scalars and arrays turned into plain Python, dict keys into strings."""
    if isinstance(obj, dict):
        return {str(k): yaml_ready(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [yaml_ready(v) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    return obj


def write_yaml(path: str | Path, obj: Any) -> Path:
    """Write ``obj`` (numpy values allowed) as block-style YAML, keys in insertion order."""
    path = Path(path)
    path.write_text(yaml.safe_dump(yaml_ready(obj), sort_keys=False))
    return path
