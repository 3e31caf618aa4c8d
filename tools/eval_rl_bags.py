#!/usr/bin/env python3
"""fgloc against robot_localization's own real-robot regression bags (issue 17 acceptance).

robot_localization (r_l, BSD-3-Clause) tests its EKF/UKF on real logs in its ``test/`` folder:
``test1.bag`` (Clearpath Husky in a parking lot, IMU mounted rotated, 395 s), ``test2.bag``
(Jackal, 61 s) and ``test3.bag`` (AR.Drone), each with a launch file holding the filter's
parameters, the static transforms the bag lacks, and the pose tester's expected final position
and tolerance (``final_x``, ``final_y``, ``final_z``, ``tolerance``).  This tool runs what an r_l
user would run, per case:

1. the parameters -> ``fgloc config from-robot-localization`` (the library function behind it)
   -> an fgloc config: a ROS 1 ``.test`` launch file is converted as it is (its
   ``static_transform_publisher`` mounts, which the bag lacks, come along as
   ``sources.static_transforms``: test1's IMU mount); a ROS 2 ``.yaml`` through an r_l
   parameter YAML of its filter node;
2. ``fgloc run BAG --config CONVERTED`` without a map (odom frame), with each back-end
   (``fgloc.app.run.run_log``, the function behind ``fgloc run``): the config's sources name the
   topics, nothing else is given;
3. with ``--tf-copy``, when the launch file gives static transforms, also a run on a copy of the
   bag with them added as ``/tf_static`` and a config without them, marked ``+tf`` (the log as
   it would have been recorded with the launch file running);
4. two dead-reckoning references from the bag alone: the wheel speed turned by the IMU's
   absolute yaw through its mount (planar), and the wheel velocity turned by the IMU's whole
   attitude (3-D, as r_l does with two_d_mode false);
5. a third, from fgloc's sources router alone (the converted config's ``sources:``, no
   back-end): the twists it hands the localizer turned by the heading it hands it (the first
   IMU's yaw when it gives one, else the integral of its least uncertain yaw-rate stream).  It
   tells a sources / porting error (this row off too) from a back-end one (this row on target).

It prints one table (final x/y, the planar distance to r_l's expected final position, pass when
it is below the test's tolerance) and each run's per-source summary, and exits 0.  The r_l
pose tester measures a 3-D distance; fgloc is planar, so the table's errors are in x, y.

Usage::

    python tools/eval_rl_bags.py FOLDER [FOLDER ...] [--backends ekf smoother] [--out DIR]
    python tools/eval_rl_bags.py --convert PARAMS.yaml|DIR ...   # the porting tool on other files

``--convert`` runs ``fgloc config from-robot-localization`` / ``from-nav2`` on each file (r_l when
it has odomN/imuN/poseN/twistN keys, nav2 when it has an amcl section) and prints one line per
file: converted or the error, the parameters not carried over, and what the converted config
would do that the ROS node does not (no source of translation left; ``differential`` on a source
that fuses only velocities, which r_l ignores).

A FOLDER holds the fetched files of one r_l branch: ``test*.bag`` and
``test_ekf_localization_node_bag*.test`` (ROS 1) and/or ``test_ekf_localization_node_bag*.yaml``
(ROS 2; the bag is ``testN.bag`` beside it).  Nothing fetched is kept in this repository.
"""

from __future__ import annotations

import argparse
import math
import re
import shlex
import sys
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from fgloc.backends.contract import Capability

FILTER_TYPES = ("ekf_localization_node", "ukf_localization_node", "ekf_node", "ukf_node")


@dataclass
class Case:
    """One r_l regression test: its bag, filter parameters, expected end and static transforms."""

    name: str
    bag: Path
    params: dict[str, Any]  # the filter node's parameters (flat, ROS 1 style)
    expected_xyz: tuple[float, float, float]
    tolerance_m: float
    source: Path
    # (parent, child, x, y, z, qx, qy, qz, qw) from static_transform_publisher nodes
    static_tfs: list[tuple[str, str, float, float, float, float, float, float, float]] = field(default_factory=list)


# ---------------------------------------------------------------------------- parameter files
def _value(text: str) -> Any:
    return yaml.safe_load(text)


def _quat_of_ypr(yaw: float, pitch: float, roll: float) -> tuple[float, float, float, float]:
    from scipy.spatial.transform import Rotation

    q = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_quat()
    return float(q[0]), float(q[1]), float(q[2]), float(q[3])


