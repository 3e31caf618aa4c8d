"""The simulator: a robot driven along a route in a continuous world, with the paper's sensors.

Sensors (defaults follow the paper's Table 2; every number is in the scenario):

* wheel encoders: 500 pulses/rev read in quadrature (2000 counts/rev) on every
  wheel, each wheel's effective radius off by a seeded ``wheel_radius_error``
  (relative, 1 sigma); counts are latched at ``odom.rate_hz`` and turned into a body
  twist by forward kinematics with the nominal radius, published on ``/odom`` with
  the dead-reckoned odom-frame pose, as a ROS odometry node does;
* compass: heading as an integer number of 0.1 deg (int16, 0..3599, counter-clockwise,
  REP 103), ``heading = map yaw + offset + noise``, the offset a fixed angle between
  compass north and the map x axis; a gyro yaw rate with bias and noise; ``/imu``;
* laser: 270 deg, 0.5 deg steps (541 beams), 0.5-50 m, Gaussian range noise of
  ``range_sigma_m`` (4 mm: the datasheet's +-8 mm read as 2 sigma; 5 mm beyond 30 m),
  angular noise ``angle_sigma_deg``, 25 Hz with a period jitter uniform in +-5 %,
  beam ``i`` measured at ``stamp + i * time_increment`` while the robot moves (motion
  distortion, as a real scanner), REP 117: no return -> +inf, closer than range_min
  -> -inf; mounted off the robot's centre (``/tf_static`` base_link -> laser);
* every sensor has its own clock phase (unsynchronized).

World and motion: the builtin hall is continuous geometry (polygons, circles; laser ranges by
exact ray intersection, compiled with numba), rotated ``world_rotation_deg`` against the map
grid, with ``map_changes`` (furniture moved, turned, removed or added since mapping, pallets,
closed doors: :data:`CHANGE_KINDS`); the robot's map is the unchanged hall's 0.05 m
rasterization (a cell is occupied when it intersects a solid). A map_server YAML as ``map``
makes a grid world instead: every cell that is not free is solid (the Willow Garage map stores
walls as grey "unknown" pixels), ray cast with :meth:`OccupancyMap.raycast` (its
``map_changes`` add solids or clear boxes of cells). The robot drives the route's legs facing
the direction of travel (0.8 m/s, 0.5 m/s^2), stops at each waypoint and turns in place to the
next leg's heading (0.8 rad/s, 1.5 rad/s^2): the heading changes at the rectangle's corners.
The true motion is sampled at 500 Hz (wheel angles are integrated at that rate);
``/ground_truth`` (nav_msgs/Odometry, pose in ``map``) and ``SimResult.ground_truth`` are at
``ground_truth_rate_hz`` (100 Hz). Stamps start at 0 s.

Robots beyond the paper's (every key in the scenario):

* ``drive: skid`` - a four-wheel skid-steer base with differential-drive kinematics whose
  wheels scrub when it turns: ``odom.scrub_factor: [lo, hi]`` makes the odometry's yaw rate
  the true one times a factor growing from ``lo`` (driving straight) to ``hi`` (turning at
  ``odom.scrub_ref_radps`` or faster), while the messages keep claiming ``twist_sigma``;
  ``odom.speed_scale`` makes every wheel report that much more speed than the ground moves;
* ``odom.wheel_noise`` (any drive): each wheel's turn between two odometry readings off by a random share
  of it (1 sigma, white; the messages keep claiming ``twist_sigma``): a noisier odometry;
* ``imu:`` - a ``sensor_msgs/Imu`` (:class:`~fgloc.types.Imu`) instead of the compass: a
  9-axis unit mounted with ``mount_rpy_deg`` (``/tf_static`` base_link -> ``frame_id`` as a
  :class:`~fgloc.types.Transform3D`), orientation = base orientation + north offset +
  distortion + noise rotated through the mount, angular velocity in its own axes with a gyro
  bias about base_link z, covariances in its own frame; ``burst_period_s`` delivers the
  messages in bursts (their arrival order, the stamps stay true);
* ``laser.stamp_delay_s`` stamps every scan that much after it was measured (a late driver);
* mounted otherwise than the robot's tf says (``/tf_static`` keeps the declared mount): ``laser.mount_error``
  ``[dx, dy, dyaw_deg]`` (the laser's true mount is the declared one composed with it),
  ``laser.upside_down`` (rolled 180 deg about its x axis: its beams sweep clockwise about the robot's up axis),
  ``imu.mount_error_rpy_deg`` (the IMU turned that much further, in its own axes, than its tf says: 180 deg of
  roll is a unit upside down, its yaw rate negated);
* ``odom.yaw_rate_sign: -1``: an odometry driver whose yaw rate (and so its pose's yaw) has the wrong sign;
* ``turn_radii_m`` drives the corners on arcs instead of stop-turn-go; ``strafe_legs`` drives
  those legs sideways keeping the heading (mecanum).

``SimResult.messages`` is in arrival order (the stamp, unless a sensor is delivered late or
in bursts).

Faults: wheel slip (the wheels turn ``fraction`` faster than the ground moves),
compass disturbance (an added heading offset), laser blackout (no scans), kidnapping
(a jump of the true pose that odometry does not see), unmapped moving obstacles
(circles the laser sees but the map does not have), odometry dropout (no ``/odom`` from
``start`` for ``duration`` s, for good when ``duration`` is null: a dead wheel driver) and late
odometry (every ``/odom`` message delivered ``delay_s`` after its stamp, the stamps true).
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.typing import ArrayLike, NDArray

from fgloc.errors import ConfigError
from fgloc.frames.imu import imu_message
from fgloc.geometry import compose, interpolate_poses, inverse, wrap_angle
from fgloc.kinematics import QuadratureEncoder, make_kinematics
from fgloc.maps import FREE, OCCUPIED, OccupancyMap, load_map
from fgloc.sim.motion import Plan, plan_route
from fgloc.sim.world import PAPER_ROUTE, World, paper_hall
from fgloc.types import CompassHeading, Imu, LaserScan, Odometry, StaticTransform, Trajectory, Transform3D

FloatArray = NDArray[np.float64]

DEFAULT_SCENARIO: dict[str, Any] = {
    "name": "paper",
    "map": "hall",
    "map_resolution_m": 0.05,
    # The robot's map is not the world: the building is not aligned with the map's grid (walls
    # cross cells obliquely, so the 0.05 m raster misplaces them by up to half a cell), and some
    # furniture has moved since the map was made (world polygon index -> shift in metres).
    "world_rotation_deg": 0.7,
    "map_changes": [{"polygon": 19, "shift": [0.15, -0.10]}, {"polygon": 22, "shift": [0.0, 0.20]}],
    "route": PAPER_ROUTE.tolist(),
    "loops": 1,
    "drive": "mecanum",
    "speed_mps": 0.8,
    "accel_mps2": 0.5,
    "yaw_rate_radps": 0.8,
    "yaw_accel_radps2": 1.5,
    "turn_radii_m": None,            # corners on arcs of this radius (one value or one per corner); None: stop-turn-go
    "strafe_legs": [],               # legs driven sideways keeping the heading (mecanum)
    "robot": {"wheel_radius_m": 0.076, "half_wheelbase_m": 0.25, "half_track_m": 0.28},
    "odom": {"rate_hz": 50.0, "pulses_per_rev": 500, "wheel_radius_error": 0.003, "twist_sigma": [0.01, 0.01, 0.03],
             "scrub_factor": None, "scrub_ref_radps": 0.8, "speed_scale": 1.0, "wheel_noise": 0.0,
             "yaw_rate_sign": 1.0},
    # distortion_deg: amplitude of a smooth position-dependent heading error (indoor magnetic
    # fields from steel and cables bend the compass by a degree or more).
    "compass": {"rate_hz": 20.0, "offset_deg": None, "sigma_deg": 0.3, "distortion_deg": 1.0,
                "gyro_sigma_radps": 0.005, "gyro_bias_radps": 0.002},
    "laser": {"mount": [0.25, 0.03, 0.0], "rate_hz": 25.0, "jitter": 0.05, "fov_deg": 270.0, "step_deg": 0.5,
              "range_min_m": 0.5, "range_max_m": 50.0, "range_sigma_m": 0.004, "range_sigma_far_m": 0.005,
              "angle_sigma_deg": 0.02, "enabled": True, "stamp_delay_s": 0.0,
              "mount_error": [0.0, 0.0, 0.0], "upside_down": False},
    "imu": None,                     # a sensor_msgs/Imu section (see IMU_DEFAULTS) replaces the compass
    #                                  (compass: null and no imu: a robot with neither, no /imu at all)
    "ground_truth_rate_hz": 100.0,
    "faults": {},
}


IMU_DEFAULTS: dict[str, Any] = {
    "rate_hz": 100.0,
    "frame_id": "imu_link",
    "mount_xyz_m": [0.0, 0.0, 0.1],
    "mount_rpy_deg": [0.0, 0.0, 0.0],   # base_link -> imu_link, roll pitch yaw (fixed axes x, y, z)
    "mount_error_rpy_deg": [0.0, 0.0, 0.0],  # the unit turned this much further (in its frame) than its tf says
    "orientation": True,                 # 9-axis (magnetometer): orientation published; false: -1 covariance
    "offset_deg": None,                  # IMU north vs map x axis; None: seeded 5-25 deg either sign
    "yaw_sigma_deg": 0.5,
    "distortion_deg": 1.0,
    "roll_pitch_sigma_deg": 0.1,
    "gyro_sigma_radps": 0.005,           # per axis, white
    "gyro_bias_radps": 0.002,            # about base_link z
    "burst_period_s": 0.0,               # > 0: delivered in bursts at the end of each period
}


@dataclass
class SimResult:
    """A simulated run: the map, the time-ordered messages, the truth and the parameters used."""

    map: OccupancyMap
    messages: list[tuple[str, object]]
    ground_truth: Trajectory
    laser_mount: StaticTransform
    compass_offset_rad: float
    robot: dict
    scenario: dict = field(default_factory=dict)
    imu_mount: Transform3D | None = None

    def topic(self, name: str) -> list:
        """All messages of one topic, in time order."""
        return [m for t, m in self.messages if t == name]


def _merge(base: dict, over: dict) -> dict:
    out = copy.deepcopy(base)
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = _merge(out[k], v)
        else:
            out[k] = copy.deepcopy(v)
    return out


#: the faults a scenario may inject and their keys (``faults:`` section; checked on loading)
FAULT_KEYS: dict[str, Any] = {
    "kidnap": {"time": None, "skip_s": None, "to": None},
    "wheel_slip": {"start": None, "duration": None, "fraction": None},
    "compass_disturbance": {"start": None, "duration": None, "offset_deg": None},
    "laser_blackout": {"start": None, "duration": None},
    "odometry_dropout": {"start": None, "duration": None},
    "odometry_late": {"delay_s": None},
    "moving_obstacles": [{"path": None, "speed_mps": None, "radius_m": None, "start": None}],
}


def check_scenario(data: dict, source: str) -> None:
    """Unknown keys and fault names of a scenario are a one-line ConfigError with a suggestion."""
    from fgloc.config.schema import check_keys

    template = {**DEFAULT_SCENARIO, "initial_yaw": None, "imu": IMU_DEFAULTS, "faults": FAULT_KEYS}
    check_keys(data, template, source, open_keys=("map_changes", "route"))


def load_scenario(path_or_dict: str | Path | dict) -> dict:
    """A scenario dict merged over the defaults; relative map paths resolve against the YAML's folder."""
    if isinstance(path_or_dict, dict):
        check_scenario(path_or_dict, "scenario")
        return _merge(_defaults_for(path_or_dict), path_or_dict)
    from fgloc.config.schema import load_yaml

    path = Path(path_or_dict)
    try:
        data = load_yaml(path.read_text())
    except FileNotFoundError:
        raise ConfigError(f"{path}: scenario file not found") from None
    except yaml.YAMLError:
        raise ConfigError(f"{path}: scenario YAML does not parse") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: scenario must be a YAML mapping")
    check_scenario(data, str(path))
    m = data.get("map", "hall")
    if isinstance(m, str) and m != "hall" and not Path(m).is_absolute():
        cand = [path.parent / m, Path.cwd() / m]
        data["map"] = str(next((c for c in cand if c.exists()), cand[0]))
    return _merge(_defaults_for(data), data)


