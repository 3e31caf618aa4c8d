"""PNG rendering of a built map with its trajectory (matplotlib Agg)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numba import njit

from fgloc.maps import OccupancyMap
from fgloc.types import FloatArray


def map_image(occ: OccupancyMap, max_px: int = 1200) -> tuple[FloatArray, tuple[float, float, float, float]]:
    """Grey levels of the map (occupied 0, free 1, unknown 0.75) at most ``max_px`` cells on a side:
    large maps are reduced block-wise (a block with an occupied cell is occupied, else free when
    it has a free cell), so that a 400 m building renders in megabytes, not gigabytes.  Returns the
    image and its extent (x0, x1, y0, y1) in metres."""
    h, w = occ.data.shape
    f = max(1, int(np.ceil(max(h, w) / max_px)))
    trinary = occ.mode == "trinary"
    img = _reduce(np.ascontiguousarray(occ.data), f, 100 if trinary else 50, 0 if trinary else 49)
    x0, _, y0, _ = occ.extent
    cell = occ.resolution * f
    rows, cols = int(np.shape(img)[0]), int(np.shape(img)[-1])
    return img, (float(x0), float(x0 + cols * cell), float(y0), float(y0 + rows * cell))


def _rgb(img: FloatArray) -> np.ndarray:
    """Grey levels as a uint8 RGB image (matplotlib then skips its float RGBA copies)."""
    g = np.round(np.asarray(img) * 255).astype(np.uint8)
    return np.repeat(g[:, :, None], 3, axis=2)


@njit(cache=True)
def _reduce(data, f, occ_min, free_max):  # pragma: no cover - compiled
    """Blocks of f x f cells: 0.0 if any is occupied (>= occ_min), 1.0 if any is free (0..free_max),
    else 0.75 (unknown)."""
    h, w = data.shape
    hh = (h + f - 1) // f
    ww = (w + f - 1) // f
    out = np.full((hh, ww), 0.75)
    for i in range(h):
        oi = i // f
        for j in range(w):
            v = data[i, j]
            oj = j // f
            if v >= occ_min:
                out[oi, oj] = 0.0
            elif v >= 0 and v <= free_max and out[oi, oj] != 0.0:
                out[oi, oj] = 1.0
    return out


def render_map_png(path: str | Path, occ: OccupancyMap, trajectory_xy: FloatArray | None = None,
                   title: str = "", loops: FloatArray | None = None, dpi: int = 110) -> Path:
    """Write ``path``: the map (occupied black, free white, unknown grey), path in blue,
    loop-closure edges (``(M, 2, 2)`` map-frame segments) in red."""
    fig, ax = _map_figure(occ, 1.0)
    if loops is not None and len(loops):
        for seg in loops:
            ax.plot(seg[:, 0], seg[:, 1], "-", color="tab:red", lw=0.4, alpha=0.5)
    if trajectory_xy is not None and len(trajectory_xy):
        ax.plot(trajectory_xy[:, 0], trajectory_xy[:, 1], "-", color="tab:blue", lw=0.6, alpha=0.8)
    return _save(fig, ax, path, title, 9, dpi)


def render_check_png(path: str | Path, occ: OccupancyMap, result, trajectory_xy: FloatArray | None = None,
                     title: str = "", dpi: int = 110) -> Path:
    """Write ``path``: the map with the self-check drawn on it (a :class:`fgloc.mapping.selfcheck.CheckResult`).

    Regions seen by several passes (or by the log) are outlined green when consistent, filled red
    when flagged, with the inconsistent scans as red arrows (own pose -> where they fit, 3x);
    change regions are boxed: orange "added" (objects not in the map), blue "removed" (map
    structure not seen)."""
    fig, ax = _map_figure(occ, 1.4)
    from matplotlib.patches import Rectangle

    from fgloc.geometry import compose

    if trajectory_xy is not None and len(trajectory_xy):
        ax.plot(trajectory_xy[:, 0], trajectory_xy[:, 1], "-", color="tab:blue", lw=0.4, alpha=0.5)
    for r in result.regions:
        if r.n_checked == 0:
            continue
        lo = r.center - 0.5 * r.size_m
        if r.flagged:
            ax.add_patch(Rectangle(tuple(lo), r.size_m, r.size_m, facecolor="red", alpha=0.30, edgecolor="red", lw=1.2))
        else:
            ax.add_patch(Rectangle(tuple(lo), r.size_m, r.size_m, fill=False, edgecolor="tab:green", lw=0.5,
                                   alpha=0.6))
    bad = [c for c in result.scans if c.status == "inconsistent"]
    if bad:
        p0 = np.array([c.pose for c in bad])
        p1 = np.array([compose(c.pose, np.array([3 * c.offset[0], 3 * c.offset[1], 3 * c.offset[2]])) for c in bad])
        ax.quiver(p0[:, 0], p0[:, 1], p1[:, 0] - p0[:, 0], p1[:, 1] - p0[:, 1], color="red", angles="xy",
                  scale_units="xy", scale=1.0, width=0.003)
    if len(result.added_xy):
        ax.plot(result.added_xy[:, 0], result.added_xy[:, 1], "s", color="tab:orange", ms=1.5)
    if len(result.removed_xy):
        ax.plot(result.removed_xy[:, 0], result.removed_xy[:, 1], "s", color="tab:cyan", ms=1.5)
    for c in result.changes:
        b = c.bbox
        ax.add_patch(Rectangle((b[0], b[1]), b[2] - b[0], b[3] - b[1], fill=False, lw=1.2,
                               edgecolor="tab:orange" if c.kind == "added" else "tab:cyan"))
    return _save(fig, ax, path, (title + "\n" if title else "") + _wrap(result.verdict, 110), 8, dpi)


def _map_figure(occ: OccupancyMap, margin_in: float) -> tuple[Any, Any]:
    """A matplotlib (Agg) figure and axes showing the map in metres, ``margin_in`` inches of
    height added for the title."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    img, (x0, x1, y0, y1) = map_image(occ)
    h, w = occ.data.shape
    scale = max(w, h) / 900.0
    fig, ax = plt.subplots(figsize=(max(4.0, w / 100 / max(scale, 1e-9) + 1), max(4.0, h / 100 / scale + margin_in)))
    ax.imshow(_rgb(img), origin="lower", extent=(x0, x1, y0, y1), interpolation="nearest")
    return fig, ax


def _save(fig: Any, ax: Any, path: str | Path, title: str, fontsize: float, dpi: int) -> Path:
    """Axis labels, equal aspect, the title (if any); write ``path`` (its folder made) and close."""
    import matplotlib.pyplot as plt

    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_aspect("equal")
    if title:
        ax.set_title(title, fontsize=fontsize)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path


def _wrap(text: str, width: int) -> str:
    import textwrap

    return "\n".join(textwrap.wrap(text, width))
