"""Occupancy-grid maps in the ROS ``map_server`` format (YAML + PGM/PNG).

Conventions (as ``nav2_map_server`` / ``map_server``):

* ``data[row, col]`` is an ``nav_msgs/OccupancyGrid`` value: ``100`` occupied,
  ``0`` free, ``-1`` unknown (``scale`` mode gives 0..100, ``raw`` the pixel).
  Row 0 is the *bottom* of the map (smallest y), i.e. the image is flipped.
* Cell ``(row, col)`` has its centre at ``origin (+) ((col + 0.5) r, (row + 0.5) r)``
  where ``origin = [x, y, yaw]`` is the pose of the lower-left corner of the
  grid in the ``map`` frame and ``r`` the resolution in m/cell.
* Loading: ``p = (255 - v) / 255`` (``v / 255`` when ``negate``); ``p >
  occupied_thresh`` -> occupied, ``p < free_thresh`` -> free, else unknown.
  Saving writes what ``map_saver`` writes: occupied 0, free 254, unknown 205.
"""

from __future__ import annotations

import math
import re
import struct
import warnings
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np
import yaml
from numpy.typing import ArrayLike, NDArray

from fgloc.config.schema import load_yaml
from fgloc.errors import MapError, read_user_text
from fgloc.gridmath import raycast_grid

OCCUPIED = 100
FREE = 0
UNKNOWN = -1

FloatArray = NDArray[np.float64]