def _defaults_for(data: dict) -> dict:
    """The defaults a scenario is merged over: the default ``map_changes`` are the builtin hall's
    furniture, so a map_server world starts without changes."""
    if data.get("map", "hall") == "hall":
        return DEFAULT_SCENARIO
    return {**DEFAULT_SCENARIO, "map_changes": []}


# ------------------------------------------------------------------- worlds
#: the kinds of ``map_changes`` entries (the world as it is now, against the map made before):
#: ``polygon``/``circle`` with ``shift: [dx, dy]`` (m) and/or ``rotate_deg`` (about its centre) moves a
#: piece of the builtin hall (its index), ``remove: true`` takes it away; ``add: [[x, y], ...]`` (a
#: convex polygon, map frame) and ``add_circle: [x, y, r]`` put new solids in (furniture, a pallet, a
#: closed door); ``clear: [x0, y0, x1, y1]`` (map_server worlds) empties a box of solid cells
CHANGE_KINDS = ("polygon", "circle", "add", "add_circle", "clear")


def _change_error(i: int, ch: Any, problem: str) -> ConfigError:
    return ConfigError(f"map_changes[{i}]: {problem} (got {ch!r}; kinds: {', '.join(CHANGE_KINDS)})")


def _moved(shape: FloatArray, ch: dict) -> FloatArray:
    """A polygon's vertices (or a circle's centre, one row) rotated about their mean and shifted."""
    out = np.asarray(shape, dtype=float).reshape(-1, 2).copy()
    rot = float(ch.get("rotate_deg") or 0.0)
    if rot:
        c, s = np.cos(np.deg2rad(rot)), np.sin(np.deg2rad(rot))
        ctr = out.mean(axis=0)
        out = (out - ctr) @ np.array([[c, s], [-s, c]]) + ctr
    return out + np.asarray(ch.get("shift", (0.0, 0.0)), dtype=float).reshape(2)


