"""What the sources and the back-end say about each input: the per-source health report, the
motion model line, and their one-line forms (the run summary's lines, a live status line).

The report of a source (:func:`source_report`) is its handler's counts and checks with what the
back-end estimated about it: the noise it showed against what its messages claimed, its gated
measurements, an odometry's speed and yaw-rate scales, an IMU's gyro bias; the scan source's
(:func:`scan_report`) the front-end's accepted and gated fixes and the scan latency.
``Localizer.stats['sources']`` holds them after the run (:meth:`SourceRouter.finish`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from fgloc.backends.contract import Capability
from fgloc.localization.sources.handler import SourceHandler
from fgloc.localization.sources.imu import MAX_YAW_SIGMA_RAD
from fgloc.localization.sources.odometry import MAX_TILT_RAD

if TYPE_CHECKING:
    from fgloc.localization.stats import RunStats

#: the back-end's streams of a source, by the key a report files them under: the source's own
#: stream (``odom``, a pose source's name) is ``noise``, an IMU's ``NAME.yaw`` / ``NAME.gyro``
#: are ``yaw`` / ``gyro``
STREAM_KEYS = ("noise", "yaw", "gyro")
#: ms: an unapplied latency estimate this uncertain measures nothing yet (a handful of fixes); not printed as a number
UNMEASURED_LATENCY_MS = 1000.0


@dataclass
class StreamNoise:
    """The noise one of a source's streams showed against the other sources of the same quantity
    (the back-end's :meth:`~fgloc.backends.contract.Backend.source_noise`): ``x_claimed`` times
    what its messages claimed, plus ``per_turn`` of each turn (0: none); ``shown_vs_claimed``:
    the shown sigma over the claimed one (None before there is evidence)."""

    x_claimed: float
    per_turn: float = 0.0
    shown_vs_claimed: float | None = None


@dataclass
class SourceReport:
    """One source's health after a run (``Localizer.stats['sources'][name]``): what its handler
    counted and checked, and what the back-end estimated about it.  None / 0 / empty: not known
    or not applicable (the scan source has no topic; only an odometry has scales)."""

    kind: str
    accepted: int = 0
    gated: int = 0
    skipped: int = 0
    skipped_reasons: dict[str, int] = field(default_factory=dict)
    topic: str | None = None
    use: list[str] = field(default_factory=list)
    mount: str | None = None  # an IMU's mount when it was not the log's from the start
    mount_late: int = 0  # messages taken as identity before the mount arrived
    unmounted: int = 0  # messages of a frame no transform chain connects to the base, used unmounted
    levelled: int = 0  # odometry messages levelled by the IMU's roll / pitch
    tilt_max_deg: float = 0.0
    tilt_implausible: int = 0  # odometry messages not levelled (tilt beyond MAX_TILT_RAD, or NaN)
    tilt_unusable: int = 0  # IMU readings whose roll / pitch variance says they are not estimated
    yaw_unusable: int = 0  # IMU readings whose yaw variance says it is not estimated
    #: the back-end's gated measurements by stream: ``backend`` (the source's own), ``yaw``, ``gyro``
    stream_gated: dict[str, int] = field(default_factory=dict)
    noise: dict[str, StreamNoise] = field(default_factory=dict)  # by :data:`STREAM_KEYS`
    from_poses: int = 0  # odometry twists the tracker replaced by pose increments
    from_poses_why: str = ""
    vy_max_mps: float | None = None  # the largest lateral velocity the odometry reported
    speed_scale: float | None = None  # the odometry's, reported / true
    yaw_rate_scale: float | None = None
    silent: bool = False  # a source the log never fed (the default layout's /imu on a wheels-only log too)
    gyro_bias_radps: float | None = None
    latency_s: float | None = None  # the scans' latency in use
    latency_estimate_s: float | None = None
    latency_sigma_s: float | None = None
    latency_not_applied: str | None = None  # why the measured latency is not the one in use

    @property
    def all_gated(self) -> int:
        """Gated by the handler (a pose source's gate) and by the back-end on every stream."""
        return int(self.gated) + sum(int(v) for v in self.stream_gated.values())

    def to_dict(self) -> dict[str, Any]:
        """The report as plain values (YAML / JSON), the known fields only."""
        d: dict[str, Any] = {"kind": self.kind, "accepted": self.accepted, "gated": self.gated,
                             "skipped": self.skipped}
        if self.skipped_reasons:
            d["skipped_reasons"] = dict(self.skipped_reasons)
        for k in ("topic", "mount", "vy_max_mps", "speed_scale", "yaw_rate_scale", "gyro_bias_radps", "latency_s",
                  "latency_estimate_s", "latency_sigma_s", "latency_not_applied"):
            v = getattr(self, k)
            if v is not None:
                d[k] = v
        if self.topic is not None:
            d["use"] = list(self.use)
        for k in ("mount_late", "unmounted", "levelled", "tilt_implausible", "tilt_unusable", "yaw_unusable",
                  "from_poses", "silent"):
            if getattr(self, k):
                d[k] = getattr(self, k)
        if self.levelled:
            d["tilt_max_deg"] = self.tilt_max_deg
        if self.from_poses:
            d["from_poses_why"] = self.from_poses_why
        for k, n in self.stream_gated.items():
            d[f"{k}_gated"] = n
        for k, sn in self.noise.items():
            d["noise_x_claimed" if k == "noise" else f"{k}_noise_x_claimed"] = sn.x_claimed
            if sn.per_turn:
                d[f"{k}_noise_per_turn"] = sn.per_turn
            if sn.shown_vs_claimed is not None:
                d[f"{k}_shown_vs_claimed"] = sn.shown_vs_claimed
        return d


def source_report(h: SourceHandler, loc: Any) -> SourceReport:
    """One source's health: counts, checks, and what the back-end estimated about it."""
    s, st = h.spec, h.state
    be = loc.backend
    hh = st.health
    r = SourceReport(hh.kind, hh.accepted, hh.gated, hh.skipped, dict(hh.skipped_reasons), topic=s.topic,
                     use=list(s.use))
    if st.extra.get("no_transform"):
        k_un = int(st.extra["no_transform"])
        frame = str(st.extra.get("no_transform_frame", ""))
        r.mount = f"{h.ctx.mounts.unconnected(frame)}: {k_un} message{'s' if k_un != 1 else ''} used unmounted"
        r.unmounted = k_un
    elif st.extra.get("mount_late"):
        k = int(st.extra["mount_late"])
        r.mount = f"from tf after {k} message{'s' if k != 1 else ''} (identity until then)"
        r.mount_late = k
    if st.extra.get("levelled"):
        r.levelled = int(st.extra["levelled"])
        r.tilt_max_deg = round(math.degrees(st.extra.get("tilt_max_rad", 0.0)), 2)
    if st.extra.get("tilt_implausible"):
        r.tilt_implausible = int(st.extra["tilt_implausible"])
    if st.extra.get("tilt_unusable"):
        r.tilt_unusable = int(st.extra["tilt_unusable"])
    if st.extra.get("yaw_unusable"):
        r.yaw_unusable = int(st.extra["yaw_unusable"])
    bhs = be.source_health()
    for n in h.backend_streams():
        bh = bhs.get(n)
        if bh is not None:
            r.stream_gated[n.split(".")[-1] if "." in n else "backend"] = bh.gated
        # the noise the stream showed against the others (an odometry's: only when it fuses its yaw)
        noise = be.source_noise(n) if h.reports_noise() else None
        if noise is not None:
            shown, claimed, c = noise.shown_sigma, noise.claimed_sigma, noise.per_turn
            r.noise[n.split(".")[-1] if "." in n else "noise"] = StreamNoise(
                round(noise.k_claimed, 3), round(c, 3) if c > 0 else 0.0,
                round(shown / claimed, 3) if shown is not None and claimed else None)
    h.report_estimates(r)
    if not st.messages:
        r.silent = True  # a source the log never fed (a configured one is also warned about: SourceRouter.finish)
    return r


def scan_report(loc: Any) -> SourceReport | None:
    """The scan source's health: the front-end's fixes accepted and gated, the scan latency (None:
    no front-end, or a back-end that does not estimate the latency)."""
    be = loc.backend
    if loc.frontend is None or Capability.LATENCY not in be.capabilities:
        return None
    used = round(float(be.latency_estimate()), 4)
    r = SourceReport("pose", accepted=int(loc.stats.get("fixes", 0)), gated=int(be.stats.get("fixes_rejected", 0)),
                     latency_s=used)
    fit = be.latency_fit()
    if fit is not None:
        r.latency_estimate_s = round(fit[0], 4)
        r.latency_sigma_s = round(fit[1], 4)
        if abs(used - r.latency_estimate_s) > 5e-5:  # measured, but another value is in use
            section = be.config_section
            cfg = getattr(loc.config, section, None) if section else None  # the run's section, not the back-end
            r.latency_not_applied = (
                f"{section}.latency_s {cfg.latency_s:g} s is configured"
                if cfg is not None and cfg.latency_s is not None else
                f"{section}.latency is off" if cfg is not None and not cfg.latency
                else "not significant yet")
    return r


def summary_lines(stats: RunStats) -> list[str]:
    """The run summary's lines about the inputs: the motion model, each source's health and the
    odometry's clock."""
    out = []
    if stats.motion_model:
        out.append(f"motion model: {stats.motion_model}")
    for name, d in stats.sources.items():
        head = f"{name}"
        if d.topic:
            head += f" ({d.kind} {d.topic}: {' '.join(d.use)})"
        parts = [f"{d.accepted} accepted"]
        if d.silent:
            parts.append("no message on the topic in the whole log")
        if d.from_poses:
            parts.append(f"{d.from_poses} of {d.accepted} from pose increments: "
                         f"{d.from_poses_why or 'the twist disagreed with the poses'}")
        gated = d.all_gated
        if gated:
            parts.append(f"{gated} gated")
        if d.skipped:
            parts.append(f"{d.skipped} skipped")
        est = []
        if d.speed_scale is not None and abs(d.speed_scale - 1.0) > 1e-4:
            est.append(f"speed scale {d.speed_scale:.3f}")
        if d.yaw_rate_scale is not None and abs(d.yaw_rate_scale - 1.0) > 1e-4:
            est.append(f"yaw-rate scale {d.yaw_rate_scale:.3f} (reported / true)")
        if d.gyro_bias_radps is not None:
            est.append(f"gyro bias {d.gyro_bias_radps:.5f} rad/s")
        if d.latency_s is not None:
            used, sig = 1000 * d.latency_s, 1000 * (d.latency_sigma_s or 0)
            if d.latency_not_applied and d.latency_estimate_s is not None and sig > UNMEASURED_LATENCY_MS:
                s = f"latency {used:.1f} ms in use; too few fixes to measure it"
            elif d.latency_not_applied and d.latency_estimate_s is not None:
                # the estimate is not the value in use: say which is which, and why
                s = (f"latency {used:.1f} ms in use; measured {1000 * d.latency_estimate_s:.1f} +- {sig:.1f} ms, "
                     f"not applied ({d.latency_not_applied})")
            elif d.latency_estimate_s is not None:
                s = f"latency {used:.1f} +- {sig:.1f} ms (estimated)"
            else:
                s = f"latency {used:.1f} ms"
            est.append(s)
        for key, what in (("noise", "yaw"), ("yaw", "heading"), ("gyro", "gyro")):
            sn = d.noise.get(key)
            if sn is not None and sn.shown_vs_claimed is not None:
                est.append(f"{what} noise {sn.shown_vs_claimed:.2f}x claimed")
            if sn is not None and sn.per_turn:
                est.append(f"{what} error {100 * sn.per_turn:.0f} % of the turn")
        if d.mount:
            est.append(f"mount: {d.mount}")
        if d.levelled and d.tilt_max_deg > 0.0:  # (on level ground: nothing to say)
            est.append(f"levelled by the IMU's roll / pitch ({d.levelled} messages, tilt up to "
                       f"{d.tilt_max_deg:.1f} deg)")
        if d.tilt_implausible:
            est.append(f"{d.tilt_implausible} not levelled (tilt > {math.degrees(MAX_TILT_RAD):.0f} deg or NaN: "
                       "check the IMU mount)")
        if d.tilt_unusable:
            est.append(f"roll / pitch of {d.tilt_unusable} readings not used (variance says not estimated)")
        if d.yaw_unusable:
            est.append(f"yaw of {d.yaw_unusable} readings not used (sigma > {math.degrees(MAX_YAW_SIGMA_RAD):.0f} deg: "
                       "not estimated)")
        out.append(f"{head}: {', '.join(parts)}" + (f"; {'; '.join(est)}" if est else ""))
    clock = stats.odom_clock or {}
    if clock.get("slow"):  # a slow odometry's clock against the scans' (localization/clock.py)
        if clock.get("applied"):
            out.append(f"odometry clock: stamps moved {clock.get('offset_s', 0.0):+.3f} s onto the scans' clock "
                       f"(estimate {clock.get('estimate_s', 0.0):+.3f} +- {max(clock.get('sigma_s', 0.0), 0.0):.3f} s "
                       f"from {clock.get('pairs', 0)} fix pairs)")
        else:
            why = "stamps in bursts" if not clock.get("regular", True) else "no confident estimate"
            out.append(f"odometry clock: stamps kept ({why}; {clock.get('pairs', 0)} fix pairs)")
    return out


def status_line(health: dict[str, SourceReport]) -> str:
    """A one-line summary of :meth:`SourceRouter.health` for a live display."""
    parts = []
    for name, d in health.items():
        s = f"{name} {d.accepted}"
        if d.gated:
            s += f"/g{d.gated}"
        if d.skipped:
            s += f"/s{d.skipped}"
        if d.yaw_rate_scale is not None and abs(d.yaw_rate_scale - 1.0) > 0.02:
            s += f" yaw x{d.yaw_rate_scale:.2f}"
        if d.gyro_bias_radps is not None:
            s += f" bias {d.gyro_bias_radps * 1000:.1f}mrad/s"
        if d.latency_s:
            s += f" lat {d.latency_s * 1000:.0f}ms"
        parts.append(s)
    return " | ".join(parts)
