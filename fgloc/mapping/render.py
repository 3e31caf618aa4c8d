"""PNG rendering of a built map with its trajectory and self-check (Pillow)."""

from __future__ import annotations

from pathlib import Path

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
    loop-closure edges (``(M, 2, 2)`` map-frame segments) in red.  ``dpi`` is kept for callers;
    the image is drawn with Pillow at about 1000 pixels on the map's longer side."""
    canvas = _Canvas(occ, title)
    if loops is not None and len(loops):
        for seg in loops:
            canvas.polyline(seg, (214, 39, 40, 128), 1)
    if trajectory_xy is not None and len(trajectory_xy):
        canvas.polyline(trajectory_xy, (31, 119, 180, 204), 1)
    return canvas.save(path)


def render_check_png(path: str | Path, occ: OccupancyMap, result, trajectory_xy: FloatArray | None = None,
                     title: str = "", dpi: int = 110) -> Path:
    """Write ``path``: the map with the self-check drawn on it (a :class:`fgloc.mapping.selfcheck.CheckResult`).

    Regions seen by several passes (or by the log) are outlined green when consistent, filled red
    when flagged, with the inconsistent scans as red arrows (own pose -> where they fit, 3x);
    change regions are boxed: orange "added" (objects not in the map), blue "removed" (map
    structure not seen)."""
    from fgloc.geometry import compose

    canvas = _Canvas(occ, (title + "\n" if title else "") + result.verdict)
    if trajectory_xy is not None and len(trajectory_xy):
        canvas.polyline(trajectory_xy, (31, 119, 180, 128), 1)
    for r in result.regions:
        if r.n_checked == 0:
            continue
        lo = r.center - 0.5 * r.size_m
        box = (lo[0], lo[1], lo[0] + r.size_m, lo[1] + r.size_m)
        if r.flagged:
            canvas.rect(box, (255, 0, 0, 77), (255, 0, 0, 255), 2)
        else:
            canvas.rect(box, None, (44, 160, 44, 153), 1)
    for c in result.scans:
        if c.status == "inconsistent":
            p1 = compose(c.pose, np.array([3 * c.offset[0], 3 * c.offset[1], 3 * c.offset[2]]))
            canvas.arrow(np.asarray(c.pose[:2], dtype=float), np.asarray(p1[:2], dtype=float), (255, 0, 0, 255))
    for xy, color in ((result.added_xy, (255, 127, 14, 255)), (result.removed_xy, (23, 190, 207, 255))):
        for p in np.asarray(xy, dtype=float).reshape(-1, 2):
            canvas.dot(p, color, 1)
    for c in result.changes:  # a minor change (under change_significant_share of the returns) thin
        b = c.bbox
        canvas.rect((b[0], b[1], b[2], b[3]), None,
                    (255, 127, 14, 255) if c.kind == "added" else (23, 190, 207, 255), 2 if c.major else 1)
    return canvas.save(path)


def _nice_step(span: float, ticks: int = 6) -> float:
    """A 1-2-5 step giving about ``ticks`` intervals over ``span``."""
    raw = max(span, 1e-9) / ticks
    mag = 10.0 ** np.floor(np.log10(raw))
    return float(next((m * mag for m in (1.0, 2.0, 5.0, 10.0) if m * mag >= raw), 10.0 * mag))


def _tick(v: float, step: float) -> str:
    """A tick label: ``v`` on the step's grid (no "-0" or "1e-14" from the arange's rounding)."""
    return f"{round(v / step) * step + 0.0:g}"