def apply_changes(world: World, changes: list[dict]) -> tuple[list[FloatArray], FloatArray]:
    """The polygons and circles of ``world`` after ``changes`` (see :data:`CHANGE_KINDS`)."""
    polys: list[FloatArray | None] = [np.asarray(p, dtype=float).copy() for p in world.polygons]
    circles: list[FloatArray | None] = [np.asarray(c, dtype=float).copy() for c in world.circles]
    added: list[FloatArray] = []
    added_c: list[FloatArray] = []
    for i, ch in enumerate(changes):
        if not isinstance(ch, dict) or sum(k in ch for k in CHANGE_KINDS) != 1:
            raise _change_error(i, ch, "one kind per entry")
        if "add" in ch:
            p = np.asarray(ch["add"], dtype=float)
            if p.ndim != 2 or p.shape[1] != 2 or len(p) < 3 or not np.isfinite(p).all():
                raise _change_error(i, ch, "add: a polygon of at least 3 [x, y] vertices")
            added.append(p)
        elif "add_circle" in ch:
            c = np.asarray(ch["add_circle"], dtype=float).reshape(-1)
            if c.shape != (3,) or not np.isfinite(c).all() or c[2] <= 0:
                raise _change_error(i, ch, "add_circle: [x, y, radius > 0]")
            added_c.append(c)
        elif "clear" in ch:
            raise _change_error(i, ch, "clear: only in a map_server world (the hall's pieces are removed by index)")
        else:
            kind = "polygon" if "polygon" in ch else "circle"
            items = polys if kind == "polygon" else circles
            j = int(ch[kind])
            if not 0 <= j < len(items) or items[j] is None:
                raise _change_error(i, ch, f"no {kind} {j} (the hall has {len(items)})")
            item = items[j]
            assert item is not None
            if ch.get("remove"):
                items[j] = None
            elif kind == "polygon":
                items[j] = _moved(item, ch)
            else:
                items[j] = np.r_[_moved(item[:2], ch)[0], item[2]]
    polys_out = [p for p in polys if p is not None] + added
    circ = [c for c in circles if c is not None] + added_c
    return polys_out, np.asarray(circ, dtype=float).reshape(-1, 3)