def _static_tf(args: str) -> tuple[str, str, float, float, float, float, float, float, float] | None:
    """``static_transform_publisher`` arguments (x y z yaw pitch roll | x y z qx qy qz qw, parent child)."""
    a = shlex.split(args)
    nums: list[float] = []
    for s in a:
        try:
            nums.append(float(s))
        except ValueError:
            break
    names = a[len(nums):]  # parent child [period_ms] (tf's ROS 1 publisher has the period last)
    if len(names) < 2 or len(nums) not in (6, 7):
        return None
    q = tuple(nums[3:7]) if len(nums) == 7 else _quat_of_ypr(nums[3], nums[4], nums[5])
    return (names[0].lstrip("/"), names[1].lstrip("/"), nums[0], nums[1], nums[2], *q)  # type: ignore[return-value]


def parse_launch_xml(path: Path) -> Case | None:
    """A ROS 1 ``.test`` / ``.launch``: the filter node's params, the test's expectations, static tfs."""
    root = ET.parse(path).getroot()
    params: dict[str, Any] = {}
    expected: dict[str, float] = {}
    tfs = []
    bag = None
    for node in root.iter("node"):
        typ = node.get("type", "")
        if typ in FILTER_TYPES:
            for p in node:
                if p.tag == "param" and p.get("name") and p.get("value") is not None:
                    params[p.get("name", "")] = _value(p.get("value", ""))
                elif p.tag == "rosparam" and p.get("param"):
                    params[p.get("param", "")] = _value(p.text or "")
        elif typ == "static_transform_publisher":
            tf = _static_tf(node.get("args", ""))
            if tf is not None:
                tfs.append(tf)
        elif typ == "play":
            m = re.search(r"(\S+\.bag)", node.get("args", ""))
            if m:
                bag = Path(m.group(1)).name
    for t in root.iter("test"):
        for p in t.iter("param"):
            if p.get("name") in ("final_x", "final_y", "final_z", "tolerance"):
                expected[p.get("name", "")] = float(p.get("value", "nan"))
    if not params or len(expected) < 4 or bag is None:
        return None
    return Case(path.stem, path.parent / bag, params,
                (expected["final_x"], expected["final_y"], expected["final_z"]), expected["tolerance"], path, tfs)


def parse_ros2_yaml(path: Path) -> Case | None:
    """A ROS 2 test YAML: ``<filter>: ros__parameters`` and ``<tester>_pose: ros__parameters``."""
    data = yaml.safe_load(path.read_text())
    if not isinstance(data, dict):
        return None
    params = exp = None
    for v in data.values():
        p = v.get("ros__parameters") if isinstance(v, dict) else None
        if not isinstance(p, dict):
            continue
        if "final_x" in p:
            exp = p
        elif any(re.fullmatch(r"(odom|imu|pose|twist)\d+", k) for k in p):
            params = p
    m = re.search(r"bag(\d+)", path.stem)
    if params is None or exp is None or m is None:
        return None
    return Case(path.stem + " (ROS 2)", path.parent / f"test{m.group(1)}.bag", params,
                (float(exp["final_x"]), float(exp["final_y"]), float(exp["final_z"])), float(exp["tolerance"]), path)


def find_cases(folders: list[Path]) -> list[Case]:
    cases: list[Case] = []
    for folder in folders:
        for p in sorted(folder.glob("test_ekf_localization_node*bag*.test")):
            c = parse_launch_xml(p)
            if c is not None and c.bag.exists():
                cases.append(c)
        have = {c.bag.resolve() for c in cases}
        for p in sorted(folder.glob("test_ekf_localization_node*bag*.yaml")):
            c = parse_ros2_yaml(p)
            if c is not None and c.bag.exists() and c.bag.resolve() not in have:
                cases.append(c)
    return cases


# ---------------------------------------------------------------------------- the bag itself
def _typestore() -> Any:
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    if "tf2_msgs/msg/TFMessage" not in ts.types:
        ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
    return ts


def read_streams(bag: Path, odom_topic: str, imu_topic: str) -> tuple[np.ndarray, np.ndarray, str, float]:
    """Odometry rows (t, vx, vy, wz), IMU rows (t, qx, qy, qz, qw), the IMU frame, the bag's duration."""
    from rosbags.rosbag1 import Reader

    ts = _typestore()
    odom, imu = [], []
    frame = ""
    with Reader(bag) as r:
        duration = r.duration / 1e9
        for c, _t, raw in r.messages():
            if c.topic not in (odom_topic, imu_topic):
                continue
            m = ts.deserialize_ros1(raw, c.msgtype)
            s = m.header.stamp.sec + m.header.stamp.nanosec * 1e-9
            if c.topic == odom_topic:
                tw = m.twist.twist
                odom.append((s, tw.linear.x, tw.linear.y, tw.angular.z))
            else:
                q = m.orientation
                imu.append((s, q.x, q.y, q.z, q.w))
                frame = m.header.frame_id.lstrip("/")
    return np.array(odom), np.array(imu), frame, duration