@dataclass
class OccupancyMap:
    """A 2-D occupancy grid with metric metadata.

    ``data``: int16 array ``(height, width)``, row 0 at the bottom (smallest y).
    ``resolution``: metres per cell. ``origin``: ``[x, y, yaw]`` of the grid's
    lower-left corner in the map frame.
    ``accuracy_m``: how well the map places its walls in the map frame (1 sigma, metres) beyond
    its rasterization: a map property the scans matched against it cannot see (a rasterized
    known world: 0; a SLAM map: the disagreement between its passes through a place, about half a
    cell).  ``None``: not declared (the native front-end then adds no floor).  Read from and
    written to the map YAML as ``accuracy_m`` (an fgloc extension; map_server and nav2 ignore unknown keys).
    """

    data: NDArray[np.int16]
    resolution: float
    origin: FloatArray = field(default_factory=lambda: np.zeros(3))
    occupied_thresh: float = 0.65
    free_thresh: float = 0.196
    negate: bool = False
    mode: str = "trinary"
    accuracy_m: float | None = None

    def __post_init__(self) -> None:
        self.data = np.asarray(self.data, dtype=np.int16)
        if self.data.ndim != 2 or self.data.size == 0:
            raise MapError(f"map grid must be a non-empty 2-D array, got shape {self.data.shape}")
        if not (np.isfinite(self.resolution) and self.resolution > 0):
            raise MapError(f"map resolution must be positive, got {self.resolution}")
        self.origin = np.asarray(self.origin, dtype=float).reshape(3)
        if self.accuracy_m is not None:
            self.accuracy_m = float(self.accuracy_m)
            if not (np.isfinite(self.accuracy_m) and self.accuracy_m >= 0):
                raise MapError(f"map accuracy_m must be a finite number >= 0, got {self.accuracy_m}")

    # ------------------------------------------------------------------ shape
    @property
    def height(self) -> int:
        return int(self.data.shape[0])

    @property
    def width(self) -> int:
        return int(self.data.shape[1])

    @property
    def occupied(self) -> NDArray[np.bool_]:
        """Boolean grid: cell is an obstacle (value > 50 in scale mode, == 100 in trinary)."""
        return self.occupied_mask(self.data)

    def occupied_mask(self, cells: NDArray) -> NDArray[np.bool_]:
        """Which of ``cells`` (values of this map's ``data``, e.g. some cells of it) are obstacles."""
        return cells >= 50 if self.mode != "trinary" else cells == OCCUPIED

    @property
    def free(self) -> NDArray[np.bool_]:
        return self.free_mask(self.data)

    def free_mask(self, cells: NDArray) -> NDArray[np.bool_]:
        """Which of ``cells`` (values of this map's ``data``, e.g. a window of it) are free."""
        return (cells >= 0) & (cells < 50) if self.mode != "trinary" else cells == FREE

    @property
    def unknown(self) -> NDArray[np.bool_]:
        return self.data < 0

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """``(xmin, xmax, ymin, ymax)`` of the grid in its own (origin-aligned) frame, offset by origin."""
        x0, y0 = self.origin[0], self.origin[1]
        return (x0, x0 + self.width * self.resolution, y0, y0 + self.height * self.resolution)

    # ------------------------------------------------------------ transforms
    def world_to_grid_continuous(self, points: ArrayLike) -> FloatArray:
        """Map-frame points ``(N, 2)`` -> continuous grid coordinates ``(N, 2)`` as (col, row).

        Cell ``(row, col)`` spans ``[col, col+1) x [row, row+1)`` in these units.
        """
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        c, s = np.cos(self.origin[2]), np.sin(self.origin[2])
        dx = p[:, 0] - self.origin[0]
        dy = p[:, 1] - self.origin[1]
        return np.column_stack([(c * dx + s * dy), (-s * dx + c * dy)]) / self.resolution

    def world_to_grid(self, points: ArrayLike) -> NDArray[np.int64]:
        """Map-frame points -> integer ``(row, col)`` indices ``(N, 2)`` (may be out of bounds)."""
        g = np.floor(self.world_to_grid_continuous(points)).astype(np.int64)
        return np.column_stack([g[:, 1], g[:, 0]])

    def grid_to_world(self, rows: ArrayLike, cols: ArrayLike) -> FloatArray:
        """Cell centres of ``(rows, cols)`` in the map frame, ``(N, 2)``."""
        r = (np.asarray(rows, dtype=float).reshape(-1) + 0.5) * self.resolution
        cc = (np.asarray(cols, dtype=float).reshape(-1) + 0.5) * self.resolution
        c, s = np.cos(self.origin[2]), np.sin(self.origin[2])
        return np.column_stack([self.origin[0] + c * cc - s * r, self.origin[1] + s * cc + c * r])

    def in_bounds(self, points: ArrayLike) -> NDArray[np.bool_]:
        rc = self.world_to_grid(points)
        return (rc[:, 0] >= 0) & (rc[:, 0] < self.height) & (rc[:, 1] >= 0) & (rc[:, 1] < self.width)

    def value_at(self, points: ArrayLike, outside: int = UNKNOWN) -> NDArray[np.int16]:
        """Grid value at map-frame points (``outside`` beyond the grid)."""
        rc = self.world_to_grid(points)
        ok = (rc[:, 0] >= 0) & (rc[:, 0] < self.height) & (rc[:, 1] >= 0) & (rc[:, 1] < self.width)
        out = np.full(len(rc), outside, dtype=np.int16)
        out[ok] = self.data[rc[ok, 0], rc[ok, 1]]
        return out

    def is_free(self, points: ArrayLike) -> NDArray[np.bool_]:
        return self.value_at(points) == FREE if self.mode == "trinary" else (
            (self.value_at(points) >= 0) & (self.value_at(points) < 50)
        )

    def free_cell_centers(self) -> FloatArray:
        """Map-frame centres of all free cells ``(N, 2)`` (for global localization)."""
        rows, cols = np.nonzero(self.free)
        return self.grid_to_world(rows, cols)

    def occupied_cell_centers(self) -> FloatArray:
        """Map-frame centres of all occupied cells ``(N, 2)``."""
        rows, cols = np.nonzero(self.occupied)
        return self.grid_to_world(rows, cols)

    # -------------------------------------------------------- distance field
    @cached_property
    def distance_field(self) -> NDArray[np.float64]:
        """Euclidean distance (m) from each cell centre to the nearest occupied cell centre.

        Occupied cells have distance 0. With no obstacle at all every cell gets +inf.
        """
        from scipy.ndimage import distance_transform_edt

        occ = self.occupied
        if not occ.any():
            return np.full(self.data.shape, np.inf)
        return distance_transform_edt(~occ) * self.resolution

    def distance_at(self, points: ArrayLike, outside: float = np.inf) -> FloatArray:
        """Bilinearly interpolated distance field (m) at map-frame points; ``outside`` off the grid."""
        g = self.world_to_grid_continuous(points) - 0.5  # cell centres at integer coordinates
        df = self.distance_field
        x, y = g[:, 0], g[:, 1]
        ok = (x >= 0) & (y >= 0) & (x <= self.width - 1) & (y <= self.height - 1)
        out = np.full(len(g), outside, dtype=float)
        if not ok.any():
            return out
        x, y = x[ok], y[ok]
        x0 = np.minimum(np.floor(x).astype(np.int64), self.width - 2 if self.width > 1 else 0)
        y0 = np.minimum(np.floor(y).astype(np.int64), self.height - 2 if self.height > 1 else 0)
        x1 = np.minimum(x0 + 1, self.width - 1)
        y1 = np.minimum(y0 + 1, self.height - 1)
        fx, fy = x - x0, y - y0
        out[ok] = (
            df[y0, x0] * (1 - fx) * (1 - fy)
            + df[y0, x1] * fx * (1 - fy)
            + df[y1, x0] * (1 - fx) * fy
            + df[y1, x1] * fx * fy
        )
        return out

    # ------------------------------------------------------------- raycasting
    def raycast(
        self,
        origins: ArrayLike,
        angles: ArrayLike,
        max_range: float,
        unknown_is_obstacle: bool = False,
    ) -> FloatArray:
        """Exact grid ray casting (Amanatides-Woo DDA, compiled with numba).

        ``origins``: ``(N, 2)`` map-frame ray starts (or one ``(2,)`` start for all);
        ``angles``: ``(N,)`` map-frame ray directions in radians.  Returns ``(N,)``
        ranges (m) to the boundary of the first occupied cell, ``+inf`` when nothing
        is hit within ``max_range`` or the ray leaves the grid.  A ray starting
        inside an occupied cell returns 0.
        """
        ang = np.asarray(angles, dtype=float).reshape(-1)
        org = np.asarray(origins, dtype=float)
        if org.ndim == 1:
            org = np.broadcast_to(org.reshape(1, 2), (len(ang), 2))
        g = self.world_to_grid_continuous(org)
        local = ang - self.origin[2]
        blocked = self.occupied | (self.unknown if unknown_is_obstacle else False)
        return raycast_grid(
            np.ascontiguousarray(blocked, dtype=np.bool_),
            np.ascontiguousarray(g[:, 0]),
            np.ascontiguousarray(g[:, 1]),
            np.cos(local),
            np.sin(local),
            float(max_range) / self.resolution,
        ) * self.resolution

    # ------------------------------------------------------------------- I/O
    @staticmethod
    def load(yaml_path: str | Path) -> OccupancyMap:
        """Load a map_server YAML and its image. Raises :class:`MapError` with a one-line reason."""
        return load_map(yaml_path)

    def save(self, yaml_path: str | Path, image_format: str = "pgm") -> Path:
        """Write ``yaml_path`` and its image (``pgm`` or ``png``) beside it, as map_saver does."""
        return save_map(self, yaml_path, image_format)

    def equals(self, other: OccupancyMap, atol: float = 1e-9) -> bool:
        return (
            self.data.shape == other.data.shape
            and bool(np.array_equal(self.data, other.data))
            and abs(self.resolution - other.resolution) <= atol
            and bool(np.allclose(self.origin, other.origin, atol=atol))
        )