class GridWorld:
    """A world made from a map_server map: every cell that is not free is solid; ``changes``
    (:data:`CHANGE_KINDS`: ``add``, ``add_circle``, ``clear``) edit it after the map was made."""

    def __init__(self, occ: OccupancyMap, changes: list[dict] | None = None):
        solid = ~occ.free
        segs: list[FloatArray] = []
        circles: list[FloatArray] = []
        for i, ch in enumerate(changes or []):
            if not isinstance(ch, dict) or sum(k in ch for k in CHANGE_KINDS) != 1:
                raise _change_error(i, ch, "one kind per entry")
            if "clear" in ch:
                box = np.asarray(ch["clear"], dtype=float).reshape(-1)
                if box.shape != (4,) or not np.isfinite(box).all():
                    raise _change_error(i, ch, "clear: [x0, y0, x1, y1]")
                rows, cols = np.indices(solid.shape)
                xy = occ.grid_to_world(rows.ravel(), cols.ravel()).reshape(*solid.shape, 2)
                inside = (xy[..., 0] >= min(box[0], box[2])) & (xy[..., 0] <= max(box[0], box[2])) \
                    & (xy[..., 1] >= min(box[1], box[3])) & (xy[..., 1] <= max(box[1], box[3]))
                solid = solid & ~inside
            elif "polygon" in ch or "circle" in ch:
                raise _change_error(i, ch, "a map_server world has no numbered pieces: clear a box, add solids")
            else:
                w = World([], np.zeros((0, 3)))
                p, c = apply_changes(w, [ch])
                for poly in p:
                    segs.append(np.column_stack([poly, np.roll(poly, -1, axis=0)]))
                circles.extend(c)
        self.solid_map = OccupancyMap(np.where(solid, OCCUPIED, FREE).astype(np.int16), occ.resolution, occ.origin)
        self.segments = np.vstack(segs) if segs else np.zeros((0, 4))
        self.circles = np.asarray(circles, dtype=float).reshape(-1, 3)

    def raycast(self, origins: FloatArray, angles: FloatArray, max_range: float,
                extra_circles: FloatArray | None = None) -> FloatArray:
        r = self.solid_map.raycast(origins, angles, max_range)
        circles = self.circles if extra_circles is None or not len(extra_circles) else np.vstack(
            [self.circles, extra_circles])
        if len(circles) or len(self.segments):
            from fgloc.sim.world import raycast_geometry

            r = np.minimum(r, raycast_geometry(origins, angles, self.segments, circles, max_range))
        return r


def build_world(sc: dict) -> tuple[Any, OccupancyMap]:
    """The world as it is now (the scenario's ``map_changes`` applied) and the robot's map of it as it was."""
    if sc["map"] == "hall":
        mapped = paper_hall()
        rot = float(sc.get("world_rotation_deg") or 0.0)
        if rot:
            b = mapped.bounds
            mapped = mapped.rotated(np.deg2rad(rot), ((b[0] + b[2]) / 2, (b[1] + b[3]) / 2))
        occ = mapped.rasterize(float(sc.get("map_resolution_m", 0.05)))
        occ.accuracy_m = 0.0  # the map is the world rasterized: no registration error beyond its cells
        polys, circles = apply_changes(mapped, sc.get("map_changes") or [])
        return World(polys, circles, mapped.bounds, mapped.interior), occ
    occ = load_map(sc["map"])
    gw = GridWorld(occ, sc.get("map_changes") or [])
    # The robot's map: free cells stay free, solid cells bordering free space are walls.
    from scipy.ndimage import binary_dilation

    border = binary_dilation(occ.free, structure=np.ones((3, 3), dtype=bool)) & ~occ.free  # 8-connected
    data = np.full(occ.data.shape, -1, dtype=np.int16)
    data[occ.free] = FREE
    data[border | occ.occupied] = OCCUPIED
    return gw, OccupancyMap(data, occ.resolution, occ.origin, accuracy_m=0.0)  # the world is this map


# -------------------------------------------------------------------- motion
def true_motion(sc: dict) -> Plan:
    """The robot's true motion along the scenario's route (a kidnapping applied)."""
    route = np.asarray(sc["route"], dtype=float)
    loops = int(sc.get("loops", 1))
    if loops > 1:
        route = np.vstack([route] + [route[1:]] * (loops - 1))
    radii = sc.get("turn_radii_m")
    n0 = len(sc["route"]) - 2  # corners of one loop
    if radii is not None and np.ndim(radii) > 0 and loops > 1 and len(radii) == n0:
        radii = (list(radii) + [0.0]) * (loops - 1) + list(radii)  # a stop where a loop closes
    plan = plan_route(route, float(sc["speed_mps"]), float(sc["accel_mps2"]), float(sc["yaw_rate_radps"]),
                      float(sc["yaw_accel_radps2"]), initial_yaw=sc.get("initial_yaw"),
                      turn_radii_m=radii, strafe_legs=tuple(sc.get("strafe_legs") or ()))
    kid = sc.get("faults", {}).get("kidnap")
    if kid:
        tk = float(kid["time"])
        after = plan.t >= tk
        if "skip_s" in kid:  # jump ahead along the route: truth(t) = plan(t + skip)
            skip = float(kid["skip_s"])
            src_t = np.where(after, plan.t + skip, plan.t)
            keep = src_t <= plan.t[-1]
            idx = np.clip(np.searchsorted(plan.t, src_t[keep]), 0, len(plan.t) - 1)
            plan = Plan(plan.t[keep], plan.poses[idx], plan.twist[idx])
        else:  # teleport to a pose and keep driving the same body motion from there
            to = np.asarray(kid["to"], dtype=float)
            k = int(np.searchsorted(plan.t, tk))
            T = compose(to, inverse(plan.poses[k]))
            poses = plan.poses.copy()
            poses[after] = compose(T, plan.poses[after])
            plan = Plan(plan.t, poses, plan.twist)
    return plan


