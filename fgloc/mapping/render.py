"""PNG rendering of a built map with its trajectory (matplotlib Agg)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fgloc.maps import OccupancyMap
from fgloc.types import FloatArray


def render_map_png(path: str | Path, occ: OccupancyMap, trajectory_xy: FloatArray | None = None,
                   title: str = "", loops: FloatArray | None = None, dpi: int = 110) -> Path:
    """Write ``path``: the map (occupied black, free white, unknown grey), path in blue,
    loop-closure edges (``(M, 2, 2)`` map-frame segments) in red."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    img = np.full(occ.data.shape, 0.75)
    img[occ.free] = 1.0
    img[occ.occupied] = 0.0
    x0, x1, y0, y1 = occ.extent
    h, w = occ.data.shape
    scale = max(w, h) / 900.0
    fig, ax = plt.subplots(figsize=(max(4.0, w / 100 / max(scale, 1e-9) * 1.0 + 1), max(4.0, h / 100 / scale + 1)))
    ax.imshow(img, cmap="gray", vmin=0, vmax=1, origin="lower", extent=(x0, x1, y0, y1), interpolation="nearest")
    if loops is not None and len(loops):
        for seg in loops:
            ax.plot(seg[:, 0], seg[:, 1], "-", color="tab:red", lw=0.4, alpha=0.5)
    if trajectory_xy is not None and len(trajectory_xy):
        ax.plot(trajectory_xy[:, 0], trajectory_xy[:, 1], "-", color="tab:blue", lw=0.6, alpha=0.8)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_aspect("equal")
    if title:
        ax.set_title(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path
