"""PNG plots like the paper's figures 6-10 (matplotlib, Agg canvas, no pyplot state).

* ``path.png``          -- x-y path of each estimate vs the reference (fig. 6), equal axes,
  optionally over the occupancy map and with the front-end fixes as dots;
* ``heading.png``       -- heading vs time, estimates and reference, degrees (fig. 7);
* ``x_error.png``, ``y_error.png`` -- x / y error vs time (figs. 8, 9);
* ``heading_error.png`` -- wrapped heading error vs time (fig. 10);
* ``track_error.png``   -- along-track and cross-track error vs time;
* ``overview.png``      -- all of the above on one page.

Errors are estimate minus reference, associated as in :mod:`fgloc.eval.metrics`.
Time axes are seconds since the reference's first stamp.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
from matplotlib.axes import Axes  # noqa: E402
from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.transforms import Affine2D  # noqa: E402

from fgloc.eval.metrics import DEFAULT_MAX_GAP_S, ErrorSeries, error_series  # noqa: E402
from fgloc.maps import OccupancyMap  # noqa: E402
from fgloc.types import Trajectory  # noqa: E402

REF_STYLE: dict[str, Any] = {"color": "black", "linestyle": "--", "linewidth": 1.2, "label": "reference"}
COLORS = ["tab:blue", "tab:red", "tab:green", "tab:orange", "tab:purple", "tab:brown"]
DPI = 120


def _as_dict(est: Trajectory | Mapping[str, Trajectory], label: str) -> dict[str, Trajectory]:
    if isinstance(est, Trajectory):
        return {label: est}
    return dict(est)


def _map_underlay(ax: Axes, occ_map: OccupancyMap) -> None:
    img = np.full(occ_map.data.shape, 205, dtype=np.uint8)
    img[occ_map.free] = 254
    img[occ_map.occupied] = 0
    w, h = occ_map.width * occ_map.resolution, occ_map.height * occ_map.resolution
    ox, oy, oyaw = (float(v) for v in occ_map.origin)
    tr = Affine2D().rotate(oyaw).translate(ox, oy) + ax.transData
    ax.imshow(
        img, cmap="gray", vmin=0, vmax=255, origin="lower", extent=(0.0, w, 0.0, h),
        interpolation="nearest", transform=tr, zorder=0,
    )


def _unwrapped_deg(yaw: np.ndarray) -> np.ndarray:
    return np.degrees(np.unwrap(yaw))


def _t0(gt: Trajectory) -> float:
    return float(gt.stamps[0])


def plot_path(
    ax: Axes,
    ests: Mapping[str, Trajectory],
    gt: Trajectory | None,
    fixes: Trajectory | None = None,
    occ_map: OccupancyMap | None = None,
) -> None:
    """x-y path of each estimate vs the reference (equal axes, metres)."""
    pts = [t.poses[:, :2] for t in ests.values()]
    if gt is not None:
        pts.append(gt.poses[:, :2])
    allp = np.vstack(pts)
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    margin = max(1.0, 0.05 * float(np.max(hi - lo)))
    if occ_map is not None:
        _map_underlay(ax, occ_map)
    if gt is not None:
        ax.plot(gt.poses[:, 0], gt.poses[:, 1], zorder=2, **REF_STYLE)
        ax.plot(gt.poses[0, 0], gt.poses[0, 1], "k^", markersize=8, zorder=4, label="start")
    if fixes is not None and len(fixes):
        ax.plot(fixes.poses[:, 0], fixes.poses[:, 1], ".", color="tab:gray", markersize=2.5,
                alpha=0.7, zorder=1, label=f"front-end fixes ({len(fixes)})")
    for k, (name, tr) in enumerate(ests.items()):
        ax.plot(tr.poses[:, 0], tr.poses[:, 1], color=COLORS[k % len(COLORS)], linewidth=1.0,
                zorder=3, label=name)
    ax.set_xlim(lo[0] - margin, hi[0] + margin)
    ax.set_ylim(lo[1] - margin, hi[1] + margin)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title("Position: path vs reference")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small")


def plot_heading(ax: Axes, ests: Mapping[str, Trajectory], gt: Trajectory | None) -> None:
    """Heading (degrees, unwrapped) vs time of each estimate and the reference."""
    t0 = _t0(gt) if gt is not None else min(float(t.stamps[0]) for t in ests.values())
    if gt is not None:
        gdeg = _unwrapped_deg(gt.poses[:, 2])
        ax.plot(gt.stamps - t0, gdeg, **REF_STYLE)
    for k, (name, tr) in enumerate(ests.items()):
        edeg = _unwrapped_deg(tr.poses[:, 2])
        if gt is not None:  # same branch of the unwrapping as the reference at the first stamp
            ref0 = float(np.interp(tr.stamps[0], gt.stamps, gdeg))
            edeg = edeg + 360.0 * np.round((ref0 - edeg[0]) / 360.0)
        ax.plot(tr.stamps - t0, edeg, color=COLORS[k % len(COLORS)], linewidth=1.0, label=name)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("heading [deg]")
    ax.set_title("Heading vs time")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small")


def _plot_error(
    ax: Axes,
    series: Mapping[str, ErrorSeries],
    t0: float,
    get: Callable[[ErrorSeries], np.ndarray],
    ylabel: str,
    title: str,
) -> None:
    for k, (name, s) in enumerate(series.items()):
        ax.plot(s.t - t0, get(s), color=COLORS[k % len(COLORS)], linewidth=0.9, label=name)
    ax.axhline(0.0, color="black", linewidth=0.6)
    ax.set_xlabel("time [s]")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small")


def plot_x_error(ax: Axes, series: Mapping[str, ErrorSeries], t0: float) -> None:
    _plot_error(ax, series, t0, lambda s: s.ex, "x error [m]", "x error vs time (estimate - reference)")


def plot_y_error(ax: Axes, series: Mapping[str, ErrorSeries], t0: float) -> None:
    _plot_error(ax, series, t0, lambda s: s.ey, "y error [m]", "y error vs time (estimate - reference)")


def plot_heading_error(ax: Axes, series: Mapping[str, ErrorSeries], t0: float) -> None:
    _plot_error(ax, series, t0, lambda s: np.degrees(s.eyaw), "heading error [deg]",
                "Heading error vs time (wrapped)")


def plot_track_error(ax: Axes, series: Mapping[str, ErrorSeries], t0: float) -> None:
    """Along-track (solid) and cross-track (dotted) error vs time."""
    for k, (name, s) in enumerate(series.items()):
        c = COLORS[k % len(COLORS)]
        ax.plot(s.t - t0, s.along, color=c, linewidth=0.9, label=f"{name} along-track")
        ax.plot(s.t - t0, s.cross, color=c, linewidth=0.9, linestyle=":", label=f"{name} cross-track")
    ax.axhline(0.0, color="black", linewidth=0.6)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("error [m]")
    ax.set_title("Along-track / cross-track error vs time")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small")


def _save(fig: Figure, path: Path) -> Path:
    FigureCanvasAgg(fig)
    fig.savefig(path, dpi=DPI)
    return path


#: the figures :func:`plot_all` writes, ``{prefix}{name}.png``
PLOT_NAMES = ("path", "heading", "x_error", "y_error", "heading_error", "track_error", "overview")


def plot_files(prefix: str = "") -> list[str]:
    """The file names :func:`plot_all` writes with this prefix."""
    return [f"{prefix}{name}.png" for name in PLOT_NAMES]


def plot_all(
    est: Trajectory | Mapping[str, Trajectory],
    gt: Trajectory,
    outdir: str | Path,
    fixes: Trajectory | None = None,
    occ_map: OccupancyMap | None = None,
    label: str = "estimate",
    prefix: str = "",
    max_gap: float = DEFAULT_MAX_GAP_S,
    title: str | None = None,
) -> list[Path]:
    """Write the figures (see the module doc) into ``outdir``; returns the files written.

    ``est`` is one trajectory (named ``label``) or a dict ``label -> Trajectory`` drawn
    on the same axes (e.g. EKF and smoother).  ``fixes`` (front-end poses) are drawn as
    dots on the path plot, over ``occ_map`` when given.  File names start with ``prefix``.
    Raises :class:`fgloc.eval.metrics.AssociationError` when an estimate does not
    overlap the reference.
    """
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    ests = _as_dict(est, label)
    series = {name: error_series(tr, gt, max_gap=max_gap) for name, tr in ests.items()}
    t0 = _t0(gt)
    files: list[Path] = []

    def single(name: str, draw: Callable[[Axes], None], size: tuple[float, float] = (8.0, 4.5)) -> None:
        fig = Figure(figsize=size, layout="constrained")
        draw(fig.add_subplot(1, 1, 1))
        files.append(_save(fig, out / f"{prefix}{name}.png"))

    single("path", lambda ax: plot_path(ax, ests, gt, fixes, occ_map), size=(8.0, 7.0))
    single("heading", lambda ax: plot_heading(ax, ests, gt))
    single("x_error", lambda ax: plot_x_error(ax, series, t0))
    single("y_error", lambda ax: plot_y_error(ax, series, t0))
    single("heading_error", lambda ax: plot_heading_error(ax, series, t0))
    single("track_error", lambda ax: plot_track_error(ax, series, t0))

    fig = Figure(figsize=(16.0, 10.0), layout="constrained")
    axs = fig.subplots(2, 3)
    plot_path(axs[0, 0], ests, gt, fixes, occ_map)
    plot_heading(axs[0, 1], ests, gt)
    plot_heading_error(axs[0, 2], series, t0)
    plot_x_error(axs[1, 0], series, t0)
    plot_y_error(axs[1, 1], series, t0)
    plot_track_error(axs[1, 2], series, t0)
    fig.suptitle(title or "fgloc evaluation: " + ", ".join(ests) + " vs reference")
    files.append(_save(fig, out / f"{prefix}overview.png"))
    return files
