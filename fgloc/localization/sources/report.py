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
from typing import Any

from fgloc.backends.contract import Capability
from fgloc.localization.sources.handler import SourceHandler


def source_report(h: SourceHandler, loc: Any, configured_inputs: bool) -> dict[str, Any]:
    """One source's health: counts, checks, and what the back-end estimated about it."""
    s, st = h.spec, h.state
    be = loc.backend
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
    bhs = be.source_health()
    for n in h.backend_streams():
        bh = bhs.get(n)
        if bh is not None:
            d[f"{n.split('.')[-1] if '.' in n else 'backend'}_gated"] = bh.gated
        # the noise the stream showed against the others (an odometry's: only when it fuses its yaw)
        noise = be.source_noise(n) if h.reports_noise() else None
        if noise is not None:
            shown, claimed, k, c = noise.shown_sigma, noise.claimed_sigma, noise.k_claimed, noise.per_turn
            key = n.split(".")[-1] if "." in n else "noise"
            d[f"{key}_noise_x_claimed" if key != "noise" else "noise_x_claimed"] = round(k, 3)
            if c > 0:
                d[f"{key}_noise_per_turn"] = round(c, 3)
            if shown is not None and claimed:
                d[f"{key}_shown_vs_claimed"] = round(shown / claimed, 3)
    h.report_estimates(d)
    if configured_inputs and not st.messages:
        d["silent"] = True  # a configured source the log never fed
    return d


def scan_report(loc: Any) -> dict[str, Any] | None:
    """The scan source's health: the front-end's fixes accepted and gated, the scan latency (None:
    no front-end, or a back-end that does not estimate the latency)."""
    be = loc.backend
    if loc.frontend is None or Capability.LATENCY not in be.capabilities:
        return None
    d = {"kind": "pose", "accepted": int(loc.stats.get("fixes", 0)),
         "gated": int(be.stats.get("fixes_rejected", 0)),
         "latency_s": round(float(be.latency_estimate()), 4)}
    fit = be.latency_fit()
    if fit is not None:
        d["latency_estimate_s"] = round(fit[0], 4)
        d["latency_sigma_s"] = round(fit[1], 4)
    return d


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
