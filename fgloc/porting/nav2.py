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
``scan_topic``                                  a note: pass ``--scan-topic`` (one topic)
==============================================  ==========================================

ROS 1 amcl names (``odom_alphaN``, ``laser_z_hit``, ``laser_z_rand``, ``laser_sigma_hit``,
``kld_err``, ``kld_z``) are read as nav2's.  A parameter the file leaves out takes the default of
the node it was written for (nav2_amcl's, or ROS 1 amcl's when the file uses ROS 1 names), not
fgloc's (differential vs omni, alphas 0.2 vs 0.05, sigma_hit 0.2 vs 0.05, ...): one note lists them.

Everything else is one note line (the beam model and its ``z_short``/``z_max``/
``lambda_short``, beam skipping, frames, tf and pose-saving settings).
"""

from __future__ import annotations

import math
import re
from typing import Any

from fgloc.porting.common import as_bool, find_params

SAME = ("alpha1", "alpha2", "alpha3", "alpha4", "alpha5", "z_hit", "z_rand", "sigma_hit",
        "laser_likelihood_max_dist", "laser_max_range", "min_particles", "max_particles", "pf_err", "pf_z",
        "resample_interval", "recovery_alpha_slow", "recovery_alpha_fast", "update_min_d", "update_min_a")
INTS = ("min_particles", "max_particles", "resample_interval")
QUIET = {"use_sim_time"}
ROS1_NAMES = {"odom_alpha1": "alpha1", "odom_alpha2": "alpha2", "odom_alpha3": "alpha3", "odom_alpha4": "alpha4",
              "odom_alpha5": "alpha5", "laser_z_hit": "z_hit", "laser_z_rand": "z_rand",
              "laser_sigma_hit": "sigma_hit", "kld_err": "pf_err", "kld_z": "pf_z"}
# the nodes' own defaults (nav2_amcl's AmclNode parameters; ROS 1 amcl's wiki page)
NAV2_DEFAULTS: dict[str, Any] = {
    "alpha1": 0.2, "alpha2": 0.2, "alpha3": 0.2, "alpha4": 0.2, "alpha5": 0.2, "z_hit": 0.5, "z_rand": 0.5,
    "sigma_hit": 0.2, "laser_likelihood_max_dist": 2.0, "laser_max_range": 100.0, "min_particles": 500,
    "max_particles": 2000, "pf_err": 0.05, "pf_z": 0.99, "resample_interval": 1, "recovery_alpha_slow": 0.0,
    "recovery_alpha_fast": 0.0, "update_min_d": 0.25, "update_min_a": 0.2, "laser_max_beams": 60,
    "robot_model_type": "differential", "laser_model_type": "likelihood_field"}
ROS1_DEFAULTS: dict[str, Any] = {
    **NAV2_DEFAULTS, "z_hit": 0.95, "z_rand": 0.05, "laser_max_range": -1.0, "min_particles": 100,
    "max_particles": 5000, "pf_err": 0.01, "resample_interval": 2, "update_min_d": 0.2,
    "update_min_a": round(math.pi / 6, 6), "laser_max_beams": 30}


def _looks_like_amcl(d: Any) -> bool:
    return isinstance(d, dict) and sum(k in d for k in ("alpha1", "z_hit", "max_particles", "update_min_d",
                                                         "laser_model_type", "odom_model_type")) >= 2


def from_nav2(data: Any, node: str | None = None, source: str = "nav2 params") -> tuple[dict[str, Any], list[str]]:
    """``(fgloc config sections, notes)`` for the ``amcl`` node of a nav2 (or ROS 1 amcl) params file."""
    name, p, others = find_params(data, _looks_like_amcl, node, source)
    ros1 = any(k in p for k in (*ROS1_NAMES, "odom_model_type", "laser_max_beams"))
    p = {ROS1_NAMES.get(str(k), k): v for k, v in p.items()}
    notes: list[str] = []
    if others:
        notes.append(f"converted node {name}; not converted: {', '.join(others)}")
    amcl: dict[str, Any] = {}
    ros2: dict[str, Any] = {}  # nav2 AMCL's topics and frames, for fgloc live --ros2
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
            notes.append(f"robot_model_type: {model}: unknown motion model (the node's default is used)")
        if "corrected" in m:
            notes.append(f"odom_model_type: {model}: fgloc's models are the corrected ones (nav2's)")
    if "laser_model_type" in p:
        used.add("laser_model_type")
        lm = str(p["laser_model_type"])
        if lm in ("likelihood_field", "likelihood_field_prob"):
            amcl["laser_model_type"] = lm
        else:
            notes.append(f"laser_model_type: {lm}: not in fgloc (likelihood_field or likelihood_field_prob); "
                         "likelihood_field used")
    if "laser_min_range" in p:
        used.add("laser_min_range")
        if float(p["laser_min_range"]) > 0:
            notes.append(f"laser_min_range: {p['laser_min_range']}: fgloc uses the scan's range_min")
    if "scan_topic" in p:
        used.add("scan_topic")
        st = p["scan_topic"]
        scans = [str(t) for t in st] if isinstance(st, (list, tuple)) else re.split(r"[\s,]+", str(st).strip())
        scans = [t for t in scans if t]
        if len(scans) > 1:
            notes.append(f"scan_topic: {' '.join(scans)}: fgloc localizes with one laser: pass --scan-topic "
                         f"{scans[0]} to fgloc run (the others are not used)")
        elif scans:
            notes.append(f"scan_topic: {scans[0]}: pass --scan-topic {scans[0]} to fgloc run")
        if scans:  # fgloc live --ros2 subscribes to it as nav2 AMCL does
            ros2["scan_topic"] = scans[0] if scans[0].startswith("/") else "/" + scans[0]
    # nav2 AMCL's ROS interface, for fgloc live --ros2 (the ros2: section keeps nav2's names)
    for key, to, conv in (("map_topic", "map_topic", lambda v: v if str(v).startswith("/") else f"/{v}"),
                          ("global_frame_id", "global_frame_id", str), ("odom_frame_id", "odom_frame_id", str),
                          ("tf_broadcast", "tf_broadcast", as_bool),
                          ("transform_tolerance", "transform_tolerance_s", float)):
        if key in p:
            used.add(key)
            ros2[to] = conv(p[key])
    if as_bool(p.get("set_initial_pose", False)):
        used.update({"set_initial_pose", "initial_pose"})
        ip = p.get("initial_pose") or {}
        if isinstance(ip, dict):
            notes.append(f"set_initial_pose: pass --initial-pose {ip.get('x', 0.0)} {ip.get('y', 0.0)} "
                         f"{ip.get('yaw', 0.0)} to fgloc run")
    # what the file leaves out is what its node would use, not fgloc's defaults
    defaults = ROS1_DEFAULTS if ros1 else NAV2_DEFAULTS
    filled = [k for k in defaults if k not in amcl]
    for k in filled:
        amcl[k] = defaults[k]
    if filled:
        notes.append(f"left out, so {'ROS 1 amcl' if ros1 else 'nav2_amcl'}'s defaults (not fgloc's): "
                     + ", ".join(f"{k} {defaults[k]}" for k in filled))
    out: dict[str, Any] = {"frontends": {"amcl": amcl}} if amcl else {}
    if ros2:
        out["ros2"] = ros2
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
