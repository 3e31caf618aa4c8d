"""nav2 (``amcl:`` section; ROS 1 ``amcl`` node too) parameters -> fgloc's AMCL front-end.

==============================================  ==========================================
nav2_amcl                                       fgloc ``frontends.amcl``
==============================================  ==========================================
``alpha1`` .. ``alpha5``                        the same
``robot_model_type`` (``...DifferentialMotion``  ``differential`` / ``omni``
Model``, ``...OmniMotionModel``, ROS 1
``diff``/``omni``/``*-corrected``)
``laser_model_type``: ``likelihood_field``,     the same
``likelihood_field_prob``
``z_hit``, ``z_rand``, ``sigma_hit``            the same
``max_beams`` (ROS 1 ``laser_max_beams``)       ``laser_max_beams``
``laser_likelihood_max_dist``,                  the same
``laser_max_range``
``min_particles``, ``max_particles``,           the same
``pf_err``, ``pf_z``, ``resample_interval``
``recovery_alpha_slow`` / ``_fast``             the same
``update_min_d``, ``update_min_a``              the same
``scan_topic``                                  a note: pass ``--scan-topic``
==============================================  ==========================================

Everything else is one note line (the beam model and its ``z_short``/``z_max``/
``lambda_short``, beam skipping, frames, tf and pose-saving settings).
"""

from __future__ import annotations

from typing import Any

from fgloc.porting.common import as_bool, find_params

SAME = ("alpha1", "alpha2", "alpha3", "alpha4", "alpha5", "z_hit", "z_rand", "sigma_hit",
        "laser_likelihood_max_dist", "laser_max_range", "min_particles", "max_particles", "pf_err", "pf_z",
        "resample_interval", "recovery_alpha_slow", "recovery_alpha_fast", "update_min_d", "update_min_a")
INTS = ("min_particles", "max_particles", "resample_interval")
QUIET = {"use_sim_time"}


def _looks_like_amcl(d: Any) -> bool:
    return isinstance(d, dict) and sum(k in d for k in ("alpha1", "z_hit", "max_particles", "update_min_d",
                                                         "laser_model_type", "odom_model_type")) >= 2


def from_nav2(data: Any, node: str | None = None, source: str = "nav2 params") -> tuple[dict[str, Any], list[str]]:
    """``(fgloc config sections, notes)`` for the ``amcl`` node of a nav2 (or ROS 1 amcl) params file."""
    name, p, others = find_params(data, _looks_like_amcl, node, source)
    notes: list[str] = []
    if others:
        notes.append(f"converted node {name}; not converted: {', '.join(others)}")
    amcl: dict[str, Any] = {}
    used: set[str] = set()
    for k in SAME:
        if k in p:
            used.add(k)
            amcl[k] = int(p[k]) if k in INTS else float(p[k])
    for k in ("max_beams", "laser_max_beams"):
        if k in p:
            used.add(k)
            amcl["laser_max_beams"] = int(p[k])
    model = p.get("robot_model_type", p.get("odom_model_type"))
    if model is not None:
        used.update({"robot_model_type", "odom_model_type"})
        m = str(model).lower()
        if "omni" in m:
            amcl["robot_model_type"] = "omni"
        elif "diff" in m:
            amcl["robot_model_type"] = "differential"
        else:
            notes.append(f"robot_model_type: {model}: unknown motion model, fgloc's default kept")
        if "corrected" in m:
            notes.append(f"odom_model_type: {model}: fgloc's models are the corrected ones (nav2's)")
    if "laser_model_type" in p:
        used.add("laser_model_type")
        lm = str(p["laser_model_type"])
        if lm in ("likelihood_field", "likelihood_field_prob"):
            amcl["laser_model_type"] = lm
        else:
            notes.append(f"laser_model_type: {lm}: not in fgloc (likelihood_field or likelihood_field_prob); "
                         "fgloc's default kept")
    if "laser_min_range" in p:
        used.add("laser_min_range")
        if float(p["laser_min_range"]) > 0:
            notes.append(f"laser_min_range: {p['laser_min_range']}: fgloc uses the scan's range_min")
    if "scan_topic" in p:
        used.add("scan_topic")
        notes.append(f"scan_topic: {p['scan_topic']}: pass --scan-topic {p['scan_topic']} to fgloc run")
    if as_bool(p.get("set_initial_pose", False)):
        used.update({"set_initial_pose", "initial_pose"})
        ip = p.get("initial_pose") or {}
        if isinstance(ip, dict):
            notes.append(f"set_initial_pose: pass --initial-pose {ip.get('x', 0.0)} {ip.get('y', 0.0)} "
                         f"{ip.get('yaw', 0.0)} to fgloc run")
    out: dict[str, Any] = {"frontends": {"amcl": amcl}} if amcl else {}
    for k in sorted(p):
        ks = str(k)
        if ks in used or ks in QUIET:
            continue
        notes.append(f"{ks}: {_why(ks)}")
    return out, notes


def _why(k: str) -> str:
    if k in ("z_short", "z_max", "lambda_short"):
        return "terms of the beam model; fgloc has the likelihood-field models"
    if k.startswith("beam_skip") or k == "do_beamskip":
        return "beam skipping is not implemented"
    if k.endswith("frame_id") or k in ("tf_broadcast", "transform_tolerance", "save_pose_rate",
                                       "always_reset_initial_pose", "first_map_only", "map_topic",
                                       "initial_pose", "set_initial_pose"):
        return "a ROS frame / tf / topic setting"
    return "no fgloc equivalent"