# ---------------------------------------------------------------- map files
#: largest grid (cells) a map image may claim: 10,000 x 10,000 (500 m x 500 m at 5 cm); the
#: front-ends hold several float fields of this size (the native one at 2x resolution)
MAX_MAP_CELLS = 100_000_000

# what a malformed image makes PIL raise (besides its own errors): headers it cannot parse,
# truncated data, absurd sizes
_IMAGE_ERRORS = (OSError, SyntaxError, ValueError, EOFError, IndexError, TypeError, KeyError,
                 ZeroDivisionError, OverflowError, MemoryError, struct.error)


def _read_image(path: Path) -> NDArray[np.uint8]:
    from PIL import Image

    try:
        with warnings.catch_warnings():
            # PIL warns above ~89M pixels; the limit that matters here is MAX_MAP_CELLS
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            with Image.open(path) as im:
                w, h = im.size  # read from the header only: nothing decoded yet
                if w * h > MAX_MAP_CELLS:
                    raise MapError(f"{path}: map image claims {w} x {h} pixels, more than the "
                                   f"{MAX_MAP_CELLS:,} cells a map may have")
                im.load()
                if im.mode in ("RGB", "RGBA", "P", "LA", "PA", "RGBX", "CMYK", "YCbCr"):
                    # map_server averages the colour channels (alpha ignored)
                    arr = np.asarray(im.convert("RGB"), dtype=np.float64).mean(axis=2)
                    return np.round(arr).astype(np.uint8)
                if im.mode in ("I;16", "I;16B", "I;16L", "I", "F"):
                    arr = np.nan_to_num(np.asarray(im, dtype=np.float64), nan=0.0, posinf=0.0, neginf=0.0)
                    return np.round(np.clip(arr, 0.0, None) * 255.0 / max(float(arr.max()), 1.0)).astype(np.uint8)
                return np.asarray(im.convert("L"), dtype=np.uint8)
    except FileNotFoundError:
        raise MapError(f"{path}: map image not found") from None
    except Image.DecompressionBombError as e:  # PIL refuses sizes above 2x its own limit at open()
        m = re.search(r"\((\d+) pixels\)", str(e))
        claim = f"{int(m.group(1)):,} pixels" if m else "too many pixels"
        raise MapError(f"{path}: map image claims {claim}, more than the {MAX_MAP_CELLS:,} cells a map may have") \
            from None
    except _IMAGE_ERRORS as e:
        msg = " ".join(str(e).split())[:200]
        raise MapError(f"{path}: cannot read map image ({e.__class__.__name__}: {msg})") from None