def _in_window(t: FloatArray, w: dict | None) -> NDArray[np.bool_]:
    if not w:
        return np.zeros(np.shape(t), dtype=bool)
    s = float(w["start"])
    return (t >= s) & (t < s + float(w["duration"]))


# ------------------------------------------------------------------- sensors
def _odometry(sc: dict, plan: Plan, rng: np.random.Generator) -> list[tuple[str, object]]:
    kin = make_kinematics({"drive": sc["drive"], **sc["robot"]})
    enc = QuadratureEncoder(int(sc["odom"]["pulses_per_rev"]))
    twist = plan.twist
    scrub = sc["odom"].get("scrub_factor")
    if scrub is not None:
        # skid steer: the wheels turn further than the base does (they scrub sideways), more so
        # the faster it turns
        lo, hi = (float(scrub), float(scrub)) if np.ndim(scrub) == 0 else (float(scrub[0]), float(scrub[1]))
        ref = float(sc["odom"].get("scrub_ref_radps", 0.8))
        f = lo + (hi - lo) * np.clip(np.abs(twist[:, 2]) / ref, 0.0, 1.0)
        twist = twist.copy()
        twist[:, 2] = twist[:, 2] * f
    wheel = kin.inverse(twist) * float(sc["odom"].get("speed_scale", 1.0))  # rad/s with the nominal radius
    slip = sc.get("faults", {}).get("wheel_slip")
    if slip:
        wheel = wheel * np.where(_in_window(plan.t, slip), 1.0 + float(slip["fraction"]), 1.0)[:, None]
    # the true radius differs from the nominal one: the wheel turns r_nom/r_true times as fast
    rad_err = 1.0 + rng.normal(0.0, float(sc["odom"]["wheel_radius_error"]), kin.n_wheels)
    wheel = wheel / rad_err[None, :]
    dt = np.diff(plan.t, prepend=plan.t[0])
    angle = np.cumsum(wheel * dt[:, None], axis=0)
    rate = float(sc["odom"]["rate_hz"])
    t_odom = plan.t[0] + rng.uniform(0, 1 / rate) + np.arange(0, plan.t[-1] - plan.t[0], 1 / rate)
    t_odom = t_odom[t_odom <= plan.t[-1]]
    ang = np.column_stack([np.interp(t_odom, plan.t, angle[:, i]) for i in range(kin.n_wheels)])
    noise = float(sc["odom"].get("wheel_noise") or 0.0)
    if noise > 0 and len(ang) > 1:
        # each wheel's turn between two readings off by a random share (uneven floor, tyre slip)
        d = np.diff(ang, axis=0) * (1.0 + rng.normal(0.0, noise, (len(ang) - 1, kin.n_wheels)))
        ang = np.vstack([ang[:1], ang[0] + np.cumsum(d, axis=0)])
    counts = enc.angle_to_counts(ang)
    sig = np.asarray(sc["odom"]["twist_sigma"], dtype=float)
    cov = np.diag(sig**2)
    yaw_sign = float(sc["odom"].get("yaw_rate_sign", 1.0))
    out: list[tuple[str, object]] = []
    pose = np.zeros(3)
    for k in range(1, len(t_odom)):
        dtk = t_odom[k] - t_odom[k - 1]
        tw = kin.forward(enc.counts_to_angle(counts[k] - counts[k - 1]) / dtk)
        tw[2] *= yaw_sign
        # midpoint integration of the odom-frame pose
        th = pose[2] + 0.5 * tw[2] * dtk
        pose = np.array([pose[0] + (tw[0] * np.cos(th) - tw[1] * np.sin(th)) * dtk,
                         pose[1] + (tw[0] * np.sin(th) + tw[1] * np.cos(th)) * dtk,
                         float(wrap_angle(pose[2] + tw[2] * dtk))])
        out.append(("/odom", Odometry(float(t_odom[k]), tw, cov.copy(), pose.copy())))
    drop = sc.get("faults", {}).get("odometry_dropout")
    if drop:
        t0 = float(drop["start"])
        t1 = t0 + float(drop["duration"]) if drop.get("duration") is not None else np.inf
        out = [(topic, m) for topic, m in out if not t0 <= m.stamp < t1]  # type: ignore[attr-defined]
    return out


