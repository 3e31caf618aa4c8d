"""Per-source inputs, robot_localization style: which topic is what, what each contributes.

The ``sources:`` config section lists input sources by name (``inputs:``); empty, the
default layout is used: ``odom`` (``nav_msgs/Odometry`` on ``/odom``: vx, vy, vyaw) and
``imu`` (``sensor_msgs/Imu`` on ``/imu``: yaw, vyaw), which reproduces fgloc's behaviour
before per-source inputs.  Each source::

    inputs:
      wheels:   {type: odometry, topic: /husky_velocity_controller/odom, use: [vx, vyaw]}
      imu:      {type: imu, topic: /imu/data, use: [yaw, vyaw], covariance: floor, sigmas: [0.01, 0.005]}
      mocap:    {type: pose, topic: /vicon/pose, use: [x, y, yaw], frame_id: map, gate: 16.3}

``type``: ``odometry`` | ``imu`` | ``pose`` (``geometry_msgs/PoseWithCovarianceStamped``).
``use``: a subset of ``x, y, yaw, vx, vy, vyaw`` (robot_localization's 15-element vector
reduced to the planar six); an IMU may add ``roll, pitch``: its attitude then levels the
odometry (the body velocity projected onto the ground plane, as robot_localization does in
3-D: a robot climbing a 10 deg slope drives 1.5 % less in the plane than its wheels say) and
its yaw rate is the heading's rate ``(sin(roll) w_y + cos(roll) w_z) / cos(pitch)``.
``differential``: use the increments of the source's poses
(odometry: as a twist; an IMU's orientation: as a yaw rate).  ``covariance``: ``message``
(as the message says), ``fixed`` (``sigmas``, one per used component), ``scaled`` (the
message's times ``scale^2``) or ``floor`` (the message's, at least ``sigmas^2``).  ``gate``:
a Mahalanobis (squared) gate against the prediction (pose sources).  ``frame_id``: the frame a
pose source must be in.  The scan-to-map front-end is always a source (``scan``).

An IMU is rotated into ``base_link`` through its mount (``/tf_static`` ``base_link ->
header.frame_id``; :mod:`fgloc.backends.imu`): any 3-D mount when the message is a whole
:class:`~fgloc.types.Imu` (every log reader gives one) and the transform a
:class:`~fgloc.types.Transform3D` (every log reader's tf, and ``static_transforms``); with a
planar transform or a yaw-only reading (:class:`~fgloc.types.CompassHeading`: fgloc's serial
link, the paper simulator), the yaw mount is undone.  A frame without a transform is identity,
with one warning once :data:`MOUNT_WAIT_S` of its stamps passed without one (a ROS 2 recorder
logs ``/tf_static`` after the first IMU messages; a mount that arrives is applied from then on and
the summary says after how many).  A configured source (``sources.inputs``) that gets no message
in the whole log is a warning at the end (:meth:`SourceRouter.silent_sources`).

Bad input is counted and skipped, never raised: an IMU quaternion of zeros or not of unit
length, a covariance with a NaN or negative diagonal (each only when the source uses that
field: a gyro-only source's zero quaternion is not a fault), a pose in another frame than the
one configured.  :meth:`SourceRouter.health` (and ``Localizer.stats['sources']`` after the run)
reports per source: accepted / gated / skipped counts with reasons, the estimated scale,
bias and latency, and the noise it showed against what its messages claimed;
:func:`status_line` is the one-line form for a live display.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from fgloc.backends.health import SourceHealth
from fgloc.backends.imu import imu_in_base, mount_rotation
from fgloc.config.schema import setting, unknown_key_error
from fgloc.errors import ConfigError
from fgloc.geometry import between, matrix_quaternion, rotate_covariance, wrap_angle, wrap_scalar
from fgloc.geometry import log as se2_log
from fgloc.io.topics import IMU, ODOMETRY, POSE_COV_STAMPED, normalize_type
from fgloc.localization.frames import ROBOT_FRAMES, parse_static_transforms, transform_of
from fgloc.types import CompassHeading, Imu, Odometry, PoseFix, StaticTransform

log = logging.getLogger(__name__)

COMPONENTS = ("x", "y", "yaw", "vx", "vy", "vyaw")
TILT = ("roll", "pitch")   # an IMU's attitude: levels the odometry (not estimated)
#: an attitude older than this (s) does not level an odometry message
MAX_TILT_AGE_S = 0.5
#: a base tilted more than this (rad) is no ground robot on a slope but a wrong mount: not levelled
MAX_TILT_RAD = math.radians(45.0)
TYPES = ("odometry", "imu", "pose")
POLICIES = ("message", "fixed", "scaled", "floor")
DEFAULT_USE = {"odometry": ("vx", "vy", "vyaw"), "imu": ("yaw", "vyaw"), "pose": ("x", "y", "yaw")}
DEFAULT_TOPIC = {"odometry": "/odom", "imu": "/imu", "pose": "/pose"}
#: the ROS message type a source of each type reads (as :func:`fgloc.io.topics.normalize_type` spells it)
MESSAGE_TYPES = {"odometry": ODOMETRY, "imu": IMU, "pose": POSE_COV_STAMPED}
#: an IMU frame that needs no mount: none given, or the robot's own (:data:`~fgloc.localization.frames.ROBOT_FRAMES`)
_OWN_FRAMES = ("", *ROBOT_FRAMES)
UNUSED_VAR = 1e6   # a component a source does not contribute: its variance
_IDENTITY = np.eye(3)
_IDENTITY.flags.writeable = False
_IDENTITY_ENTRY = (None, _IDENTITY, _IDENTITY.ravel().tolist())
#: s (of an IMU's stamps): an IMU frame without a mount is warned about only after this long without
#: one, or at the end of the log: a ROS 2 recorder logs /tf_static up to tens of ms after the first
#: IMU messages (TurtleBot3 bags: 0-53 ms), and a mount that arrives is applied from then on
MOUNT_WAIT_S = 1.0
#: a differential source's message stamped before the previous one: skipped, so that the next
#: increment spans from the newest pose (resetting the reference to it lost the increment before)
OUT_OF_ORDER = "differential: stamp not after the previous message's (out of order)"


@dataclass(frozen=True)
class SourcesConfig:
    """``sources:`` per-source inputs (see :mod:`fgloc.localization.sources`)."""

    inputs: dict = setting({}, "name -> {type: odometry|imu|pose, topic, use: [x, y, yaw, vx, vy, vyaw], "
                           "differential, covariance: message|fixed|scaled|floor, sigmas, scale, gate, frame_id}; "
                           "empty: odom (/odom: vx, vy, vyaw) and imu (/imu: yaw, vyaw)")
    static_transforms: list[dict] = setting([], "mounts the log lacks: [{parent: base_link, child: imu_link, "
                                      "xyz: [x, y, z], rpy_deg: [roll, pitch, yaw] | xyzw: [qx, qy, qz, qw]}]; "
                                      "they win over the log's /tf_static (fgloc.localization.frames)")


@dataclass
class SourceSpec:
    """One input source, checked."""

    name: str
    type: str
    topic: str
    use: tuple[str, ...]
    differential: bool = False
    covariance: str = "message"
    sigmas: tuple[float, ...] = ()
    scale: float = 1.0
    gate: float | None = None
    frame_id: str | None = None

    def uses(self, comp: str) -> bool:
        return comp in self.use

    @property
    def fused(self) -> tuple[str, ...]:
        """The used components the back-end fuses (``use`` without an IMU's levelling roll, pitch),
        in order: one sigma each for the ``fixed`` / ``floor`` policies."""
        return fused_components(self.use)


def fused_components(use: Sequence[str]) -> tuple[str, ...]:
    return tuple(u for u in use if u in COMPONENTS)


def parse_sources(cfg: SourcesConfig | dict | None, topics: Any = None, source: str = "config") -> list[SourceSpec]:
    """The sources of a ``sources:`` section (the default layout when it lists none); one-line
    :class:`ConfigError` naming the key for anything wrong.  ``topics`` renames the default
    layout's topics (``--odom-topic`` / ``--imu-topic``)."""
    inputs = (cfg.inputs if isinstance(cfg, SourcesConfig) else dict(cfg or {})) or {}
    if not inputs:
        names = {"odom": "/odom", "imu": "/imu"}
        if isinstance(topics, dict):
            names.update({k: str(v) for k, v in topics.items() if k in names and v})
        elif topics is not None:
            names.update({k: str(getattr(topics, k)) for k in names if getattr(topics, k, None)})
        return [SourceSpec("odom", "odometry", names["odom"], DEFAULT_USE["odometry"]),
                SourceSpec("imu", "imu", names["imu"], DEFAULT_USE["imu"])]
    out: list[SourceSpec] = []
    seen_topics: dict[str, str] = {}
    for name, d in inputs.items():
        where = f"{source}: sources.inputs.{name}"
        if not isinstance(d, dict):
            raise ConfigError(f"{where}: must be a mapping (type, topic, use, ...)")
        keys = ("type", "topic", "use", "differential", "covariance", "sigmas", "scale", "gate", "frame_id")
        unknown = set(d) - set(keys)
        if unknown:
            raise unknown_key_error(source, f"sources.inputs.{name}", sorted(unknown)[0], keys)
        typ = str(d.get("type", "")).lower()
        if typ not in TYPES:
            raise ConfigError(f"{where}.type: must be one of {', '.join(TYPES)}, got {d.get('type')!r}")
        use = tuple(str(u).lower() for u in (d.get("use") or DEFAULT_USE[typ]))
        allowed = COMPONENTS + TILT if typ == "imu" else COMPONENTS
        bad = [u for u in use if u not in allowed]
        if bad:
            raise ConfigError(f"{where}.use: {bad[0]!r} is not one of {', '.join(allowed)}")
        if typ == "imu" and (("roll" in use) != ("pitch" in use)):
            raise ConfigError(f"{where}.use: roll and pitch level the odometry together: use both or neither")
        pol = str(d.get("covariance", "message")).lower()
        if pol not in POLICIES:
            raise ConfigError(f"{where}.covariance: must be one of {', '.join(POLICIES)}, got {pol!r}")
        sig = tuple(float(s) for s in (d.get("sigmas") or ()))
        fused = fused_components(use)
        if pol in ("fixed", "floor") and len(sig) != len(fused):
            raise ConfigError(f"{where}.sigmas: {pol} needs one sigma per used component ({len(fused)}: "
                              f"{', '.join(fused)}), got {len(sig)}")
        if any(not (math.isfinite(s) and s > 0) for s in sig):
            raise ConfigError(f"{where}.sigmas: every sigma must be a positive number")
        gate = d.get("gate")
        if gate is not None and not (isinstance(gate, (int, float)) and gate > 0):
            raise ConfigError(f"{where}.gate: must be a positive number or null")
        topic = str(d.get("topic") or DEFAULT_TOPIC[typ])
        if topic in seen_topics:
            raise ConfigError(f"{where}.topic: {topic} is already source {seen_topics[topic]!r}")
        seen_topics[topic] = str(name)
        out.append(SourceSpec(str(name), typ, topic, use, bool(d.get("differential", False)), pol, sig,
                              float(d.get("scale", 1.0)), None if gate is None else float(gate),
                              None if d.get("frame_id") is None else str(d["frame_id"])))
    return out


def differential_cov(cov: np.ndarray, prev_cov: np.ndarray, prev_yaw: float, dt: float) -> np.ndarray:
    """The covariance of a differential source's twist, as robot_localization computes it (its
    ``*_differential`` mode, which the ported configs were tuned with): the two poses' covariances
    (``[x, y, yaw]``, the xy block turned from the source's frame into the earlier pose's body
    frame) summed and multiplied by ``dt``.  (Not ``(C1 + C2) / dt^2``: an odometry's poses are
    integrated, consecutive ones almost perfectly correlated, and that formula made the increments
    of r_l's test2.bag 125000 times less certain than robot_localization takes them, so the
    filter ignored them.)"""
    return np.asarray(rotate_covariance(np.asarray(cov) + np.asarray(prev_cov), -prev_yaw) * dt, dtype=float)


def _same_rotation(a: StaticTransform, b: StaticTransform) -> bool:
    qa, qb = getattr(a, "rotation_xyzw", None), getattr(b, "rotation_xyzw", None)
    if qa is None or qb is None:
        return qa is None and qb is None and float(a.pose[2]) == float(b.pose[2])
    return bool(np.array_equal(np.asarray(qa), np.asarray(qb)))


def _needed(spec: SourceSpec, msg: Imu) -> Imu:
    """``msg`` without the fields ``spec`` does not use (their faults are none of its business):
    the orientation serves yaw, roll / pitch and orientation increments, the angular velocity
    vyaw (and a levelling IMU's heading rate)."""
    orient = spec.uses("yaw") or spec.uses("roll")
    rates = spec.uses("vyaw")
    if orient and rates:
        return msg
    return replace(msg, orientation_xyzw=msg.orientation_xyzw if orient else None,
                   orientation_cov=msg.orientation_cov if orient else None,
                   angular_velocity_radps=msg.angular_velocity_radps if rates else None,
                   angular_velocity_cov=msg.angular_velocity_cov if rates else None)


def _cov_bad(c: Any) -> bool:
    """A covariance (3x3, or its diagonal) with a NaN / inf / negative variance (scalar checks:
    every odometry message passes here)."""
    if c is None:
        return False
    a = c if isinstance(c, np.ndarray) else np.asarray(c, dtype=float)
    d = a.ravel().tolist()
    if len(d) == 9:
        d = d[::4]
    return not all(math.isfinite(v) and v >= 0 for v in d)


@dataclass
class _State:
    health: SourceHealth
    prev_pose: tuple[float, np.ndarray] | None = None
    prev_yaw: tuple[float, float] | None = None
    fused: bool = True
    messages: int = 0          # every message routed to the source, whatever became of it
    vy_max: float = 0.0        # the largest |lateral velocity| an odometry's messages reported (m/s)
    extra: dict = field(default_factory=dict)


class SourceRouter:
    """Routes each configured source's messages into the localizer (see the module docstring)."""

    def __init__(self, loc: Any, specs: list[SourceSpec], static: Sequence[StaticTransform] | None = None) -> None:
        self.loc = loc
        self.specs = specs
        # configured mounts (sources.static_transforms) win over the log's
        self.configured = {t.child.lstrip("/"): t for t in static or ()}
        self.mounts: dict[str, StaticTransform] = dict(self.configured)
        # every tf link by child frame: an IMU mounted through a chain (base_link -> plate -> imu)
        self._links: dict[str, StaticTransform] = {}
        self._chains: dict[str, StaticTransform | None] = {}
        # the mounts' rotations by frame (and their entries as floats)
        self._rotations: dict[str, tuple[StaticTransform | None, np.ndarray, list[float]]] = {}
        self._warned: set[str] = set()
        self._twist_uses: dict[str, tuple[SourceSpec, bool, bool]] = {}   # _twist_use's answers by source
        self.state: dict[str, _State] = {}
        self._tilt: tuple[float, float, float] | None = None   # t, roll, pitch of the base (levelling IMU)
        self._tilt_source: str | None = None
        self.configured_inputs = False  # the specs came from a config's sources.inputs (install_sources)
        #: the log's topics and their message types (``{"/imu": "sensor_msgs/msg/Imu"}``), when the
        #: caller knows them: a silent source's warning names the log's topics of its type
        self.log_topics: dict[str, str] | None = None
        first: dict[str, str] = {}
        for s in specs:
            kind = {"odometry": "odometry", "imu": "imu", "pose": "pose"}[s.type]
            st = _State(SourceHealth(s.name, kind))
            # the back-ends integrate one twist source and one heading frame: the first of each
            if s.type in ("odometry", "imu"):
                if s.type in first:
                    st.fused = s.type == "imu"  # a second IMU still gives its yaw rate
                    st.extra["second"] = True
                else:
                    first[s.type] = s.name
            self.state[s.name] = st

    # ------------------------------------------------------------------ session wiring
    def install(self, session: Any) -> None:
        """Route every source's topic (and ``/tf_static`` / ``/tf``) to this router; messages
        dispatched by kind (``odom``, ``imu``: ``fgloc live``'s sensor threads) go to the first
        source of that type, so they are checked and counted the same way."""
        first: dict[str, SourceSpec] = {}
        for s in self.specs:
            kind = f"source:{s.name}"
            session.routes.table[s.topic] = kind
            session.register(kind, (lambda msg, spec=s: self.on_message(spec, msg)))
            first.setdefault(s.type, s)
        for kind, typ in (("odom", "odometry"), ("imu", "imu")):
            if typ in first:
                session.register(kind, (lambda msg, spec=first[typ]: self.on_message(spec, msg)))
        for tf_topic in ("/tf_static", "/tf"):
            if tf_topic not in session.routes.table:
                session.routes.table[tf_topic] = "tf"
        session.register("tf", self.on_tf)

    def on_tf(self, msg: object) -> None:
        if isinstance(msg, (list, tuple)):
            for tr in msg:
                if not isinstance(tr, StaticTransform):
                    continue
                child = tr.child.lstrip("/")
                if child in self.configured or child in ROBOT_FRAMES:
                    continue
                if tr.parent.lstrip("/") in ROBOT_FRAMES:
                    self.mounts[child] = tr
                old = self._links.get(child)
                if old is None or not _same_rotation(old, tr) or old.parent != tr.parent:
                    self._chains.clear()
                self._links[child] = tr

    def _chain(self, frame: str) -> StaticTransform | None:
        """``base_link -> frame`` through the tf links (rotation composed; None: no chain)."""
        if frame in self._chains:
            return self._chains[frame]
        R, cur, out = np.eye(3), frame, None
        for _ in range(32):
            tr = self._links.get(cur)
            if tr is None:
                break
            R = mount_rotation(tr) @ R
            cur = tr.parent.lstrip("/")
            if cur in ROBOT_FRAMES:
                out = transform_of(cur, frame, [0.0, 0.0, 0.0], matrix_quaternion(R).tolist())
                break
        self._chains[frame] = out
        return out

    def on_message(self, spec: SourceSpec, msg: object) -> None:
        st = self.state[spec.name]
        st.messages += 1
        try:
            if spec.type == "odometry" and isinstance(msg, Odometry):
                self._odometry(spec, st, msg)
            elif spec.type == "imu" and isinstance(msg, (Imu, CompassHeading)):
                self._imu(spec, st, msg)
            elif spec.type == "pose" and isinstance(msg, PoseFix):
                self._pose(spec, st, msg)
            else:
                self._skip(st, f"{type(msg).__name__} on a {spec.type} source")
        except (ValueError, FloatingPointError, np.linalg.LinAlgError) as e:
            self._skip(st, f"bad message ({e.__class__.__name__})")

    def _skip(self, st: _State, reason: str) -> None:
        """Count a skipped input on its source and in the localizer's summary."""
        st.health.skip(reason)
        stats = self.loc.stats
        stats["skipped"] = stats.get("skipped", 0) + 1
        r = stats.setdefault("skipped_reasons", {})
        key = f"{st.health.name}: {reason}"
        r[key] = r.get(key, 0) + 1

    # ------------------------------------------------------------------ covariance policy
    def _var(self, spec: SourceSpec, comp: str, msg_var: float) -> float:
        """The variance of ``comp`` under the source's policy (NaN: the back-end default)."""
        if not spec.uses(comp):
            return UNUSED_VAR
        pol = spec.covariance
        if pol == "fixed":
            return spec.sigmas[spec.fused.index(comp)] ** 2
        if pol == "scaled":
            return msg_var * spec.scale**2 if math.isfinite(msg_var) else msg_var
        if pol == "floor":
            s2 = spec.sigmas[spec.fused.index(comp)] ** 2
            return max(msg_var, s2) if math.isfinite(msg_var) else s2
        return msg_var

    # ------------------------------------------------------------------ odometry
    def _odometry(self, spec: SourceSpec, st: _State, msg: Odometry) -> None:
        h = st.health
        # a second odometry source: its velocities are measurements in a back-end that takes them
        # (the EKF's add_velocity; the smoothers' integrate them into a factor of their own); a
        # back-end without add_velocity integrates one twist source and skips it
        add_vel = None if st.fused else getattr(self.loc.backend, "add_velocity", None)
        if not st.fused and add_vel is None:
            self._skip(st, "a second odometry source (this back-end integrates one twist source; the EKF fuses "
                       "its velocities)")
            return
        if _cov_bad(msg.twist_cov) or (spec.differential and _cov_bad(msg.pose_cov)):
            self._skip(st, "covariance with a NaN or negative diagonal")
            return
        tw = np.asarray(msg.twist, dtype=float).reshape(-1)
        cov = None if msg.twist_cov is None else np.array(msg.twist_cov, dtype=float).reshape(3, 3)
        tw_msg, cov_msg = tw.copy(), cov
        if tw.shape == (3,):
            vy = abs(float(tw[1]))
            if vy > st.vy_max:  # (a NaN never is)
                st.vy_max = vy
        pose = None if msg.pose is None else np.asarray(msg.pose, dtype=float).reshape(-1)
        velocities, whole_twist = self._twist_use(spec)
        if spec.differential or not velocities:
            # robot_localization's differential mode: the twist of the pose increments
            pc = None if msg.pose_cov is None else np.asarray(msg.pose_cov, dtype=float).reshape(3, 3)
            if pose is not None and st.prev_pose is not None and not msg.stamp > st.prev_pose[0]:
                # out of order: the increments go on from the newest pose (none is lost)
                self._skip(st, OUT_OF_ORDER)
                return
            prev, st.prev_pose = st.prev_pose, (None if pose is None else (float(msg.stamp), pose))
            prev_pc, st.extra["prev_pose_cov"] = st.extra.get("prev_pose_cov"), pc
            if pose is None:
                self._skip(st, "differential source without poses")
                return
            if prev is None or not msg.stamp > prev[0]:
                return
            dt = float(msg.stamp) - prev[0]
            tw = se2_log(between(prev[1], pose)) / dt
            cov = None if pc is None else \
                differential_cov(pc, pc if prev_pc is None else prev_pc, float(prev[1][2]), dt)
            comps: tuple[str, ...] = ("x", "y", "yaw")
            mixed = [i for i, (pc_, vc) in enumerate((("x", "vx"), ("y", "vy"), ("yaw", "vyaw")))
                     if not spec.uses(pc_) and spec.uses(vc)]
            if mixed:
                # an axis fused as a velocity beside the increments of the others (r_l: x, y, vyaw)
                dflt = np.square(list(getattr(self.loc.backend, "encoder_sigmas", None) or (0.01, 0.01, 0.02)))
                tw = tw.copy()
                cov = np.diag(dflt) if cov is None else cov.copy()
                comps = tuple(("vx", "vy", "vyaw")[i] if i in mixed else c for i, c in enumerate(comps))
                for i in mixed:
                    tw[i] = tw_msg[i]
                    cov[i, :] = 0.0
                    cov[:, i] = 0.0
                    ok = cov_msg is not None and float(cov_msg[i, i]) > 0
                    cov[i, i] = float(cov_msg[i, i]) if ok and cov_msg is not None else float(dflt[i])
        else:
            comps = ("vx", "vy", "vyaw")
        default = list(getattr(self.loc.backend, "encoder_sigmas", None) or (0.01, 0.01, 0.02))
        if cov is None or not (cov[0, 0] > 0 and cov[1, 1] > 0 and cov[2, 2] > 0):
            cov = np.diag(np.square(default))
        if whole_twist:
            out = cov  # the default layout: the message's whole covariance, exactly as before
        else:
            out = np.zeros((3, 3))
            for i, c in enumerate(comps):
                v = self._var(spec, c, float(cov[i, i]))
                out[i, i] = v if math.isfinite(v) else default[i] ** 2
            # a diff drive that does not report vy: 0 with the message's (small) variance, as before
            if comps[1] == "vy" and not spec.uses("vy"):
                out[1, 1] = float(cov[1, 1])
        tw, out = self._levelled(st, float(msg.stamp), tw, out)
        if add_vel is not None:
            used = tuple(spec.uses(p) or spec.uses(v) for p, v in (("x", "vx"), ("y", "vy"), ("yaw", "vyaw")))
            add_vel(float(msg.stamp), tw, out, used, spec.name)
            h.accepted += 1
            return
        h.accepted += 1
        m = Odometry(float(msg.stamp), tw, out, None if spec.differential else msg.pose, None,
                     msg.frame_id, msg.child_frame_id)
        self.loc.on_odometry(m)

    def _twist_use(self, spec: SourceSpec) -> tuple[bool, bool]:
        """Whether an odometry source fuses any of vx, vy, vyaw, and whether it takes the message's
        whole twist and covariance as they are (all three, ``covariance: message``, not differential):
        worked out once per source (every odometry message asks)."""
        got = self._twist_uses.get(spec.name)
        if got is None or got[0] is not spec:
            got = self._twist_uses[spec.name] = (
                spec, any(spec.uses(c) for c in ("vx", "vy", "vyaw")),
                spec.covariance == "message" and set(spec.use) >= {"vx", "vy", "vyaw"} and not spec.differential)
        return got[1], got[2]

    def _levelled(self, st: _State, t: float, tw: np.ndarray, cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The body twist projected onto the ground plane through the levelling IMU's latest
        roll / pitch: ``[vx cos p + vy sin r sin p, vy cos r, w]`` (unchanged without one)."""
        if self._tilt is None or abs(t - self._tilt[0]) > MAX_TILT_AGE_S:
            return tw, cov
        _, r, p = self._tilt
        if abs(r) > MAX_TILT_RAD or abs(p) > MAX_TILT_RAD:
            st.extra["tilt_implausible"] = st.extra.get("tilt_implausible", 0) + 1
            return tw, cov
        cr, sr, cp, sp = math.cos(r), math.sin(r), math.cos(p), math.sin(p)
        J = np.array([[cp, sr * sp, 0.0], [0.0, cr, 0.0], [0.0, 0.0, 1.0]])
        st.extra["levelled"] = st.extra.get("levelled", 0) + 1
        st.extra["tilt_max_rad"] = max(st.extra.get("tilt_max_rad", 0.0), abs(r), abs(p))
        return J @ np.asarray(tw, dtype=float), J @ np.asarray(cov, dtype=float) @ J.T

    # ------------------------------------------------------------------ IMU
    def _mount(self, frame: str) -> StaticTransform | None:
        f = frame.lstrip("/")
        if f in _OWN_FRAMES:
            return None
        tr = self.mounts.get(f)
        if tr is None:
            tr = self._chain(f)
        return tr

    def _unmounted(self, st: _State, frame: str, t: float) -> None:
        """An IMU message of ``frame`` without a mount (yet): taken as identity, counted; warned about
        once :data:`MOUNT_WAIT_S` of its stamps have passed without one (or at :meth:`finish`)."""
        f = frame.lstrip("/")
        st.extra["no_transform"] = st.extra.get("no_transform", 0) + 1
        st.extra["no_transform_frame"] = f
        since = st.extra.setdefault("no_transform_since", t)
        if t - since >= MOUNT_WAIT_S:
            self._warn_mount(f)

    def _warn_mount(self, f: str) -> None:
        if f not in self._warned:
            self._warned.add(f)
            log.warning("no transform base_link -> %s: the IMU is taken as mounted like base_link", f)

    @staticmethod
    def _mounted(st: _State) -> None:
        """The mount arrived after messages taken as identity (a /tf_static logged late)."""
        if st.extra.get("no_transform"):
            st.extra["mount_late"] = st.extra.get("mount_late", 0) + int(st.extra.pop("no_transform"))
            st.extra.pop("no_transform_since", None)

    def _rotation(self, tr: StaticTransform | None) -> np.ndarray:
        """``mount_rotation(tr)``, computed once per transform (every IMU message asks; a new
        transform of the same frame replaces it)."""
        return self._rotation_entry(tr)[1]

    def _rotation_values(self, tr: StaticTransform | None) -> list[float]:
        """:meth:`_rotation`'s 9 entries row by row as floats (what :func:`imu_in_base` reads), kept with it."""
        return self._rotation_entry(tr)[2]

    def _rotation_entry(self, tr: StaticTransform | None) -> tuple[StaticTransform | None, np.ndarray, list[float]]:
        if tr is None:
            return _IDENTITY_ENTRY
        got = self._rotations.get(tr.child)
        if got is None or got[0] is not tr:
            R = mount_rotation(tr)
            got = self._rotations[tr.child] = (tr, R, R.ravel().tolist())
        return got

    def _imu(self, spec: SourceSpec, st: _State, msg: Imu | CompassHeading) -> None:
        h = st.health
        if isinstance(msg, Imu):
            mount = self._mount(msg.frame_id)
            if mount is None and msg.frame_id.lstrip("/") not in _OWN_FRAMES:
                self._unmounted(st, msg.frame_id, float(msg.stamp))
            elif mount is not None:
                self._mounted(st)
            base, problems = imu_in_base(_needed(spec, msg), self._rotation_values(mount))
            for p in problems:
                self._skip(st, p)
            yaw, yaw_var, rate, rate_var = base.yaw_rad, base.yaw_var, base.yaw_rate_radps, base.yaw_rate_var
            if spec.uses("roll") and base.roll_pitch_rad is not None:
                if self._tilt_source in (None, spec.name):  # the first levelling IMU levels
                    self._tilt_source = spec.name
                    self._tilt = (float(msg.stamp), *base.roll_pitch_rad)
                # the heading's rate on a slope; a tilt no ground robot drives on (an upside-down or
                # left-handed mount, as _levelled refuses it) keeps the base's own z rate
                if base.heading_rate_radps is not None and max(map(abs, base.roll_pitch_rad)) <= MAX_TILT_RAD:
                    rate = base.heading_rate_radps
        else:
            yaw, rate = msg.yaw_rad, msg.yaw_rate_radps
            yaw_var, rate_var = float(msg.yaw_var), float(msg.yaw_rate_var)
            if yaw is not None and (yaw_var < 0 or math.isinf(yaw_var)):
                self._skip(st, "imu: orientation covariance with a NaN or negative diagonal")
                yaw = None
            if rate is not None and (rate_var < 0 or math.isinf(rate_var)):
                self._skip(st, "imu: angular velocity covariance with a NaN or negative diagonal")
                rate = None
            # a yaw-only reading: an unknown yaw mount is absorbed by the heading offset estimate
            mount = self._mount(msg.frame_id)
            if mount is not None:
                R = self._rotation(mount)
                if yaw is not None:  # the reader gave the sensor frame's yaw: undo the mount's
                    yaw = float(wrap_angle(yaw - math.atan2(R[1, 0], R[0, 0])))
                if rate is not None:
                    if abs(R[2, 2]) < 0.9:
                        # the sensor's z axis is not the base's: its z rate is not the yaw rate, and
                        # a reader that gives only z cannot say what is (a skip only if it is used)
                        if spec.uses("vyaw"):
                            self._skip(st, "imu: yaw rate of a tilted mount not in the message (needs the whole Imu)")
                        rate = None
                    else:
                        rate = rate * float(np.sign(R[2, 2]))
        t = float(msg.stamp)
        add_rel = getattr(self.loc.backend, "add_relative_yaw", None)
        if spec.differential and yaw is not None and spec.uses("yaw") and not spec.uses("vyaw") \
                and add_rel is not None:
            # orientation increments as a heading with the source's own offset (a back-end that
            # takes them: the EKF), not as a rate d_yaw / d_t, which stamp jitter turns into spikes
            if st.prev_yaw is not None and not t > st.prev_yaw[0]:
                self._skip(st, f"imu: {OUT_OF_ORDER}")
                return
            st.prev_yaw = (t, yaw)
            add_rel(t, float(yaw), self._var(spec, "yaw", yaw_var), "imu" if not st.extra.get("second") else spec.name)
            h.accepted += 1
            return
        if spec.differential and yaw is not None:
            # orientation increments as a yaw rate (robot_localization's imuN_differential)
            var = yaw_var if math.isfinite(yaw_var) else 1e-4
            if st.prev_yaw is not None and not t > st.prev_yaw[0]:
                self._skip(st, f"imu: {OUT_OF_ORDER}")
                return
            prev, st.prev_yaw = st.prev_yaw, (t, yaw)
            prev_var, st.extra["prev_yaw_var"] = st.extra.get("prev_yaw_var", var), var
            if prev is not None and t > prev[0] and spec.uses("yaw"):
                d_rate = wrap_scalar(yaw - prev[1]) / (t - prev[0])
                if rate is None or not spec.uses("vyaw"):  # r_l's variance (differential_cov)
                    rate, rate_var = d_rate, (var + prev_var) * (t - prev[0])
            yaw = None
        if yaw is not None and spec.uses("yaw"):
            yaw_var = self._var(spec, "yaw", yaw_var)
        else:
            yaw = None
        if rate is not None and spec.uses("vyaw"):
            rate_var = self._var(spec, "vyaw", rate_var)
        elif not (spec.differential and rate is not None):
            rate = None
        if yaw is None and rate is None:
            if not h.skipped:  # an empty reading: the localizer counts it as it always did
                self.loc.on_compass(CompassHeading(t, None, None))
            return
        if st.extra.get("second"):
            yaw = None  # a second IMU's heading is in another world frame: only its rate is fused
            if rate is None:
                return
            add_gyro = getattr(self.loc.backend, "add_gyro", None)
            if add_gyro is not None and self.loc.backend.initialized:
                add_gyro(t, rate, rate_var, spec.name)
            h.accepted += 1
            return
        h.accepted += 1
        self.loc.on_compass(CompassHeading(t, yaw, rate, yaw_var if yaw is not None else float("nan"),
                                           rate_var if rate is not None else float("nan"), frame_id="base_link"))

    # ------------------------------------------------------------------ pose
    def _pose(self, spec: SourceSpec, st: _State, msg: PoseFix) -> None:
        h = st.health
        want = spec.frame_id or ("odom" if self.loc.odom_mode else "map")
        if msg.frame_id.lstrip("/") != want:
            self._skip(st, f"pose in frame {msg.frame_id!r}, not {want!r}")
            return
        pose = np.asarray(msg.pose, dtype=float).reshape(-1)
        cov = np.asarray(msg.cov, dtype=float).reshape(3, 3)
        if pose.shape != (3,) or not np.all(np.isfinite(pose)):
            self._skip(st, "pose not finite")
            return
        if _cov_bad(cov):
            self._skip(st, "covariance with a NaN or negative diagonal")
            return
        c = np.diag([self._var(spec, comp, float(cov[i, i])) for i, comp in enumerate(("x", "y", "yaw"))])
        if spec.covariance == "message":
            c = cov.copy()
            for i, comp in enumerate(("x", "y", "yaw")):
                if not spec.uses(comp):
                    c[i, :] = 0.0
                    c[:, i] = 0.0
                    c[i, i] = UNUSED_VAR
        if not np.all(np.diag(c) > 0):
            self._skip(st, "covariance zero (unknown): set covariance fixed with sigmas")
            return
        be = self.loc.backend
        if not be.initialized:
            self._skip(st, "before the localizer started")
            return
        t = float(msg.stamp)
        if spec.gate is not None:
            be.current(covariance=True)  # a fresh marginal to gate against (not the one an output last asked for)
            pred, pcov = be.predict(t)
            e = pose - pred
            e[2] = wrap_angle(e[2])
            try:
                d2 = float(e @ np.linalg.solve(pcov + c, e))
            except np.linalg.LinAlgError:
                d2 = math.inf
            if not d2 <= spec.gate:
                h.gated += 1
                return
        if spec.differential:
            self._skip(st, "differential pose sources are not fused (use an odometry source)")
            return
        used = be.add_keyframe(t, PoseFix(t, pose, c, source=spec.name, frame_id=want))
        if used:
            h.accepted += 1
        else:
            h.gated += 1

    # ------------------------------------------------------------------ health
    def health(self) -> dict[str, dict[str, Any]]:
        """Per source: counts, and what the back-end estimated about it (see the module docstring)."""
        be = self.loc.backend
        arb = getattr(be, "arb", None)
        out: dict[str, dict[str, Any]] = {}
        for s in self.specs:
            st = self.state[s.name]
            d = st.health.to_dict()
            d["topic"] = s.topic
            d["use"] = list(s.use)
            if st.extra.get("no_transform"):
                d["mount"] = "no transform: identity"
            elif st.extra.get("mount_late"):
                k = int(st.extra["mount_late"])
                d["mount"] = f"from tf after {k} message{'s' if k != 1 else ''} (identity until then)"
                d["mount_late"] = int(st.extra["mount_late"])
            if st.extra.get("levelled"):
                d["levelled"] = int(st.extra["levelled"])
                d["tilt_max_deg"] = round(math.degrees(st.extra.get("tilt_max_rad", 0.0)), 2)
            if st.extra.get("tilt_implausible"):
                d["tilt_implausible"] = int(st.extra["tilt_implausible"])
            names = {"odometry": ["odom"] if st.fused else [s.name],
                     "imu": [f"{s.name}.yaw", f"{s.name}.gyro"] if st.extra.get("second") else ["imu.yaw", "imu.gyro"],
                     "pose": [s.name]}[s.type]
            bhs = getattr(be, "sources", {})
            for n in names:
                bh = bhs.get(n)
                if bh is not None:
                    d[f"{n.split('.')[-1] if '.' in n else 'backend'}_gated"] = bh.gated
                # the noise an odometry's yaw rate showed: only when the source fuses its yaw
                if arb is not None and n in arb.streams and (s.type != "odometry" or s.uses("vyaw") or s.uses("yaw")):
                    shown, claimed = arb.shown_sigma(n), arb.claimed_sigma(n)
                    k, c = arb.noise(n)
                    key = n.split(".")[-1] if "." in n else "noise"
                    d[f"{key}_noise_x_claimed" if key != "noise" else "noise_x_claimed"] = round(k, 3)
                    if c > 0:
                        d[f"{key}_noise_per_turn"] = round(c, 3)
                    if shown is not None and claimed:
                        d[f"{key}_shown_vs_claimed"] = round(shown / claimed, 3)
            if s.type == "odometry" and st.fused and not s.differential:
                # twists the localizer's tracker replaced by pose increments (pipeline.pose_deltas)
                n_poses = int(self.loc.stats.get("odometry_from_poses", 0) or 0)
                if n_poses:
                    d["from_poses"] = n_poses
                    mode = getattr(getattr(self.loc, "pcfg", None), "pose_deltas", "auto")
                    d["from_poses_why"] = "pipeline.pose_deltas: always" if mode == "always" else \
                        "the twist disagreed with the poses (pipeline.pose_deltas: auto)"
                if st.messages:
                    d["vy_max_mps"] = round(st.vy_max, 4)
            if s.type == "odometry" and st.fused and hasattr(be, "odom_scales"):
                sc = be.odom_scales()
                d["speed_scale"] = round(float(sc[0]), 4)
                d["yaw_rate_scale"] = round(float(sc[1]), 4)
            if self.configured_inputs and not st.messages:
                d["silent"] = True  # a configured source the log never fed
            if s.type == "imu" and st.messages:
                b = None
                if hasattr(be, "gyro_bias"):
                    b = be.gyro_bias(s.name if st.extra.get("second") else "imu")
                if b is not None:
                    d["gyro_bias_radps"] = round(float(b), 7)
            out[s.name] = d
        if getattr(self.loc, "frontend", None) is not None and hasattr(be, "latency_estimate"):
            lat = getattr(be, "latency_est", None)
            d = {"kind": "pose", "accepted": int(self.loc.stats.get("fixes", 0)),
                 "gated": int(be.stats.get("fixes_rejected", 0)),
                 "latency_s": round(float(be.latency_estimate()), 4)}
            if lat is not None:
                est, sig = lat.estimate()
                if math.isfinite(sig):
                    d["latency_estimate_s"] = round(est, 4)
                    d["latency_sigma_s"] = round(sig, 4)
            out["scan"] = d
        return out

    def finish(self) -> None:
        for s in self.specs:
            st = self.state[s.name]
            if st.extra.get("no_transform"):  # the log ended before MOUNT_WAIT_S without a mount
                self._warn_mount(str(st.extra.get("no_transform_frame", "")))
        for line in self.silent_sources():
            log.warning("%s", line)
        self.loc.stats["sources"] = self.health()
        odo = [s for s in self.specs if s.type == "odometry" and self.state[s.name].fused]
        st0 = self.state[odo[0].name] if odo else None
        vy = None if st0 is None or not st0.messages or odo[0].differential else st0.vy_max
        self.loc.stats["motion_model"] = motion_model(self.loc.backend, vy)

    def silent_sources(self) -> list[str]:
        """One line per configured source (``sources.inputs``) that got no message in the whole run:
        the run went on without it (a ported robot_localization config naming a topic the log does
        not have).  The log's topics of that type are named when :attr:`log_topics` (topic ->
        message type, set by the caller that read the log) is known.  The default layout's sources
        are not configured: a log without ``/imu`` is a wheels-only log, not a mistake."""
        if not self.configured_inputs:
            return []
        out = []
        for s in self.specs:
            if self.state[s.name].messages:
                continue
            line = f"sources.inputs.{s.name}: no message on {s.topic} in the whole log; ran without it"
            if self.log_topics is not None:
                want = MESSAGE_TYPES[s.type]
                have = sorted(t for t, typ in self.log_topics.items() if normalize_type(typ) == want)
                what = want.split("/")[-1]
                line += f" (the log's {what} topics: {', '.join(have) if have else 'none'})"
            out.append(line)
        return out


def motion_model(backend: Any, vy_max_mps: float | None = None) -> str:
    """Which body twist the back-end integrates, and why (the run summary's line); ``vy_max_mps``:
    the largest lateral velocity the odometry's messages reported (None: unknown)."""
    st = getattr(backend, "stats", {})
    if "omni" not in st:  # the smoother / batch integrate the odometry's whole twist
        if vy_max_mps == 0.0:
            return "differential: the odometry's lateral velocity is 0 throughout (its whole twist is integrated)"
        if vy_max_mps is not None:
            return ("omni: the odometry's whole twist (vx, vy, w) is integrated (lateral velocity up to "
                    f"{vy_max_mps:.3f} m/s)")
        return "omni: the odometry's whole twist (vx, vy, w) is integrated"
    v = getattr(getattr(backend, "cfg", None), "omni_vy_mps", None)
    if st.get("omni_since") is not None:
        return "omni [x, y, yaw, vx, vy, w]: the odometry reported lateral velocity" + (f" (> {v} m/s)" if v else "")
    if st.get("omni"):
        return "omni [x, y, yaw, vx, vy, w] (configured: ekf.omni true)"
    cfg = getattr(backend, "cfg", None)
    if getattr(cfg, "omni", None) is False:
        why = "configured: ekf.omni false"
    elif vy_max_mps:
        why = (f"the lateral velocity it was handed stayed under ekf.omni_vy_mps {v} m/s; the messages reported up to "
               f"{vy_max_mps:.3f} m/s")
    else:
        why = "the odometry never reported lateral velocity"
    return f"differential [x, y, yaw, v, w] ({why})"


def summary_lines(stats: dict[str, Any]) -> list[str]:
    """The run summary's lines about the inputs: the motion model and each source's health
    (``Localizer.stats`` after the run: ``motion_model``, ``sources``)."""
    out = []
    if stats.get("motion_model"):
        out.append(f"motion model: {stats['motion_model']}")
    for name, d in (stats.get("sources") or {}).items():
        head = f"{name}"
        if d.get("topic"):
            head += f" ({d.get('kind')} {d['topic']}: {' '.join(d.get('use', []))})"
        parts = [f"{d.get('accepted', 0)} accepted"]
        if d.get("silent"):
            parts.append("no message on the topic in the whole log")
        if d.get("from_poses"):
            parts.append(f"{d['from_poses']} of {d.get('accepted', 0)} from pose increments: "
                         f"{d.get('from_poses_why', 'the twist disagreed with the poses')}")
        gated = int(d.get("gated", 0)) + sum(int(v) for k, v in d.items() if k.endswith("_gated"))
        if gated:
            parts.append(f"{gated} gated")
        if d.get("skipped"):
            parts.append(f"{d['skipped']} skipped")
        est = []
        if "speed_scale" in d and abs(d["speed_scale"] - 1.0) > 1e-4:
            est.append(f"speed scale {d['speed_scale']:.3f}")
        if "yaw_rate_scale" in d and abs(d["yaw_rate_scale"] - 1.0) > 1e-4:
            est.append(f"yaw-rate scale {d['yaw_rate_scale']:.3f} (reported / true)")
        if "gyro_bias_radps" in d:
            est.append(f"gyro bias {d['gyro_bias_radps']:.5f} rad/s")
        if "latency_s" in d:
            s = f"latency {1000 * d['latency_s']:.1f} ms"
            if "latency_estimate_s" in d:
                s += f" (estimate {1000 * d['latency_estimate_s']:.1f} +- {1000 * d.get('latency_sigma_s', 0):.1f})"
            est.append(s)
        for key, what in (("noise", "yaw"), ("yaw", "heading"), ("gyro", "gyro")):
            k = d.get(f"{key}_shown_vs_claimed")
            if k is not None:
                est.append(f"{what} noise {k:.2f}x claimed")
            c = d.get(f"{key}_noise_per_turn")
            if c:
                est.append(f"{what} error {100 * c:.0f} % of the turn")
        if d.get("mount"):
            est.append(f"mount: {d['mount']}")
        if d.get("levelled"):
            est.append(f"levelled by the IMU's roll / pitch ({d['levelled']} messages, tilt up to "
                       f"{d.get('tilt_max_deg', 0):.1f} deg)")
        if d.get("tilt_implausible"):
            est.append(f"{d['tilt_implausible']} not levelled (tilt > 45 deg: check the IMU mount)")
        out.append(f"{head}: {', '.join(parts)}" + (f"; {'; '.join(est)}" if est else ""))
    clock = stats.get("odom_clock") or {}
    if clock.get("slow"):  # a slow odometry's clock against the scans' (localization/clock.py)
        if clock.get("applied"):
            out.append(f"odometry clock: stamps moved {clock.get('offset_s', 0.0):+.3f} s onto the scans' clock "
                       f"(estimate {clock.get('estimate_s', 0.0):+.3f} +- {max(clock.get('sigma_s', 0.0), 0.0):.3f} s "
                       f"from {clock.get('pairs', 0)} fix pairs)")
        else:
            why = "stamps in bursts" if not clock.get("regular", True) else "no confident estimate"
            out.append(f"odometry clock: stamps kept ({why}; {clock.get('pairs', 0)} fix pairs)")
    return out


def source_topics(cfg: SourcesConfig | dict | None) -> dict[str, str]:
    """``{topic: type}`` of a ``sources:`` section's inputs (empty when it lists none: the
    default layout's topics are the command line's)."""
    inputs = (cfg.inputs if isinstance(cfg, SourcesConfig) else dict(cfg or {})) or {}
    if not inputs:
        return {}
    return {s.topic: s.type for s in parse_sources(cfg)}


def status_line(health: dict[str, dict[str, Any]]) -> str:
    """A one-line summary of :meth:`SourceRouter.health` for a live display."""
    parts = []
    for name, d in health.items():
        s = f"{name} {d.get('accepted', 0)}"
        if d.get("gated"):
            s += f"/g{d['gated']}"
        if d.get("skipped"):
            s += f"/s{d['skipped']}"
        if "yaw_rate_scale" in d and abs(d["yaw_rate_scale"] - 1.0) > 0.02:
            s += f" yaw x{d['yaw_rate_scale']:.2f}"
        if "gyro_bias_radps" in d:
            s += f" bias {d['gyro_bias_radps'] * 1000:.1f}mrad/s"
        if d.get("latency_s"):
            s += f" lat {d['latency_s'] * 1000:.0f}ms"
        parts.append(s)
    return " | ".join(parts)


def install_sources(session: Any) -> SourceRouter:
    """Build the router of the localizer's ``sources:`` section and wire it into ``session``."""
    loc = session.loc
    cfg = getattr(getattr(loc, "config", None), "sources", None)
    topics = {k: t for t, k in session.routes.table.items() if k in ("odom", "imu")}
    specs = parse_sources(cfg, topics)
    static = cfg.get("static_transforms") if isinstance(cfg, dict) else getattr(cfg, "static_transforms", None)
    router = SourceRouter(loc, specs, parse_static_transforms(static))
    inputs = cfg.get("inputs") if isinstance(cfg, dict) else getattr(cfg, "inputs", None)
    router.configured_inputs = bool(inputs)
    # the default kinds' topics now belong to the sources
    for t in [t for t, k in session.routes.table.items() if k in ("odom", "imu")]:
        del session.routes.table[t]
    router.install(session)
    return router