def dead_reckoning(odom: np.ndarray, imu: np.ndarray, mount_q: tuple[float, float, float, float] | None
                   ) -> dict[str, Any]:
    """Wheel speed turned by the IMU's absolute attitude through its mount: planar (yaw) and 3-D."""
    from scipy.spatial.transform import Rotation

    mount = Rotation.identity() if mount_q is None else Rotation.from_quat(mount_q)
    att = Rotation.from_quat(imu[:, 1:5]) * mount.inv()  # base_link in the IMU's world frame
    idx = np.clip(np.searchsorted(imu[:, 0], odom[:, 0]), 0, len(imu) - 1)
    dt = np.diff(odom[:, 0], prepend=odom[0, 0])
    v = np.zeros((len(odom), 3))
    v[1:, :2] = odom[:-1, 1:3]  # each twist held until the next message
    yaw = att[idx].as_euler("ZYX")[:, 0]
    c, s = np.cos(yaw), np.sin(yaw)
    planar = np.array([np.sum((v[:, 0] * c - v[:, 1] * s) * dt), np.sum((v[:, 0] * s + v[:, 1] * c) * dt)])
    p3 = np.sum(att[idx].apply(v) * dt[:, None], axis=0)
    imu_yaw = np.unwrap((Rotation.from_quat(imu[:, 1:5]) * mount.inv()).as_euler("ZYX")[:, 0])
    return {
        "planar": planar, "3d": p3,
        "distance_m": float(np.sum(np.hypot(v[:, 0], v[:, 1]) * dt)),
        "wheel_turn_rad": float(np.sum(np.abs(np.r_[0.0, odom[:-1, 3]]) * dt)),
        "imu_turn_rad": float(np.sum(np.abs(np.diff(imu_yaw)))),
    }


class _Recorder:
    """A localizer stand-in for :class:`~fgloc.localization.sources.SourceRouter`: records what
    the router hands it (odometry, compass readings, second IMUs' gyro rates)."""

    odom_mode = True
    frontend = None
    initialized = True
    encoder_sigmas = (0.01, 0.01, 0.02)
    capabilities = frozenset({Capability.GYRO})  # a back-end double: takes a second IMU's yaw rate

    def __init__(self) -> None:
        self.backend = self
        self.stats: dict[str, Any] = {}
        self.odometry: list[tuple[float, float, float]] = []
        self.yaw: list[tuple[float, float]] = []
        self.rates: dict[str, list[tuple[float, float, float]]] = {}

    def on_odometry(self, m: Any) -> None:
        self.odometry.append((float(m.stamp), float(m.twist[0]), float(m.twist[1])))

    def on_compass(self, m: Any) -> None:
        if m.yaw_rad is not None:
            self.yaw.append((float(m.stamp), float(m.yaw_rad)))
        if m.yaw_rate_radps is not None:
            self.rates.setdefault("imu", []).append((float(m.stamp), float(m.yaw_rate_radps), float(m.yaw_rate_var)))

    def add_gyro(self, t: float, rate: float, var: float, source: str) -> None:
        self.rates.setdefault(source, []).append((float(t), float(rate), float(var)))