def _compass(sc: dict, plan: Plan, offset: float, rng: np.random.Generator) -> list[tuple[str, object]]:
    c = sc["compass"]
    rate = float(c["rate_hz"])
    t = plan.t[0] + rng.uniform(0, 1 / rate) + np.arange(0, plan.t[-1] - plan.t[0], 1 / rate)
    yaw_true = interpolate_poses(plan.t, plan.poses, t)[:, 2]
    xy = interpolate_poses(plan.t, plan.poses, t)[:, :2]
    amp = np.deg2rad(float(c.get("distortion_deg", 0.0)))
    field_err = amp * (0.6 * np.sin(0.45 * xy[:, 0] + 0.3) * np.cos(0.35 * xy[:, 1] - 0.7)
                       + 0.4 * np.sin(0.21 * xy[:, 0] - 0.5 * xy[:, 1] + 1.1))
    heading = yaw_true + offset + field_err + rng.normal(0, np.deg2rad(float(c["sigma_deg"])), len(t))
    dist = sc.get("faults", {}).get("compass_disturbance")
    if dist:
        heading = heading + np.where(_in_window(t, dist), np.deg2rad(float(dist["offset_deg"])), 0.0)
    deci = np.round(np.rad2deg(np.mod(heading, 2 * np.pi)) * 10).astype(np.int64) % 3600  # int16 on the wire
    yaw_meas = np.asarray(wrap_angle(np.deg2rad(deci.astype(np.int16) / 10.0)))
    wz = np.interp(t, plan.t, plan.twist[:, 2])
    rate_meas = wz + float(c["gyro_bias_radps"]) + rng.normal(0, float(c["gyro_sigma_radps"]), len(t))
    yaw_var = (np.deg2rad(max(float(c["sigma_deg"]), 0.05)) ** 2 + np.deg2rad(0.1) ** 2 / 12
               + 0.5 * np.deg2rad(float(c.get("distortion_deg", 0.0))) ** 2)
    return [("/imu", CompassHeading(float(t[k]), float(yaw_meas[k]), float(rate_meas[k]), float(yaw_var),
                                    float(c["gyro_sigma_radps"]) ** 2)) for k in range(len(t))]


def scrub_factor(sc: dict, wz_radps: ArrayLike) -> FloatArray:
    """The simulated skid-steer odometry's yaw-rate factor at true yaw rate ``wz_radps`` (1 without scrub)."""
    w = np.abs(np.asarray(wz_radps, dtype=float))
    scrub = sc["odom"].get("scrub_factor")
    if scrub is None:
        return np.ones_like(w)
    lo, hi = (float(scrub), float(scrub)) if np.ndim(scrub) == 0 else (float(scrub[0]), float(scrub[1]))
    return np.asarray(lo + (hi - lo) * np.clip(w / float(sc["odom"].get("scrub_ref_radps", 0.8)), 0.0, 1.0))


def imu_mount_transform(sc: dict, true_mount: bool = False) -> Transform3D:
    """``/tf_static`` base_link -> imu frame of the scenario's IMU (``true_mount``: where the unit is,
    ``imu.mount_error_rpy_deg`` further)."""
    from scipy.spatial.transform import Rotation

    c = {**IMU_DEFAULTS, **(sc.get("imu") or {})}
    rot = Rotation.from_euler("xyz", np.deg2rad(np.asarray(c["mount_rpy_deg"], dtype=float)))
    if true_mount:
        rot = rot * Rotation.from_euler("xyz", np.deg2rad(np.asarray(c["mount_error_rpy_deg"], dtype=float)))
    R = rot.as_matrix()
    xyz = np.asarray(c["mount_xyz_m"], dtype=float)
    return Transform3D("base_link", str(c["frame_id"]), np.array([xyz[0], xyz[1], float(np.arctan2(R[1, 0], R[0, 0]))]),
                       z=float(xyz[2]), rotation_xyzw=np.asarray(rot.as_quat(), dtype=float))


def _imu(sc: dict, plan: Plan, offset: float, mount: Transform3D,
         rng: np.random.Generator) -> list[tuple[float, str, object]]:
    """``sensor_msgs/Imu`` messages ``(arrival, topic, msg)`` of a 9-axis IMU mounted with ``mount``."""
    from scipy.spatial.transform import Rotation

    from fgloc.frames.imu import mount_rotation

    c = {**IMU_DEFAULTS, **(sc.get("imu") or {})}
    rate = float(c["rate_hz"])
    t = plan.t[0] + rng.uniform(0, 1 / rate) + np.arange(0, plan.t[-1] - plan.t[0], 1 / rate)
    poses = interpolate_poses(plan.t, plan.poses, t)
    amp = np.deg2rad(float(c.get("distortion_deg", 0.0)))
    xy = poses[:, :2]
    field_err = amp * (0.6 * np.sin(0.45 * xy[:, 0] + 0.3) * np.cos(0.35 * xy[:, 1] - 0.7)
                       + 0.4 * np.sin(0.21 * xy[:, 0] - 0.5 * xy[:, 1] + 1.1))
    ysig = np.deg2rad(float(c["yaw_sigma_deg"]))
    yaw = poses[:, 2] + offset + field_err + rng.normal(0, ysig, len(t))
    dist = sc.get("faults", {}).get("compass_disturbance")
    if dist:
        yaw = yaw + np.where(_in_window(t, dist), np.deg2rad(float(dist["offset_deg"])), 0.0)
    rp_sig = np.deg2rad(float(c["roll_pitch_sigma_deg"]))
    roll = rng.normal(0, rp_sig, len(t))
    pitch = rng.normal(0, rp_sig, len(t))
    R_wb = Rotation.from_euler("ZYX", np.column_stack([yaw, pitch, roll])).as_matrix()
    wz = np.interp(t, plan.t, plan.twist[:, 2])
    gsig = float(c["gyro_sigma_radps"])
    R_bi = mount_rotation(mount)
    w_base = np.column_stack([np.zeros(len(t)), np.zeros(len(t)), wz + float(c["gyro_bias_radps"])])
    ocov = np.diag([rp_sig**2, rp_sig**2, ysig**2 + 0.5 * amp**2])
    wcov = np.eye(3) * gsig**2
    burst = float(c.get("burst_period_s") or 0.0)
    out: list[tuple[float, str, object]] = []
    for k in range(len(t)):
        msg = imu_message(float(t[k]), R_wb[k], w_base[k], R_bi, ocov, wcov, frame_id=str(c["frame_id"]),
                          with_orientation=bool(c["orientation"]))
        # white gyro noise on the sensor's own axes
        assert msg.angular_velocity_radps is not None
        msg.angular_velocity_radps = msg.angular_velocity_radps + rng.normal(0, gsig, 3)
        arrival = (np.floor(t[k] / burst) + 1.0) * burst if burst > 0 else float(t[k])
        out.append((float(arrival), "/imu", msg))
    return out


