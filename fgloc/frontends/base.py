"""The scan-to-map front-end interface and the scan preprocessing all front-ends share.

A front-end takes a :class:`~fgloc.types.LaserScan` (laser frame), a prior guess of
the ``base_link`` pose in ``map`` (``[x_m, y_m, yaw_rad]``) and optionally the
odometry motion since the previous call (``odom_delta``, base frame,
``between(prev_odom, cur_odom)``) and returns a :class:`MatchResult`: the
``base_link`` pose in ``map`` *at the scan stamp* (REP 117: the stamp is the time of
the first beam), its 3x3 covariance over ``[x, y, yaw]``, a quality score in
``[0, 1]``, or ``ok=False`` with a human-readable ``reason``.

Front-ends never raise on bad input: scans full of NaN/inf/zero ranges, too few
valid beams, a guess off the map or in unknown space all give "no fix" with a
reason (:class:`FrontendBase` turns any unexpected exception into a no-fix too).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from fgloc.config.schema import setting
from fgloc.errors import ConfigError
from fgloc.geometry import YAW, X, Y, exp_along, wrap_scalar
from fgloc.geometry import log as se2_log
from fgloc.gridmath import njit
from fgloc.maps import OccupancyMap
from fgloc.types import LaserScan, PoseFix, StaticTransform, all_finite

FloatArray = NDArray[np.float64]

__all__ = [
    "MatchResult",
    "ScanMatcher",
    "FrontendBase",
    "PreprocessOptions",
    "ScanPreprocessor",
    "no_fix",
    "check_guess",
    "on_grid",
    "deskew_offsets",
    "voxel_downsample",
    "FixAcceptance",
    "registration_sigma",
    "grid_cell",
]


@dataclass
class MatchResult:
    """The answer of a front-end.

    ``pose``: ``base_link`` in ``map`` ``[x_m, y_m, yaw_rad]`` at the scan stamp (None if
    no fix); ``cov``: 3x3 covariance of ``[x, y, yaw]`` in the map frame (m^2, rad^2);
    ``quality`` in ``[0, 1]`` (front-end specific: inlier fraction or similar);
    ``reason``: why there is no fix (empty when ``ok``); ``n_inliers``: beams that agreed.
    """

    ok: bool
    pose: FloatArray | None
    cov: FloatArray | None
    quality: float = 0.0
    reason: str = ""
    n_inliers: int = 0
    info: dict[str, Any] = field(default_factory=dict, repr=False)  # diagnostics (timings, iterations)

    def to_fix(self, stamp: float, source: str) -> PoseFix | None:
        """The fix as a :class:`~fgloc.types.PoseFix` (map frame), or None unless ok and finite."""
        if not self.ok or self.pose is None or self.cov is None:
            return None
        pose = np.asarray(self.pose, dtype=float)
        cov = np.asarray(self.cov, dtype=float)
        if not all_finite(pose, cov):
            return None
        return PoseFix(float(stamp), pose, cov, quality=float(self.quality), source=source)

    @property
    def why(self) -> str:
        """The no-fix reason (empty for a fix)."""
        return "" if self.ok else (self.reason or "no fix")


def no_fix(reason: str, n_inliers: int = 0, quality: float = 0.0, **info: Any) -> MatchResult:
    """A "no fix" result with its reason."""
    return MatchResult(False, None, None, quality=quality, reason=reason, n_inliers=n_inliers, info=dict(info))


@runtime_checkable
class ScanMatcher(Protocol):
    """What the pipeline calls. ``name`` identifies the front-end (``native``, ``kiss``, ``amcl``)."""

    name: str
    is_particle_filter: bool  # see FrontendBase
    supports_global: bool

    def match(
        self, scan: LaserScan, guess: np.ndarray, odom_delta: np.ndarray | None = None
    ) -> MatchResult: ...

    def reset(self, pose: np.ndarray | None = None) -> None:
        """Forget internal state; ``pose`` re-initialises, ``None`` = global localization (AMCL)."""
        ...


# ------------------------------------------------------------------ preprocessing
@dataclass(frozen=True)
class PreprocessOptions:
    """``frontends.<name>.preprocess``: the scan preprocessing every front-end shares.

    De-skew undoes motion distortion per beam when ``time_increment != 0`` (negative: the
    beams are listed against the sweep, REP 117 timing still holds) and the odometry motion
    since the last call is given.  With ``deskew_extrapolate`` the twist during the scan is
    extrapolated linearly from the last two odometry intervals to the middle of the sweep
    (accelerating robots: the last interval ends where the scan starts).
    """

    max_beams: int = setting(0, "keep at most N valid beams by uniform striding (0 = all)", min=0)
    voxel_size_m: float = setting(0.0, "2-D voxel downsampling of the base-frame points (0 = off)", min=0)
    deskew: bool = setting(True, "per-beam motion de-skew from the odometry motion since the previous scan")
    min_valid_beams: int = setting(10, "fewer valid (finite, inside [range_min, range_max]) beams -> no fix", min=1)
    max_deskew_interval_s: float = setting(0.5, "a longer gap since the previous scan -> that scan is not "
                                           "de-skewed (constant velocity would not hold)", min=0)
    deskew_extrapolate: bool = setting(True, "extrapolate the twist to the middle of the sweep from the last two "
                                       "odometry intervals (false: hold the last interval's mean twist)")

    def __post_init__(self) -> None:
        if self.max_beams < 0 or self.voxel_size_m < 0 or self.min_valid_beams < 1:
            raise ConfigError(
                f"preprocess: max_beams >= 0, voxel_size_m >= 0, min_valid_beams >= 1 required, got "
                f"{self.max_beams}, {self.voxel_size_m}, {self.min_valid_beams}"
            )


def deskew_offsets(
    n_beams: int, time_increment: float, odom_delta: FloatArray, interval_s: float
) -> FloatArray:
    """Per-beam pose of ``base_link`` at beam ``i`` relative to the first beam, ``(n, 3)``.

    Constant-velocity model: the robot moved by ``odom_delta`` (base frame) over the
    last ``interval_s`` seconds and keeps that twist during the scan; beam ``i`` was
    measured ``i * time_increment`` after the first beam (REP 117).
    """
    twist = se2_log(np.asarray(odom_delta, dtype=float)) / float(interval_s)
    return deskew_offsets_twist(n_beams, time_increment, twist)


def deskew_offsets_twist(n_beams: int, time_increment: float, twist: FloatArray) -> FloatArray:
    """Per-beam pose relative to the first beam for a constant body ``twist`` [vx, vy, wz]."""
    tau = np.arange(n_beams, dtype=float) * float(time_increment)
    return exp_along(np.asarray(twist, dtype=float), tau)


def voxel_downsample(points: FloatArray, voxel_size: float) -> FloatArray:
    """Keep the first point of each ``voxel_size`` square (stable order)."""
    if voxel_size <= 0 or len(points) == 0:
        return points
    keys = np.floor(points / voxel_size).astype(np.int64)
    _, first = np.unique(keys, axis=0, return_index=True)
    return points[np.sort(first)]


class ScanPreprocessor:
    """Valid beams -> (de-skewed) points in ``base_link`` at the scan stamp.

    State: the stamp of the previous call (the time base of ``odom_delta``) and the
    previous interval's twist (for the acceleration-aware extrapolation).
    Returns ``(points, "")`` or ``(None, reason)``; never raises on a bad scan.

    What depends only on the scan layout (the beams' angles with their cosines and sines) is
    computed once per layout and reused; per scan one compiled pass over the ranges gathers and
    transforms the valid beams (:func:`_beam_points`, with each used beam's time for the de-skew)
    and one more de-skews them (:func:`_deskew_apply`): the same operations on the same values,
    each rounded as numpy's array code over the full sweep rounds it (no fused multiply-add), so
    the same points, bit for bit; the beams' rotation during the sweep takes the C library's cosines
    and sines, which numpy's float64 ``cos`` and ``sin`` are.
    """

    def __init__(self, laser_mount: StaticTransform | np.ndarray | None, options: PreprocessOptions | None = None):
        if laser_mount is None:
            mount = np.zeros(3)
        elif isinstance(laser_mount, StaticTransform):
            mount = np.asarray(laser_mount.pose, dtype=float).reshape(3)
        else:
            mount = np.asarray(laser_mount, dtype=float).reshape(3)
        self.mount: FloatArray = mount
        # transform_points' coefficients (numpy's cos / sin of the mount yaw, as it computes them)
        self._mount_cs = (mount[X], mount[Y], np.cos(mount[YAW]), np.sin(mount[YAW]))
        self.options = options or PreprocessOptions()
        self._last_stamp: float | None = None
        self._last_twist: tuple[float, tuple[float, float, float]] | None = None  # (mid-interval time, twist)
        self._layout: tuple[int, float, float] | None = None  # (beams, angle_min, angle_increment)
        self._cos: FloatArray = np.zeros(0)
        self._sin: FloatArray = np.zeros(0)

    def reset(self) -> None:
        self._last_stamp = None
        self._last_twist = None

    def _trig(self, n: int, a0: float, da: float) -> tuple[FloatArray, FloatArray]:
        """``cos`` and ``sin`` of every beam's angle ``a0 + da * i`` (cached per layout)."""
        key = (n, a0, da)
        if key != self._layout:
            beams = np.arange(n)
            ang = a0 + da * beams
            self._cos, self._sin = np.cos(ang), np.sin(ang)
            self._layout = key
        return self._cos, self._sin

    def __call__(
        self, scan: LaserScan, odom_delta: np.ndarray | None = None
    ) -> tuple[FloatArray | None, str]:
        opt = self.options
        try:
            ranges = scan.ranges
            if not (isinstance(ranges, np.ndarray) and ranges.ndim == 1 and ranges.dtype in _RANGE_DTYPES):
                ranges = np.asarray(ranges, dtype=float).reshape(-1)
            stamp = float(scan.stamp)
            a0, da = float(scan.angle_min), float(scan.angle_increment)
            rmin, rmax = float(scan.range_min), float(scan.range_max)
            t_inc = float(scan.time_increment or 0.0)
        except (TypeError, ValueError, AttributeError) as e:
            return None, f"malformed scan ({e.__class__.__name__}: {e})"
        prev, self._last_stamp = self._last_stamp, stamp if math.isfinite(stamp) else None
        if not (math.isfinite(a0) and math.isfinite(da)):
            return None, "scan angles are not finite"
        n = len(ranges)
        if n == 0:
            return None, "empty scan"
        if n > 1 and da == 0.0:
            return None, "angle_increment 0 (the beams have no directions)"
        if not math.isfinite(rmin):
            rmin = 0.0
        if not (math.isfinite(rmax) and rmax > 0):
            rmax = math.inf
        cos_a, sin_a = self._trig(n, a0, da)
        deskew = opt.deskew and t_inc != 0 and math.isfinite(t_inc)
        # valid beams (finite, > 0, inside [rmin, rmax]), strided to max_beams, in base_link; one pass
        # in compiled code over the ranges as they came (float32 or float64)
        mx, my, mc, ms = self._mount_cs
        pts, tau_used, m = _beam_points(np.ascontiguousarray(ranges), rmin, rmax, opt.min_valid_beams, opt.max_beams,
                                        cos_a, sin_a, t_inc if deskew else 0.0, mx, my, mc, ms)
        if m < opt.min_valid_beams:
            return None, f"only {m} valid beams (< {opt.min_valid_beams}; NaN/inf/zero/out-of-range dropped)"
        prev_twist, self._last_twist = self._last_twist, None
        if odom_delta is not None:
            od = odom_delta if isinstance(odom_delta, np.ndarray) and odom_delta.ndim == 1 and \
                odom_delta.dtype == np.float64 else np.asarray(odom_delta, dtype=float).reshape(-1)
            interval = (stamp - prev) if (prev is not None and math.isfinite(stamp)) else float(scan.scan_time or 0.0)
            o = od.tolist() if od.shape == (3,) else None  # as Python floats (float() of each element)
            if (
                o is not None
                and math.isfinite(o[0] + o[1] + o[2])
                and math.isfinite(interval)
                and 0 < interval <= opt.max_deskew_interval_s
            ):
                # the twist in scalar maths (the same operations element by element as on the arrays)
                lx, ly, lw = se2_log(o).tolist()
                twist = (lx / interval, ly / interval, lw / interval)
                mid = stamp - 0.5 * interval
                self._last_twist = (mid, twist)
                if deskew:
                    if opt.deskew_extrapolate and prev_twist is not None and \
                            0 < mid - prev_twist[0] <= opt.max_deskew_interval_s:
                        dt_prev = mid - prev_twist[0]
                        ahead = stamp + 0.5 * (n - 1) * t_inc - mid
                        (v0, v1, v2), (p0, p1, p2) = twist, prev_twist[1]
                        twist = (v0 + (v0 - p0) / dt_prev * ahead, v1 + (v1 - p1) / dt_prev * ahead,
                                 v2 + (v2 - p2) / dt_prev * ahead)
                    _deskew_in_place(pts, twist, tau_used)
        if opt.voxel_size_m > 0:
            pts = voxel_downsample(pts, opt.voxel_size_m)
            if len(pts) < opt.min_valid_beams:
                return None, f"only {len(pts)} points after voxel downsampling (< {opt.min_valid_beams})"
        return pts, ""


_RANGE_DTYPES = (np.dtype(np.float32), np.dtype(np.float64))


@njit(cache=True)
def _beam_points(ranges, rmin, rmax, min_valid, max_beams, cos_a, sin_a, t_inc, mx, my, mc, ms):  # pragma: no cover
    """The valid beams of ``ranges`` as points in ``base_link``: ``(points (m, 2), their beam times
    ``i * t_inc`` (empty when ``t_inc`` is 0), valid beams before striding)``; no points (``(0, 2)``)
    when fewer than ``min_valid`` beams are valid.

    Valid: finite, > 0 and inside ``[rmin, rmax]`` (``rmax = inf``: no upper limit); with
    ``max_beams`` (> 0) and more valid beams, every ``ceil(valid / max_beams)``-th.  The point is
    the mount transform of ``r (cos a, sin a)``: ``(mx + mc px - ms py, my + ms px + mc py)``, each
    operation rounded as numpy rounds it (no fastmath: no fused multiply-add), the same bits as the
    array code over the gathered beams."""
    n = ranges.shape[0]
    lower_open = rmin <= 0.0
    upper = rmax < math.inf
    m = 0
    for i in range(n):
        r = float(ranges[i])
        if (r > 0.0 if lower_open else r >= rmin) and (r <= rmax if upper else r < math.inf):
            m += 1
    if m < min_valid:
        return np.empty((0, 2)), np.empty(0), m
    stride = 1
    if max_beams > 0 and m > max_beams:
        stride = int(math.ceil(m / max_beams))
    k = (m + stride - 1) // stride
    pts = np.empty((k, 2))
    with_tau = t_inc != 0.0
    tau_used = np.empty(k if with_tau else 0)
    skip = 0  # valid beams to pass over before the next one kept
    o = 0  # points written
    for i in range(n):
        r = float(ranges[i])
        if (r > 0.0 if lower_open else r >= rmin) and (r <= rmax if upper else r < math.inf):
            if skip == 0:
                px = r * cos_a[i]
                py = r * sin_a[i]
                pts[o, 0] = mx + mc * px - ms * py
                pts[o, 1] = my + ms * px + mc * py
                if with_tau:
                    tau_used[o] = float(i) * t_inc  # np.arange(n, dtype=float) * t_inc
                o += 1
                skip = stride
            skip -= 1
    return pts, tau_used, m


@njit(cache=True)
def _deskew_apply(pts, tau, vx, vy, w):  # pragma: no cover - compiled
    """``pts`` (at each beam's time ``tau`` after the first) moved into the base frame at the first
    beam in place: ``exp_along([vx, vy, w], tau)`` applied point by point, each operation rounded as
    numpy's array code rounds it (no fastmath); the rotation ``w tau``'s cosine and sine are the C
    library's, which numpy's float64 ``cos`` and ``sin`` call (the same values)."""
    small = abs(w) < 1e-12
    for i in range(pts.shape[0]):
        th = w * tau[i]
        c = math.cos(th)
        s = math.sin(th)
        if small:
            ox = vx * tau[i]
            oy = vy * tau[i]
        else:
            c1 = 1.0 - c
            ox = (vx * s - vy * c1) / w
            oy = (vx * c1 + vy * s) / w
        x = pts[i, 0]
        y = pts[i, 1]
        pts[i, 0] = ox + c * x - s * y
        pts[i, 1] = oy + s * x + c * y


def _deskew_in_place(pts: FloatArray, twist: tuple[float, float, float], tau: FloatArray) -> None:
    """``pts`` (at each beam's time ``tau`` after the first) moved into the base frame at the first
    beam: ``exp_along(twist, tau)`` applied point by point (:func:`_deskew_apply`: the same values
    :func:`deskew_offsets_twist` gives)."""
    _deskew_apply(pts, tau, float(twist[0]), float(twist[1]), float(twist[2]))


UNKNOWN_GUESS_RADIUS_M = 0.4  # a guess in unknown space this close to free space is still matched


def registration_floor(H: FloatArray, sigma_m: float) -> FloatArray:
    """The covariance a map registration error of ``sigma_m`` (1 sigma) leaves in a fix with scan
    normal matrix ``H`` (``J^T W J`` over x, y, yaw).

    A map whose walls sit ``sigma_m`` off in the map frame (a SLAM map's passes disagree; a wall is
    known only to its cell) moves every fix by about that much, whatever the scan shows: the
    residuals fit the shifted map.  Position: ``sigma^2`` stretched along the scan's weakly
    constrained direction, ``sigma^2 sqrtm((H_xy / mean eig)^-1)`` (a corridor's walls pin the
    cross-track position, the along-track one rests on a few door frames); heading: ``sigma^2 /
    l^2`` with ``l = sqrt(H_yaw / mean(H_xx, H_yy))`` the points' r.m.s. moment arm.
    """
    out = np.zeros((3, 3))
    if not (sigma_m > 0):
        return out
    hxy = H[:2, :2]
    tr = 0.5 * float(hxy[0, 0] + hxy[1, 1])
    if not (tr > 0 and math.isfinite(tr)):
        return out
    w, V = np.linalg.eigh(hxy / tr)
    w = np.maximum(w, 1e-6)
    out[:2, :2] = sigma_m**2 * (V @ np.diag(1.0 / np.sqrt(w)) @ V.T)
    lever2 = float(H[2, 2]) / tr
    if lever2 > 0:
        out[2, 2] = sigma_m**2 / lever2
    return out


def registration_sigma(accuracy_m: float, resolution_m: float) -> float:
    """The part of a map's accuracy (1 sigma, m) that moves a whole fix: ``sqrt(accuracy^2 -
    resolution^2 / 12)``, 0 when the accuracy is no more than the raster's.  A wall is known to its
    cell (uniform over it: ``resolution / sqrt(12)``), but each wall sits differently in its cells:
    that part differs from wall to wall, the scan's residuals see it and the per-run covariance
    carries it (``fgloc map``'s ``accuracy_m`` adds it to the passes' registration in quadrature).
    What no residual can see is the rest: the passes' registration, which moves every wall the scan
    sees together (the registration floor, :func:`registration_floor`)."""
    acc = float(accuracy_m)
    raster2 = float(resolution_m) ** 2 / 12.0
    return math.sqrt(acc * acc - raster2) if acc * acc > raster2 else 0.0


def map_accuracy(occ_map: OccupancyMap, value: float | str, where: str) -> float:
    """The map registration sigma (m) a front-end adds as a floor: ``value`` when a number, else
    (``auto``) the map's declared ``accuracy_m`` (``fgloc map`` writes what its self-check measured:
    the passes' registration and the raster; on the Radish logs fr079 0.022, intel 0.029, aces
    0.033 m, 0.9-1.3 times half a cell), and 0 for a map that declares none (no floor: with it the
    smoother weighs the CARMEN odometry more, whose pose-derived twist noise is too tight, and its
    heading on the Radish segments got worse, see the README's real-map table).  ConfigError for
    anything else."""
    if isinstance(value, str):
        if value != "auto":
            raise ConfigError(f"frontends config [{where}]: map_accuracy_m must be a number >= 0 or auto, "
                              f"got {value!r}")
        acc = occ_map.accuracy_m
        return 0.0 if acc is None else float(acc)
    out = float(value)
    if not (out >= 0 and math.isfinite(out)):
        raise ConfigError(f"frontends config [{where}]: map_accuracy_m must be >= 0, got {value}")
    return out


_ORIGIN_TRIG: tuple[float, float, float] = (0.0, 1.0, 0.0)  # (yaw, cos, sin) of the last map origin seen


def grid_cell(occ_map: OccupancyMap, x: float, y: float) -> tuple[int, int]:
    """``occ_map.world_to_grid`` of one point in scalar maths: the same operations on the same
    values (numpy's cos / sin of the origin's yaw), ``(row, col)``; a numpy call per operation on
    a 1x2 array was most of :func:`check_guess`."""
    global _ORIGIN_TRIG
    ox, oy, oyaw = float(occ_map.origin[0]), float(occ_map.origin[1]), float(occ_map.origin[2])
    if _ORIGIN_TRIG[0] != oyaw:
        _ORIGIN_TRIG = (oyaw, float(np.cos(oyaw)), float(np.sin(oyaw)))
    _, c, s = _ORIGIN_TRIG
    res = float(occ_map.resolution)
    dx, dy = x - ox, y - oy
    return math.floor((-s * dx + c * dy) / res), math.floor((c * dx + s * dy) / res)


def on_grid(occ_map: OccupancyMap, x: float, y: float) -> tuple[int, int] | None:
    """The grid cell ``(row, col)`` of one point (:func:`grid_cell`), or None where ``occ_map.in_bounds``
    is false or the point is not finite."""
    if not (math.isfinite(x) and math.isfinite(y)):
        return None
    row, col = grid_cell(occ_map, x, y)
    return (row, col) if 0 <= row < occ_map.height and 0 <= col < occ_map.width else None


def check_guess(occ_map: OccupancyMap, guess: np.ndarray | None) -> tuple[FloatArray | None, str]:
    """Validate a prior guess: finite, on the map and not deep in unknown space (more than
    ``UNKNOWN_GUESS_RADIUS_M`` from free space). ``(pose, "")`` or ``(None, reason)``."""
    try:
        g = np.array(guess, dtype=float).reshape(-1)  # a copy: the yaw is wrapped in place
    except (TypeError, ValueError):
        return None, "guess is not a pose [x, y, yaw]"
    if g.shape != (3,):
        return None, f"guess must be [x, y, yaw], got shape {g.shape}"
    x, y, yaw = float(g[0]), float(g[1]), float(g[2])
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(yaw)):
        return None, "guess is not finite"
    cell = on_grid(occ_map, x, y)
    if cell is None:
        return None, f"guess ({x:.2f}, {y:.2f}) is off the map"
    i_c, j_c = cell
    if occ_map.data[i_c, j_c] < 0:  # unknown (the cell alone: .unknown builds the whole grid)
        # a map built by SLAM leaves unknown specks and ragged edges where the robot drove
        # (doorways, glass, the edge of what one half of a log saw): a guess there is fine
        # when free space is within UNKNOWN_GUESS_RADIUS_M; deep in unknown space it is not
        r = int(np.ceil(UNKNOWN_GUESS_RADIUS_M / occ_map.resolution))
        i0, j0 = max(i_c - r, 0), max(j_c - r, 0)
        win = occ_map.data[i0:i_c + r + 1, j0:j_c + r + 1]
        ii, jj = np.nonzero(occ_map.free_mask(win))
        d2 = (ii + i0 - i_c) ** 2 + (jj + j0 - j_c) ** 2
        if not (len(d2) and float(np.sqrt(d2.min())) * occ_map.resolution <= UNKNOWN_GUESS_RADIUS_M):
            return None, f"guess ({x:.2f}, {y:.2f}) is in unknown space"
    g[YAW] = wrap_scalar(yaw)  # wrap_angle's value, in scalar maths
    return g, ""


# ------------------------------------------------------------------ base class
class FrontendBase:
    """Common plumbing: the preprocessor, the guess check and the never-raise wrapper.

    Subclasses implement ``_match(points_base, guess, scan)`` with points already in
    ``base_link`` (de-skewed) and a validated guess.
    """

    name: str = "base"
    #: keeps its own pose belief (particles): re-seeded by ``reset(pose)`` whenever the localizer
    #: resets its back-end, given the odometry as it came (its motion model), and a scan it skips
    #: (update thresholds) says nothing about being lost
    is_particle_filter: bool = False
    #: has its own global localization mode, ``reset(None)`` (else the localizer runs its
    #: correlative global search and refines the candidates with ``match``)
    supports_global: bool = False

    def __init__(
        self, occ_map: OccupancyMap, laser_mount: StaticTransform | None, preprocess: PreprocessOptions | None
    ):
        self.map = occ_map
        self.laser_mount = laser_mount
        self.pre = ScanPreprocessor(laser_mount, preprocess)

    def reset(self, pose: np.ndarray | None = None) -> None:
        self.pre.reset()

    def match(self, scan: LaserScan, guess: np.ndarray, odom_delta: np.ndarray | None = None) -> MatchResult:
        try:
            pts, why = self.pre(scan, odom_delta)
            if pts is None:
                return no_fix(why)
            g, why = check_guess(self.map, guess)
            if g is None:
                return no_fix(why)
            return self._match(pts, g, scan)
        except Exception as e:  # never raise on bad input: report it as a no-fix
            return no_fix(f"{self.name}: internal error ({e.__class__.__name__}: {e})")

    def _match(self, points: FloatArray, guess: FloatArray, scan: LaserScan) -> MatchResult:  # pragma: no cover
        raise NotImplementedError


class FixAcceptance:
    """The acceptance tests and covariance scaling the scan matchers share (native, kiss).

    ``conf`` is the matcher's config section, with the fields ``inlier_dist_m``, ``min_inliers``,
    ``min_inlier_fraction``, ``max_jump_m``, ``max_jump_deg``, ``min_eigen_ratio``,
    ``cov_inflation`` (``[kxy, kyaw]``) and ``cov_floor``; ``name`` prefixes the reasons.
    """

    def __init__(self, name: str, conf: Any) -> None:
        self.name = name
        self.inlier_dist = float(conf.inlier_dist_m)
        self.min_inliers = int(conf.min_inliers)
        self.min_inlier_fraction = float(conf.min_inlier_fraction)
        self.max_jump_m = float(conf.max_jump_m)
        self.max_jump = math.radians(conf.max_jump_deg)
        self.min_eigen_ratio = float(conf.min_eigen_ratio)
        infl = np.broadcast_to(np.asarray(conf.cov_inflation, dtype=float).reshape(-1), (2,))
        if not np.all(infl > 0):
            raise ConfigError(f"frontends config [{name}]: cov_inflation must be positive, got {conf.cov_inflation}")
        self.cov_inflation = (float(infl[0]), float(infl[1]))
        self.cov_scale = np.diag(np.sqrt([infl[0], infl[0], infl[1]]))
        self._unit_scale = self.cov_inflation == (1.0, 1.0)
        self.cov_floor = np.diag(np.asarray(conf.cov_floor, dtype=float))

    def within_jump(self, pose: FloatArray, guess: FloatArray) -> bool:
        """``pose`` is within ``max_jump_m`` / ``max_jump_deg`` of ``guess``."""
        jump = math.hypot(pose[0] - guess[0], pose[1] - guess[1])
        return jump <= self.max_jump_m and abs(wrap_scalar(pose[YAW] - guess[YAW])) <= self.max_jump

    def too_few_inliers(self, n_in: int, n: int, **info: Any) -> MatchResult | None:
        """A no-fix when fewer than ``min_inliers`` or ``min_inlier_fraction`` of ``n`` points agree."""
        if n_in < self.min_inliers or n_in / n < self.min_inlier_fraction:
            return no_fix(f"{self.name}: too few inliers ({n_in} of {n} points within {self.inlier_dist:.3f} m)",
                          n_inliers=n_in, quality=n_in / n, **info)
        return None

    def jumped(self, pose: FloatArray, guess: FloatArray, n_in: int, quality: float, **info: Any
               ) -> MatchResult | None:
        """A no-fix when ``pose`` is farther from ``guess`` than ``max_jump_m`` / ``max_jump_deg``."""
        jump = math.hypot(pose[0] - guess[0], pose[1] - guess[1])
        dyaw = abs(wrap_scalar(pose[YAW] - guess[YAW]))
        if jump > self.max_jump_m or dyaw > self.max_jump:
            return no_fix(f"{self.name}: solution jumped {jump:.2f} m / {math.degrees(dyaw):.1f} deg from the guess",
                          n_inliers=n_in, quality=quality, **info)
        return None

    def inflate(self, cov: FloatArray) -> FloatArray:
        """``S cov S`` with ``S = diag(sqrt(kxy), sqrt(kxy), sqrt(kyaw))`` (``cov`` itself when ``S = I``:
        products with 1 and sums with exact zeros change no bit of a finite ``cov``)."""
        if self._unit_scale:
            return cov
        return self.cov_scale @ cov @ self.cov_scale  # type: ignore[no-any-return]

    def finish(self, cov: FloatArray) -> FloatArray:
        """``cov + diag(cov_floor)``, symmetrized."""
        cov = cov + self.cov_floor
        return 0.5 * (cov + cov.T)  # type: ignore[no-any-return]