def sources_dead_reckoning(bag: Path, config: Path) -> tuple[np.ndarray, str] | None:
    """Item 5 of the module doc: ``(final x, y, what heading)`` or None (no odometry / heading)."""
    from fgloc.config import load_config
    from fgloc.frames.static import parse_static_transforms
    from fgloc.io import open_log
    from fgloc.localization.sources import SourceRouter, parse_sources

    cfg = load_config(config)
    specs = parse_sources(cfg.sources)
    rec = _Recorder()
    router = SourceRouter(rec, specs, parse_static_transforms(cfg.sources.static_transforms))
    by_topic = {s.topic: s for s in specs}
    src = open_log(bag)
    want = [t for t in [*by_topic, "/tf_static", "/tf"] if src.has(t)]
    for topic, msg in src.messages(want):
        if topic in by_topic:
            router.on_message(by_topic[topic], msg)
        else:
            router.on_tf(msg)
    if not rec.odometry:
        return None
    odo = np.array(sorted(rec.odometry))
    if rec.yaw:
        y = np.array(sorted(rec.yaw))
        heading, what = np.interp(odo[:, 0], y[:, 0], np.unwrap(y[:, 1])), "first IMU's yaw"
    else:
        streams = {k: np.array(sorted(v)) for k, v in rec.rates.items() if len(v) > 1}
        if not streams:
            return None
        name = min(streams, key=lambda k: float(np.nanmedian(streams[k][:, 2])))
        r = streams[name]
        integral = np.r_[0.0, np.cumsum(r[1:, 1] * np.diff(r[:, 0]))]
        heading, what = np.interp(odo[:, 0], r[:, 0], integral), f"{name}'s yaw rate integrated"
    dt = np.diff(odo[:, 0], prepend=odo[0, 0])
    c, s = np.cos(heading), np.sin(heading)
    xy = np.array([np.sum((odo[:, 1] * c - odo[:, 2] * s) * dt), np.sum((odo[:, 1] * s + odo[:, 2] * c) * dt)])
    return xy, what