def _moving_obstacles(sc: dict, t: float) -> FloatArray:
    obs = sc.get("faults", {}).get("moving_obstacles") or []
    out = []
    for o in obs:
        a = np.asarray(o["path"][0], dtype=float)
        b = np.asarray(o["path"][1], dtype=float)
        length = float(np.hypot(*(b - a)))
        s = (float(o.get("speed_mps", 0.5)) * max(t - float(o.get("start", 0.0)), 0.0)) % (2 * length)
        s = s if s <= length else 2 * length - s
        p = a + (b - a) * (s / max(length, 1e-9))
        out.append([p[0], p[1], float(o.get("radius_m", 0.3))])
    return np.asarray(out, dtype=float).reshape(-1, 3)


def _laser(sc: dict, plan: Plan, world: Any, rng: np.random.Generator,
           progress: Callable[[float], None] | None = None) -> list[tuple[str, object]]:
    L = sc["laser"]
    if not L.get("enabled", True):
        return []
    err = np.asarray(L.get("mount_error") or (0.0, 0.0, 0.0), dtype=float).reshape(3)
    mount = compose(np.asarray(L["mount"], dtype=float), np.array([err[0], err[1], np.deg2rad(err[2])]))
    sweep = -1.0 if L.get("upside_down") else 1.0  # upside down: the scan's angles turn about the robot's -z
    rate = float(L["rate_hz"])
    n = int(round(float(L["fov_deg"]) / float(L["step_deg"]))) + 1
    inc = np.deg2rad(float(L["step_deg"]))
    amin = -np.deg2rad(float(L["fov_deg"])) / 2
    beam_angles = amin + inc * np.arange(n)
    rmin, rmax = float(L["range_min_m"]), float(L["range_max_m"])
    blackout = sc.get("faults", {}).get("laser_blackout")
    delay = float(L.get("stamp_delay_s") or 0.0)  # a late driver: stamped after the measurement
    out: list[tuple[str, object]] = []
    t = plan.t[0] + rng.uniform(0, 1 / rate)
    while True:
        period = (1.0 / rate) * (1.0 + rng.uniform(-float(L["jitter"]), float(L["jitter"])))
        tinc = period / (360.0 / float(L["step_deg"]))  # the mirror turns 360 deg per period
        tb = t + tinc * np.arange(n)
        if tb[-1] > plan.t[-1]:
            break
        if not (blackout and _in_window(np.array([t]), blackout)[0]):
            base = interpolate_poses(plan.t, plan.poses, tb)
            lp = compose(base, mount)
            ang = lp[:, 2] + sweep * beam_angles + rng.normal(0, np.deg2rad(float(L["angle_sigma_deg"])), n)
            r = world.raycast(lp[:, :2], ang, rmax + 0.1, extra_circles=_moving_obstacles(sc, t))
            sig = np.where(r < 30.0, float(L["range_sigma_m"]), float(L["range_sigma_far_m"]))
            with np.errstate(invalid="ignore"):
                r = r + rng.normal(0, 1, n) * sig
            r = np.where(r > rmax, np.inf, r)
            r = np.where(r < rmin, -np.inf, r)
            out.append(("/scan", LaserScan(float(t) + delay, float(amin), float(inc), rmin, rmax,
                                           r.astype(np.float32), time_increment=float(tinc),
                                           scan_time=float(period))))
        t += period
        if progress is not None:
            progress(min((t - plan.t[0]) / max(plan.t[-1] - plan.t[0], 1e-9), 1.0))
    return out