#: the map file of the folder ``fgloc map -o FOLDER`` writes
MAP_FOLDER_FILE = "map.yaml"


def map_file(path: str | Path) -> Path:
    """The map_server YAML that ``path`` names: the path itself, or ``path/map.yaml`` when ``path``
    is a folder holding one (the folder ``fgloc map -o FOLDER`` writes)."""
    path = Path(path)
    inside = path / MAP_FOLDER_FILE
    return inside if path.is_dir() and inside.is_file() else path


def load_map(yaml_path: str | Path) -> OccupancyMap:
    """Load a ROS map_server map (a YAML file, or a folder holding ``map.yaml``: :func:`map_file`).
    Errors are :class:`MapError` naming the file and the problem."""
    yaml_path = map_file(yaml_path)
    text = read_user_text(yaml_path, "map file", MapError)
    try:
        meta = load_yaml(text)
    except yaml.YAMLError as e:
        line = getattr(getattr(e, "problem_mark", None), "line", None)
        where = f" at line {line + 1}" if line is not None else ""
        raise MapError(f"{yaml_path}: map YAML does not parse{where}") from None
    except (RecursionError, ValueError, TypeError, OverflowError) as e:  # e.g. absurdly deep nesting
        raise MapError(f"{yaml_path}: map YAML does not parse ({e.__class__.__name__})") from None
    if not isinstance(meta, dict):
        raise MapError(f"{yaml_path}: map YAML must be a mapping with image, resolution and origin")
    for key in ("image", "resolution", "origin"):
        if key not in meta:
            raise MapError(f"{yaml_path}: map YAML lacks required key '{key}'")
    try:
        resolution = float(meta["resolution"])
        origin = [float(v) for v in meta["origin"]]
        if len(origin) == 2:
            origin.append(0.0)
        if len(origin) != 3:
            raise ValueError("origin must have 3 numbers [x, y, yaw]")
        negate = bool(int(meta.get("negate", 0)))
        occ_t = float(meta.get("occupied_thresh", 0.65))
        free_t = float(meta.get("free_thresh", 0.196))
        mode = str(meta.get("mode", "trinary")).lower()
    except (TypeError, ValueError, OverflowError) as e:
        raise MapError(f"{yaml_path}: bad value in map YAML ({' '.join(str(e).split())[:200]})") from None
    if not (np.isfinite(resolution) and resolution > 0):
        raise MapError(f"{yaml_path}: resolution must be a positive number, got {meta['resolution']!r}")
    if not all(np.isfinite(origin)):
        raise MapError(f"{yaml_path}: origin must be finite numbers, got {meta['origin']!r}")
    if not (0.0 <= free_t <= occ_t <= 1.0):
        raise MapError(f"{yaml_path}: need 0 <= free_thresh <= occupied_thresh <= 1, got {free_t}, {occ_t}")
    if mode not in ("trinary", "scale", "raw"):
        raise MapError(f"{yaml_path}: unknown mode '{mode}' (trinary, scale or raw)")
    accuracy = meta.get("accuracy_m")
    if accuracy is not None:
        try:
            accuracy = float(accuracy)
        except (TypeError, ValueError, OverflowError):
            accuracy = math.nan
        if not (math.isfinite(accuracy) and accuracy >= 0):
            raise MapError(f"{yaml_path}: accuracy_m must be a number >= 0 (metres), got {meta['accuracy_m']!r}")
    image_path = Path(str(meta["image"]))
    if not image_path.is_absolute():
        image_path = yaml_path.parent / image_path
    pix = _read_image(image_path)
    grid = _pixels_to_grid(pix, negate, occ_t, free_t, mode)
    return OccupancyMap(
        data=np.flipud(grid),
        resolution=resolution,
        origin=np.array(origin),
        occupied_thresh=occ_t,
        free_thresh=free_t,
        negate=negate,
        mode=mode,
        accuracy_m=accuracy,
    )