def with_static_tfs(bag: Path, tfs: list[tuple[Any, ...]], out: Path) -> Path:
    """A copy of ``bag`` with the launch file's static transforms as one latched ``/tf_static``."""
    from rosbags.rosbag1 import Reader, Writer

    ts = _typestore()
    M = ts.types
    if out.exists():
        out.unlink()
    with Reader(bag) as r, Writer(out) as w:
        conns = {c.id: w.add_connection(c.topic, c.msgtype, typestore=ts) for c in r.connections}
        tfc = w.add_connection("/tf_static", "tf2_msgs/msg/TFMessage", typestore=ts, latching=1)
        t0 = max(r.start_time - 1, 0)  # before every message (at the first one's time it may be read after it)
        stamp = M["builtin_interfaces/msg/Time"](sec=t0 // 10**9, nanosec=t0 % 10**9)
        trs = []
        for parent, child, x, y, z, qx, qy, qz, qw in tfs:
            trs.append(M["geometry_msgs/msg/TransformStamped"](
                header=M["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id=parent), child_frame_id=child,
                transform=M["geometry_msgs/msg/Transform"](
                    translation=M["geometry_msgs/msg/Vector3"](x=x, y=y, z=z),
                    rotation=M["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw))))
        w.write(tfc, t0, ts.serialize_ros1(M["tf2_msgs/msg/TFMessage"](transforms=trs), "tf2_msgs/msg/TFMessage"))
        for c, t, raw in r.messages():
            w.write(conns[c.id], t, raw)
    return out


# ---------------------------------------------------------------------------- fgloc
def convert(case: Case, work: Path, mounts: bool = True) -> tuple[Path | None, list[str], str | None]:
    """The r_l parameters -> fgloc config file (``fgloc config from-robot-localization``): a ROS 1
    launch file as it is (with its static transforms; ``mounts=False``: through a parameter YAML
    of the filter node alone), a ROS 2 case through a parameter YAML."""
    from fgloc.commands.porting import convert_file
    from fgloc.errors import FglocError

    if mounts and case.source.suffix in (".test", ".launch"):
        rl = case.source
    else:
        rl = work / f"{case.name}.rl.yaml"
        rl.write_text(yaml.safe_dump({"ekf_filter_node": {"ros__parameters": case.params}}, sort_keys=False))
    try:
        _, notes, text = convert_file("rl", rl)
    except FglocError as e:
        return None, [], str(e)
    out = work / f"{case.name}{'' if mounts else '.nomounts'}.fgloc.yaml"
    out.write_text(text)
    return out, notes, None


def run_fgloc(bag: Path, config: Path, backend: str, odom_topic: str | None, imu_topic: str | None,
              outdir: Path) -> dict[str, Any]:
    """``fgloc run BAG --backend B --config C`` in the odom frame: final pose and the summary's stats
    (``odom_topic`` / ``imu_topic`` None: the config's sources name them)."""
    import logging

    from fgloc.app.run import RunRequest, run_log
    from fgloc.errors import FglocError
    from fgloc.io.tum import read_tum

    fgloc_log = logging.getLogger("fgloc")
    level = fgloc_log.level
    fgloc_log.setLevel(logging.ERROR)  # the expected 'no laser transform' warning, for this run only
    try:
        r = run_log(RunRequest(log=bag, outdir=outdir, backend=backend, config=config, odom_topic=odom_topic,
                               imu_topic=imu_topic, force=True, view_channels=False))
    except FglocError as e:
        return {"error": str(e)}
    except Exception as e:  # noqa: BLE001 - a crash is a finding, reported in the table
        return {"error": f"crash: {type(e).__name__}: {str(e).strip().splitlines()[0] if str(e).strip() else ''}"}
    finally:
        fgloc_log.setLevel(level)
    traj = read_tum(outdir / "trajectory.tum")
    final = np.asarray(traj.poses[-1], dtype=float)
    return {"final": final, "stats": r.stats, "wall_s": r.wall_s, "failure": r.failure()}


def source_line(stats: Any) -> str:
    """The per-source health the run summary should show, in one line (``stats``: a
    :class:`fgloc.localization.stats.RunStats`)."""
    parts = []
    for name, r in stats.sources.items():
        h = r.to_dict()
        keys = [k for k in ("accepted", "gated", "backend_gated", "yaw_gated", "skipped", "speed_scale",
                            "yaw_rate_scale", "gyro_bias_radps", "yaw_shown_vs_claimed") if k in h]
        parts.append(f"{name}: " + " ".join(f"{k}={h[k]}" for k in keys))
    be = stats.backend
    extra = {k: be[k] for k in ("gated", "compass_recoveries", "solver_failures", "gyro_factors",
                                "relative_yaw_factors", "relative_yaw_reanchored", "velocity_factors",
                                "velocity_gaps") if k in be}
    if stats.counters.get("odometry_from_poses"):
        extra["odometry_from_poses"] = stats.counters["odometry_from_poses"]
    return "; ".join(parts) + (f"; backend {extra}" if extra else "")


# ---------------------------------------------------------------------------- main
def topics(params: dict[str, Any]) -> tuple[str | None, str | None]:
    o = next((params[k] for k in sorted(params) if re.fullmatch(r"odom\d+", k)), None)
    i = next((params[k] for k in sorted(params) if re.fullmatch(r"imu\d+", k)), None)
    return o, i


def _convert_one(path: Path) -> str:
    """One line: what the porting tool made of a public parameter file."""
    from fgloc.commands.porting import convert_file
    from fgloc.errors import FglocError

    text = path.read_text(errors="replace")
    kind = "rl" if re.search(r"^\s*(odom|imu|pose|twist)\d+\s*:", text, re.M) else \
        "nav2" if re.search(r"^\s*(amcl|robot_model_type|laser_model_type)\s*:", text, re.M) else None
    if kind is None:
        return f"skip      {path.name}: neither r_l nor amcl parameters"
    try:
        cfg, notes, _ = convert_file(kind, path)
    except FglocError as e:
        return f"ERROR     {path.name}: {e}"
    except Exception as e:  # noqa: BLE001 - a crash is a finding
        return f"CRASH     {path.name}: {type(e).__name__}: {e}"
    odd = []
    if kind == "rl":
        srcs = ((cfg.get("sources") or {}).get("inputs") or {})
        if not any(set(s.get("use", [])) & {"x", "y", "vx", "vy"} for s in srcs.values()):
            odd.append("no source of translation left")
        for n, s in srcs.items():
            if s.get("differential") and not set(s.get("use", [])) & {"x", "y", "yaw"}:
                odd.append(f"{n}: differential on velocities only {s.get('use')}")
    return (f"{'converted' if not odd else 'SUSPECT':9s} {path.name} [{kind}]: {len(notes)} not carried over"
            + (f"; {'; '.join(odd)}" if odd else ""))


def table_row(case: Case, duration_s: float, dr: dict[str, Any], label: str, p: Any) -> list[str]:
    """One line of the table: an estimate's final (x, y) against r_l's (None: the run failed)."""
    ex, ey, _ = case.expected_xyz
    first = [case.name, label, f"{duration_s:.0f}", f"{dr['distance_m']:.1f}", f"({ex:.2f}, {ey:.2f})"]
    if p is None:
        return [*first, "-", "-", f"{case.tolerance_m:.3f}", "ERROR"]
    e = math.hypot(p[0] - ex, p[1] - ey)
    return [*first, f"({p[0]:.2f}, {p[1]:.2f})", f"{e:.3f}", f"{case.tolerance_m:.3f}",
            "pass" if e < case.tolerance_m else "FAIL"]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("folders", nargs="*", type=Path, help="folders with r_l's test bags and parameter files")
    ap.add_argument("--convert", nargs="+", type=Path, default=None,
                    help="only convert these parameter files (or every *.yaml in these folders) and report")
    ap.add_argument("--backends", nargs="+", default=["ekf", "smoother"])
    ap.add_argument("--out", type=Path, default=None, help="where fgloc writes (default: a temporary folder)")
    ap.add_argument("--tf-copy", action="store_true",
                    help="also run on a copy of the bag with the launch file's static tfs added as /tf_static")
    a = ap.parse_args(argv)
    if a.convert:
        files = [f for p in a.convert for f in (sorted(p.glob("*.y*ml")) if p.is_dir() else [p])]
        lines = [_convert_one(f) for f in files]
        for line in lines:
            print(line)
        print(f"{len(files)} files: " + ", ".join(f"{sum(line.startswith(k) for line in lines)} {k.lower()}"
                                                 for k in ("converted", "SUSPECT", "ERROR", "CRASH", "skip")))
        return 0
    if not a.folders:
        ap.error("give folders with the r_l bags, or --convert FILES")

    work = a.out or Path(tempfile.mkdtemp(prefix="eval_rl_"))
    work.mkdir(parents=True, exist_ok=True)
    cases = find_cases(a.folders)
    if not cases:
        print(f"no r_l test cases (testN.bag + its .test/.yaml) in {', '.join(map(str, a.folders))}")
        return 0
    rows: list[list[str]] = []
    notes_out: list[str] = []
    for case in cases:
        odom_t, imu_t = topics(case.params)
        ex, ey, ez = case.expected_xyz
        cfg, notes, err = convert(case, work)
        where = f"{case.name} [{case.source.parent.name}/{case.source.name}]"
        if err or cfg is None:
            notes_out.append(f"{where}: conversion failed: {err}")
            continue
        odom, imu, imu_frame, duration = read_streams(case.bag, odom_t or "", imu_t or "")
        mount = next((tf for tf in case.static_tfs if tf[1] == imu_frame), None)
        dr = dead_reckoning(odom, imu, None if mount is None else mount[5:9])
        notes_out.append(f"{where}: {case.bag.name}, {duration:.0f} s, {dr['distance_m']:.1f} m driven, "
                         f"|turn| wheels {dr['wheel_turn_rad']:.1f} rad vs IMU {dr['imu_turn_rad']:.1f} rad; "
                         f"r_l expects ({ex:.3f}, {ey:.3f}, z {ez:.3f}) +- {case.tolerance_m} m; "
                         f"{len(notes)} r_l parameter(s) not carried over")
        rows.append(table_row(case, duration, dr, "dead reckoning, IMU yaw", dr["planar"]))
        rows.append(table_row(case, duration, dr, "dead reckoning, IMU attitude 3-D", dr["3d"]))
        sdr = sources_dead_reckoning(case.bag, cfg)
        if sdr is not None:
            rows.append(table_row(case, duration, dr, "dead reckoning, fgloc sources' output", sdr[0]))
            notes_out.append(f"  dead reckoning, fgloc sources' output: heading from the {sdr[1]}")
        variants: list[tuple[str, Path, Path]] = [("", case.bag, cfg)]
        if case.static_tfs and a.tf_copy:
            bare, _, _ = convert(case, work, mounts=False)
            if bare is not None:
                variants.append(("+tf", with_static_tfs(case.bag, case.static_tfs, work / f"{case.bag.stem}_tf.bag"),
                                 bare))
        for tag, bag, config in variants:
            for be in a.backends:
                label = f"fgloc {be}{' ' + tag if tag else ''}"
                res = run_fgloc(bag, config, be, None, None, work / f"{case.name}_{be}{tag}")
                if "error" in res:
                    rows.append(table_row(case, duration, dr, label, None))
                    notes_out.append(f"  {label}: {res['error']}")
                    continue
                rows.append(table_row(case, duration, dr, label, res["final"]))
                notes_out.append(f"  {label}: {source_line(res['stats'])}")
    head = ["case", "estimate", "s", "dist m", "r_l final (x, y)", "final (x, y)", "xy error m", "tol m", ""]
    width = [max(len(str(r[i])) for r in [head, *rows]) for i in range(len(head))]
    for r in [head, *rows]:
        print("  ".join(str(v).ljust(w) for v, w in zip(r, width, strict=True)).rstrip())
    print()
    for n in notes_out:
        print(n)
    print(f"\n(fgloc outputs in {work})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