# --------------------------------------------------------------------- API
def run_scenario(path_or_dict: str | Path | dict, seed: int = 0,
                 progress: Callable[[float], None] | None = None) -> SimResult:
    """Simulate a scenario (YAML path or dict over :data:`DEFAULT_SCENARIO`), deterministic per seed.

    ``progress``, if given, is called with the simulated fraction (0..1) as the laser is simulated.
    """
    sc = load_scenario(path_or_dict)
    rng = np.random.default_rng(seed)
    rngs = rng.spawn(4)
    world, occ = build_world(sc)
    plan = true_motion(sc)
    if sc["map"] == "hall" and not world.is_free(plan.poses[::25, :2], clearance=0.3).all():
        raise ConfigError("scenario route runs into an obstacle")
    off_deg = (sc["compass"] or {}).get("offset_deg")
    offset = float(np.deg2rad(off_deg)) if off_deg is not None else float(
        np.deg2rad(rngs[0].uniform(5.0, 25.0) * rngs[0].choice([-1.0, 1.0])))
    mount = StaticTransform("base_link", "laser", np.asarray(sc["laser"]["mount"], dtype=float), z=0.2)
    tf: list[StaticTransform] = [mount]
    imu_mount = None
    timed: list[tuple[float, str, object]] = []
    if sc.get("imu") is not None:
        imu_off = sc["imu"].get("offset_deg")
        if imu_off is not None:
            offset = float(np.deg2rad(imu_off))
        imu_mount = imu_mount_transform(sc)
        tf.append(imu_mount)
        timed += _imu(sc, plan, offset, imu_mount_transform(sc, true_mount=True), rngs[2])
    msgs: list[tuple[str, object]] = [("/tf_static", tf)]
    odom = _odometry(sc, plan, rngs[1])
    late = float((sc.get("faults", {}).get("odometry_late") or {}).get("delay_s") or 0.0)
    if late > 0:
        timed += [(float(m.stamp) + late, topic, m) for topic, m in odom]  # type: ignore[attr-defined]
    else:
        msgs += odom
    if sc.get("imu") is None and sc.get("compass") is not None:
        msgs += _compass(sc, plan, offset, rngs[2])
    msgs += _laser(sc, plan, world, rngs[3], progress)
    gt_rate = float(sc["ground_truth_rate_hz"])
    t_gt = np.arange(plan.t[0], plan.t[-1], 1.0 / gt_rate)
    gt_poses = interpolate_poses(plan.t, plan.poses, t_gt)
    gt_twist = np.column_stack([np.interp(t_gt, plan.t, plan.twist[:, i]) for i in range(3)])
    for k in range(len(t_gt)):
        msgs.append(("/ground_truth", Odometry(float(t_gt[k]), gt_twist[k], None, gt_poses[k], frame_id="map")))
    first = msgs[0]
    # arrival order: the stamp, unless a sensor arrives late (IMU bursts)
    arr = [(float(m[1].stamp), m[0], m[1]) for m in msgs[1:]] + timed  # type: ignore[attr-defined]
    arr.sort(key=lambda a: a[0])
    rest = [(topic, msg) for _, topic, msg in arr]
    robot = {"drive": sc["drive"], **sc["robot"], "pulses_per_rev": sc["odom"]["pulses_per_rev"]}
    return SimResult(occ, [first] + rest, Trajectory(t_gt, gt_poses), mount, offset, robot, sc, imu_mount)


def simulate_paper(seed: int = 0, **overrides: Any) -> SimResult:
    """The paper's experiment: a mecanum robot at 0.8 m/s once around a 78 m rectangle in a hall.

    ``overrides`` are scenario keys merged over :data:`DEFAULT_SCENARIO` (e.g. ``route=...``,
    ``laser={"range_max_m": 10.0}``); ``progress`` (a callable) is passed to :func:`run_scenario`.
    """
    progress = overrides.pop("progress", None)
    return run_scenario(dict(overrides), seed=seed, progress=progress)


#: the files :func:`write_sim` writes
SIM_FILES = ("log.mcap", "map.yaml", "map.pgm", "ground_truth.tum", "scenario.yaml")


def write_sim(result: SimResult, outdir: str | Path) -> Path:
    """Write ``log.mcap``, ``map.yaml`` + ``map.pgm``, ``ground_truth.tum`` and ``scenario.yaml`` into outdir."""
    from fgloc.io.mcap_writer import LogWriter
    from fgloc.io.tum import write_tum
    from fgloc.io.yamlio import write_yaml

    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    imu_as_heading = False
    with LogWriter(out / "log.mcap") as w:
        for i, (topic, msg) in enumerate(result.messages):
            if isinstance(msg, Imu):
                try:
                    w.write(topic, msg)
                    continue
                except TypeError:
                    # a log writer without sensor_msgs/Imu in full: the reading in base_link
                    msg = _imu_as_heading(msg, result.imu_mount)
                    imu_as_heading = True
            w.write(topic, msg, stamp=0.0 if i == 0 and topic == "/tf_static" else None)
    result.map.save(out / "map.yaml")
    write_tum(out / "ground_truth.tum", result.ground_truth)
    info = dict(result.scenario)
    info["effective"] = {
        "compass_offset_deg": float(np.rad2deg(result.compass_offset_rad)),
        "laser_mount": [float(v) for v in result.laser_mount.pose],
        "duration_s": float(result.ground_truth.duration),
        "path_length_m": float(result.ground_truth.path_length()),
    }
    if imu_as_heading:
        info["effective"]["imu_written_as"] = "yaw and yaw rate in base_link (the log writer takes no full Imu)"
    write_yaml(out / "scenario.yaml", info)
    return out


def _imu_as_heading(msg: Imu, mount: StaticTransform | None) -> CompassHeading:
    from fgloc.frames.imu import imu_in_base, mount_rotation

    b, _ = imu_in_base(msg, mount_rotation(mount))
    return CompassHeading(b.stamp, b.yaw_rad, b.yaw_rate_radps, b.yaw_var, b.yaw_rate_var, frame_id="base_link")