class _Canvas:
    """The map drawn at about ``side_px`` pixels on its longer side with metre axes and a title;
    overlays in map coordinates (metres), blended onto it when saved.  Pillow only: matplotlib's
    import and first figure cost more than the rest of the map's writing (ACES: ~1 s of CPU)."""

    def __init__(self, occ: OccupancyMap, title: str, side_px: int = 1000):
        import textwrap

        from PIL import Image, ImageDraw, ImageFont

        img, (x0, x1, y0, y1) = map_image(occ)
        self.x0, self.y1 = x0, y1
        self.s = side_px / max(x1 - x0, y1 - y0, 1e-9)  # pixels per metre
        w = max(int(round((x1 - x0) * self.s)), 1)
        h = max(int(round((y1 - y0) * self.s)), 1)
        self.font = ImageFont.load_default(size=13)
        lines = [ln for part in title.split("\n") for ln in (textwrap.wrap(part, max(w // 7, 40)) or [""])] \
            if title else []
        self.left, self.top = 70, 12 + 17 * len(lines)
        W, H = self.left + w + 25, self.top + h + 45
        grey = np.flipud(np.round(np.asarray(img) * 255).astype(np.uint8))
        base = Image.new("RGB", (W, H), (255, 255, 255))
        base.paste(Image.fromarray(grey, "L").resize((w, h), Image.Resampling.NEAREST).convert("RGB"),
                   (self.left, self.top))
        d = ImageDraw.Draw(base)
        for i, ln in enumerate(lines):
            d.text((W / 2, 6 + 17 * i), ln, fill=(0, 0, 0), font=self.font, anchor="ma")
        d.rectangle((self.left - 1, self.top - 1, self.left + w, self.top + h), outline=(0, 0, 0))
        step = _nice_step(max(x1 - x0, y1 - y0))
        for v in np.arange(np.ceil(x0 / step) * step, x1 + 1e-9, step):
            u = self.left + (v - x0) * self.s
            d.line((u, self.top + h, u, self.top + h + 5), fill=(0, 0, 0))
            d.text((u, self.top + h + 7), _tick(v, step), fill=(0, 0, 0), font=self.font, anchor="ma")
        for v in np.arange(np.ceil(y0 / step) * step, y1 + 1e-9, step):
            q = self.top + (y1 - v) * self.s
            d.line((self.left - 6, q, self.left - 1, q), fill=(0, 0, 0))
            d.text((self.left - 8, q), _tick(v, step), fill=(0, 0, 0), font=self.font, anchor="rm")
        d.text((self.left + w / 2, self.top + h + 25), "x [m]", fill=(0, 0, 0), font=self.font, anchor="ma")
        d.text((8, self.top + h / 2), "y [m]", fill=(0, 0, 0), font=self.font, anchor="lm")
        self.base = base
        self.overlay = Image.new("RGBA", (W, H), (0, 0, 0, 0))
        self.draw = ImageDraw.Draw(self.overlay)

    def px(self, xy: FloatArray) -> list[tuple[float, float]]:
        p = np.asarray(xy, dtype=float).reshape(-1, 2)
        u = self.left + (p[:, 0] - self.x0) * self.s
        v = self.top + (self.y1 - p[:, 1]) * self.s
        return list(zip(u.tolist(), v.tolist(), strict=True))

    def polyline(self, xy: FloatArray, color: tuple[int, ...], width: int) -> None:
        pts = self.px(xy)
        if len(pts) >= 2:
            self.draw.line(pts, fill=color, width=width)

    def rect(self, box: tuple[float, float, float, float], fill: tuple[int, ...] | None,
             outline: tuple[int, ...], width: int) -> None:
        (u0, v1), (u1, v0) = self.px(np.array([[box[0], box[1]], [box[2], box[3]]]))
        self.draw.rectangle((u0, v0, u1, v1), fill=fill, outline=outline, width=width)

    def arrow(self, p0: FloatArray, p1: FloatArray, color: tuple[int, ...]) -> None:
        (a, b), (c, d) = self.px(np.array([p0, p1]))
        self.draw.line((a, b, c, d), fill=color, width=2)
        ang = np.arctan2(d - b, c - a)
        if np.hypot(c - a, d - b) > 1:
            head = [(c, d)] + [(c - 9 * np.cos(ang + s), d - 9 * np.sin(ang + s)) for s in (0.4, -0.4)]
            self.draw.polygon(head, fill=color)

    def dot(self, p: FloatArray, color: tuple[int, ...], r: float) -> None:
        ((u, v),) = self.px(p)
        self.draw.rectangle((u - r, v - r, u + r, v + r), fill=color)

    def save(self, path: str | Path) -> Path:
        from PIL import Image

        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        Image.alpha_composite(self.base.convert("RGBA"), self.overlay).convert("RGB").save(path)
        return path