def _pixels_to_grid(pix: NDArray[np.uint8], negate: bool, occ_t: float, free_t: float, mode: str) -> NDArray[np.int16]:
    if mode == "raw":
        return pix.astype(np.int16)
    p = pix.astype(np.float64) / 255.0
    occ = p if negate else 1.0 - p
    out = np.full(pix.shape, UNKNOWN, dtype=np.int16)
    out[occ > occ_t] = OCCUPIED
    out[occ < free_t] = FREE
    if mode == "scale":
        mid = (occ >= free_t) & (occ <= occ_t)
        if occ_t > free_t:
            out[mid] = np.round(99.0 * (occ[mid] - free_t) / (occ_t - free_t)).astype(np.int16)
    return out


#: PIL's name of each image format a map is written in
IMAGE_FORMATS = {"pgm": "PPM", "png": "PNG"}


def save_map(m: OccupancyMap, yaml_path: str | Path, image_format: str = "pgm") -> Path:
    """Write a map_server map (trinary: occupied 0, free 254, unknown 205)."""
    yaml_path = Path(yaml_path)
    if image_format not in IMAGE_FORMATS:
        raise MapError(f"{yaml_path}: image format must be pgm or png, got {image_format}")
    yaml_path.parent.mkdir(parents=True, exist_ok=True)
    image_path = yaml_path.with_suffix("." + image_format)
    write_map_files(m, yaml_path, image_path, image_path.name, image_format)
    return yaml_path


def write_map_files(m: OccupancyMap, yaml_path: Path, image_path: Path, image_name: str,
                    image_format: str = "pgm") -> None:
    """The map's YAML at ``yaml_path`` naming its image ``image_name``, and the image at ``image_path``
    (``pgm`` or ``png``, whatever the file's own name: a staged output's is ``NAME.partial``)."""
    from PIL import Image

    pix = np.full(m.data.shape, 205, dtype=np.uint8)
    pix[m.free] = 254
    pix[m.occupied] = 0
    Image.fromarray(np.flipud(pix), mode="L").save(image_path, format=IMAGE_FORMATS[image_format])
    meta = {
        "image": image_name,
        "mode": "trinary",
        "resolution": float(m.resolution),
        "origin": [float(v) for v in m.origin],
        "negate": 0,
        "occupied_thresh": 0.65,
        "free_thresh": 0.196,
    }
    if m.accuracy_m is not None:
        meta["accuracy_m"] = float(m.accuracy_m)
    yaml_path.write_text(yaml.safe_dump(meta, sort_keys=False))
