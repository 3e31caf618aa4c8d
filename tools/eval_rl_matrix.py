#!/usr/bin/env python3
"""The fusion matrix: real logs x the configurations a user may write x back-end.

robot_localization (r_l, BSD-3-Clause) checks its EKF on its own real-robot bags against a final
position and tolerance written in each test's launch file (``tools/eval_rl_bags.py`` reads them).
Its answer is its own EKF's earlier output with the launch file's parameters.  A user porting a
robot writes other configurations than that launch file; this tool runs each of them, the way
``fgloc run BAG --config CONFIG`` does (no map, odom frame), with each back-end, and prints one
table: the final position's distance from r_l's expected one, r_l's tolerance, pass / fail.

Configurations (each derived from r_l's launch file converted by ``fgloc config
from-robot-localization``; a variant that would equal another one, or that r_l's vectors make
meaningless, is left out for that log):

* ``defaults``: no config at all (the log's odometry and IMU topics, fgloc's default layout);
  on a log whose launch file publishes mounts the log lacks, the run is on a copy of the log
  with them in ``/tf_static`` (without the mount no user's run can work: the EKF ends 121 m off
  on noetic test1 too);
* ``r_l``: r_l's vectors converted, the mounts in the config (``sources.static_transforms``);
* ``r_l, mount in /tf_static``: the same vectors, the mounts in the log instead of the config;
* ``+ gyro`` / ``- gyro``: the IMU's yaw rate (``vyaw``) fused / not, everything else r_l's;
* ``+ wheel yaw`` / ``- wheel yaw``: the odometry's yaw rate fused / not;
* ``+ gyro + wheel yaw``: both (a typical port: odom vx, vy, vyaw; imu yaw, vyaw);
* ``2-D``: roll and pitch not used (r_l's ``two_d_mode: true``) where r_l's vectors level the
  odometry with them.

When the log carries a GPS (``sensor_msgs/NavSatFix``), each run's trajectory is also compared
with it, an independent reference: the estimate is aligned to the GPS track (2-D rigid fit)
over its first :data:`GPS_ALIGN_M` metres of travel, and the table gives the distance between
the two at the end.  r_l's answer is an EKF's output, not ground truth.

Usage::

    python tools/eval_rl_matrix.py NOETIC_DIR GROOVY_DIR [--backends ekf smoother] [--only test1.bag ...]
        [--variants defaults r_l ...] [--out DIR] [--markdown]

Prints the table (``--markdown``: as the README carries it), the medians per back-end and the
cells where the EKF is within tolerance and the smoother is not.  Exits 0.
"""

from __future__ import annotations

import argparse
import copy
import importlib.util
import math
import statistics
import sys
import tempfile
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import yaml

HERE = Path(__file__).resolve().parent
#: m of travel over which an estimate is aligned to the log's GPS track
GPS_ALIGN_M = 50.0


def _rl_tool() -> ModuleType:
    """``tools/eval_rl_bags.py`` (the r_l case reader, the conversion, the run) as a module."""
    mod = sys.modules.get("eval_rl_bags")
    if mod is not None:
        return mod
    spec = importlib.util.spec_from_file_location("eval_rl_bags", HERE / "eval_rl_bags.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules["eval_rl_bags"] = mod  # its dataclasses look their module up
    spec.loader.exec_module(mod)
    return mod


# ---------------------------------------------------------------------------- configurations
@dataclass
class Variant:
    """One configuration of a log: ``config`` None = no config at all; ``tf_bag``: run on the
    copy of the log with the launch file's mounts as ``/tf_static``."""

    name: str
    config: dict[str, Any] | None
    tf_bag: bool = False


def _inputs(cfg: dict[str, Any], kind: str) -> list[dict[str, Any]]:
    return [s for s in cfg["sources"]["inputs"].values() if s.get("type") == kind]


def _toggle(cfg: dict[str, Any], kind: str, comp: str, on: bool) -> dict[str, Any] | None:
    """``cfg`` with ``comp`` fused by the first ``kind`` source (``on``, when no ``kind`` source
    fuses it yet) or by none (``on`` False: removed from every one); None when nothing changes
    (no such source, or already so)."""
    out = copy.deepcopy(cfg)
    srcs = _inputs(out, kind)
    if not srcs:
        return None
    if on:
        if any(comp in s.get("use", []) for s in srcs):
            return None
        srcs[0]["use"] = [*srcs[0].get("use", []), comp]
    else:
        if not any(comp in s.get("use", []) for s in srcs):
            return None
        for s in srcs:
            s["use"] = [c for c in s.get("use", []) if c != comp]
    # a source left with nothing to fuse goes
    out["sources"]["inputs"] = {n: s for n, s in out["sources"]["inputs"].items() if s.get("use")}
    return out


def _without_mounts(cfg: dict[str, Any]) -> dict[str, Any]:
    out = copy.deepcopy(cfg)
    out["sources"].pop("static_transforms", None)
    return out


def variants(converted: dict[str, Any], has_mounts: bool) -> list[Variant]:
    """The configurations of one log, from its converted r_l config (see the module doc)."""
    out = [Variant("defaults", None, tf_bag=has_mounts), Variant("r_l", converted)]
    if has_mounts:
        out.append(Variant("r_l, mount in /tf_static", _without_mounts(converted), tf_bag=True))
    seen = [yaml.safe_dump(converted, sort_keys=True)]

    def add(name: str, cfg: dict[str, Any] | None) -> None:
        if cfg is None:
            return
        text = yaml.safe_dump(cfg, sort_keys=True)
        if text in seen or not cfg["sources"]["inputs"]:
            return
        seen.append(text)
        out.append(Variant(name, cfg))

    for on in (True, False):
        sign = "+" if on else "-"
        add(f"{sign} gyro", _toggle(converted, "imu", "vyaw", on))
        add(f"{sign} wheel yaw", _toggle(converted, "odometry", "vyaw", on))
    both = _toggle(converted, "imu", "vyaw", True) or converted
    add("+ gyro + wheel yaw", _toggle(both, "odometry", "vyaw", True))
    flat = _toggle(converted, "imu", "roll", False)
    add("2-D", _toggle(flat, "imu", "pitch", False) if flat is not None else None)
    return out


# ---------------------------------------------------------------------------- GPS reference
def read_gps(bag: Path) -> np.ndarray | None:
    """The log's GPS fixes as local east / north metres, rows ``(t, e, n)`` (None: no GPS)."""
    from rosbags.rosbag1 import Reader

    ts = _rl_tool()._typestore()
    rows = []
    with Reader(bag) as r:
        conns = [c for c in r.connections if c.msgtype == "sensor_msgs/msg/NavSatFix"]
        if not conns:
            return None
        for c, _t, raw in r.messages(connections=conns[:1]):
            m = ts.deserialize_ros1(raw, c.msgtype)
            if m.status.status < 0 or not (math.isfinite(m.latitude) and math.isfinite(m.longitude)):
                continue
            rows.append((m.header.stamp.sec + m.header.stamp.nanosec * 1e-9, m.latitude, m.longitude))
    if len(rows) < 10:
        return None
    g = np.array(rows)
    r_earth = 6378137.0
    e = np.radians(g[:, 2] - g[0, 2]) * r_earth * math.cos(math.radians(g[0, 1]))
    n = np.radians(g[:, 1] - g[0, 1]) * r_earth
    return np.c_[g[:, 0], e, n]


def gps_end_error(stamps: np.ndarray, xy: np.ndarray, gps: np.ndarray, align_m: float = GPS_ALIGN_M) -> float | None:
    """The distance at the end between an estimate (``stamps``, ``xy``) and the GPS track, the
    estimate rigidly aligned to the GPS over its first ``align_m`` metres of travel (None: the
    GPS does not cover the estimate's start and end, or it travelled less)."""
    t = np.asarray(stamps, dtype=float)
    p = np.asarray(xy, dtype=float)
    if len(t) < 2 or gps[0, 0] > t[0] + 1.0 or gps[-1, 0] < t[-1] - 1.0:
        return None
    travelled = np.r_[0.0, np.cumsum(np.hypot(*np.diff(p, axis=0).T))]
    if travelled[-1] < align_m:
        return None
    sel = (gps[:, 0] >= t[0]) & (gps[:, 0] <= t[np.searchsorted(travelled, align_m)])
    if sel.sum() < 5:
        return None
    q = gps[sel, 1:3]
    e = np.c_[np.interp(gps[sel, 0], t, p[:, 0]), np.interp(gps[sel, 0], t, p[:, 1])]
    ec, qc = e.mean(axis=0), q.mean(axis=0)
    u, _, vt = np.linalg.svd((e - ec).T @ (q - qc))
    d = np.sign(np.linalg.det(vt.T @ u.T))
    rot = vt.T @ np.diag([1.0, d]) @ u.T
    end = rot @ (p[-1] - ec) + qc
    g_end = np.array([np.interp(t[-1], gps[:, 0], gps[:, 1]), np.interp(t[-1], gps[:, 0], gps[:, 2])])
    return float(np.hypot(*(end - g_end)))


def heading_check(case: Any, gps: np.ndarray, png: Path | None = None) -> list[str]:
    """Which heading source the log's GPS agrees with: the wheels' speed dead-reckoned along
    each of the IMU's orientation yaw, its gyro (through the launch file's mount) and the wheels'
    own yaw rate, each aligned to the GPS course over the first 60 s; lines of figures (and a plot)."""
    from rosbags.rosbag1 import Reader
    from scipy.spatial.transform import Rotation

    tool = _rl_tool()
    odom_topic, imu_topic = tool.topics(case.params)
    ts = tool._typestore()
    imu, odo = [], []
    frame = ""
    with Reader(case.bag) as r:
        conns = [c for c in r.connections if c.topic in (odom_topic, imu_topic)]
        for c, _t, raw in r.messages(connections=conns):
            m = ts.deserialize_ros1(raw, c.msgtype)
            t = m.header.stamp.sec + m.header.stamp.nanosec * 1e-9
            if c.topic == imu_topic:
                w, q = m.angular_velocity, m.orientation
                imu.append((t, w.x, w.y, w.z, q.x, q.y, q.z, q.w))
                frame = m.header.frame_id.lstrip("/")
            else:
                odo.append((t, m.twist.twist.linear.x, m.twist.twist.angular.z))
    a, o = np.array(imu), np.array(odo)
    tf = next((x for x in case.static_tfs if x[1] == frame), None)
    mount = Rotation.identity() if tf is None else Rotation.from_quat(tf[5:9])
    yaw = np.unwrap((Rotation.from_quat(a[:, 4:8]) * mount.inv()).as_euler("ZYX")[:, 0])
    wz = mount.apply(a[:, 1:4])[:, 2]
    gyro = np.r_[0.0, np.cumsum(0.5 * (wz[1:] + wz[:-1]) * np.diff(a[:, 0]))]
    wheel = np.r_[0.0, np.cumsum(o[:-1, 2] * np.diff(o[:, 0]))]
    t = gps[:, 0]
    tc, cog = [], []
    for i in range(len(t)):  # course over ground over 6 s, where the robot moved 3 m or more
        j = int(np.searchsorted(t, t[i] + 6.0))
        if j >= len(t):
            break
        d = gps[j, 1:3] - gps[i, 1:3]
        if np.hypot(*d) > 3.0:
            tc.append(0.5 * (t[i] + t[j]))
            cog.append(math.atan2(d[1], d[0]))
    tcs, course = np.array(tc), np.unwrap(np.array(cog))
    to = o[:, 0]
    dt = np.diff(to, prepend=to[0])
    v = np.r_[0.0, o[:-1, 1]]
    g0 = np.array([np.interp(to[0], t, gps[:, 1]), np.interp(to[0], t, gps[:, 2])])
    g_at = np.c_[np.interp(to, t, gps[:, 1]), np.interp(to, t, gps[:, 2])]
    sources = {"IMU orientation yaw": (a[:, 0], yaw), "gyro (through the mount)": (a[:, 0], gyro),
               "wheels' yaw rate": (to, wheel)}
    lines = [f"{case.bag.name}: {len(gps)} GPS fixes; turn over the log: " + ", ".join(
        f"{k} {float(h[-1] - h[0]):.2f} rad" for k, (_, h) in sources.items())]
    lines.append(f"GPS: the robot ends {float(np.hypot(*(g_at[-1] - g_at[0]))):.1f} m from its start; "
                 f"r_l's expected final position is {math.hypot(*case.expected_xyz[:2]):.1f} m from it")
    paths = {}
    for name, (ht, h) in sources.items():
        hc = np.interp(tcs, ht, h)
        res = course - hc - np.median((course - hc)[tcs < tcs[0] + 60.0])
        off = float(np.median(course - hc - res))
        blocks = [float(np.degrees(np.mean(res[(tcs >= tcs[0] + k) & (tcs < tcs[0] + k + 40)])))
                  for k in range(0, int(tcs[-1] - tcs[0]), 40)]
        hh = np.interp(to, ht, h) + off
        xy = g0 + np.cumsum(np.c_[v * np.cos(hh) * dt, v * np.sin(hh) * dt], axis=0)
        e = np.hypot(*(xy - g_at).T)
        paths[name] = xy
        lines.append(f"  {name}: course minus GPS course per 40 s {' '.join(f'{b:+.0f}' for b in blocks)} deg; "
                     f"wheel speed along it ends {e[-1]:.1f} m from the GPS (RMSE {np.sqrt(np.mean(e**2)):.1f} m)")
    if png is not None:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(6, 7))
        ax.plot(gps[:, 1], gps[:, 2], "k.", ms=2, label="GPS (/fix)")
        for name, xy in paths.items():
            ax.plot(xy[:, 0], xy[:, 1], label=f"wheel speed along the {name}")
        ax.set_xlabel("east m")
        ax.set_ylabel("north m")
        ax.axis("equal")
        ax.legend(fontsize=8)
        ax.set_title(f"{log_label(case)}: dead reckoning against the log's GPS")
        fig.tight_layout()
        fig.savefig(png, dpi=80)
        plt.close(fig)
    return lines


# ---------------------------------------------------------------------------- the runs
@dataclass
class Cell:
    """One run of the matrix."""

    log: str
    variant: str
    backend: str
    tolerance_m: float
    error_m: float | None  # from r_l's answer (None: the run failed)
    final: tuple[float, float] | None
    gps_m: float | None = None
    wall_s: float = 0.0
    note: str = ""
    stats: dict[str, Any] = field(default_factory=dict)
    failure: str | None = None  # what `fgloc run` says when it calls the run unusable (it exits 3)

    @property
    def passed(self) -> bool:
        return self.error_m is not None and self.error_m < self.tolerance_m


def log_label(case: Any) -> str:
    """``noetic test1`` / ``groovy test3``: the branch folder's and the bag's names."""
    branch = "groovy" if "groovy" in case.source.parent.name or "test_bag" in case.name else "noetic"
    return f"{branch} {case.bag.stem}"


def _merged(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    out = copy.deepcopy(base)
    for k, v in over.items():
        out[k] = _merged(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else copy.deepcopy(v)
    return out


def run_matrix(cases: Iterable[Any], backends: list[str], work: Path, only_variants: list[str] | None = None,
               progress: Callable[[Cell], None] | None = None, overlay: dict[str, Any] | None = None) -> list[Cell]:
    """Every configuration of every case (an r_l :class:`eval_rl_bags.Case`) with every back-end;
    ``overlay``: settings merged into every configuration (``{"smoother": {...}}``)."""
    tool = _rl_tool()
    from fgloc.io.tum import read_tum

    cells: list[Cell] = []
    for case in cases:
        label = log_label(case)
        conv, _, err = tool.convert(case, work)
        if conv is None:
            cells.extend(Cell(label, "r_l", be, case.tolerance_m, None, None, note=f"conversion: {err}")
                         for be in backends)
            continue
        converted = yaml.safe_load(conv.read_text())
        gps = read_gps(case.bag)
        tf_bag = None
        ex, ey, _ = case.expected_xyz
        for v in variants(converted, bool(case.static_tfs)):
            if only_variants and v.name not in only_variants:
                continue
            bag = case.bag
            if v.tf_bag:
                if tf_bag is None:
                    tf_bag = tool.with_static_tfs(case.bag, case.static_tfs, work / f"{label.replace(' ', '_')}_tf.bag")
                bag = tf_bag
            slug = f"{label}-{v.name}".replace(" ", "_").replace("/", "").replace(",", "")
            cfg_path = work / f"{slug}.yaml"
            cfg_path.write_text(yaml.safe_dump(_merged(v.config or {}, overlay or {}), sort_keys=False))
            for be in backends:
                t0 = time.perf_counter()
                res = tool.run_fgloc(bag, cfg_path, be, None, None, work / f"{slug}-{be}")
                wall = time.perf_counter() - t0
                if "error" in res:
                    cell = Cell(label, v.name, be, case.tolerance_m, None, None, wall_s=wall, note=res["error"])
                else:
                    f = res["final"]
                    cell = Cell(label, v.name, be, case.tolerance_m, math.hypot(f[0] - ex, f[1] - ey),
                                (float(f[0]), float(f[1])), wall_s=wall, stats=res["stats"],
                                failure=res.get("failure"))
                    if gps is not None:
                        tr = read_tum(work / f"{slug}-{be}" / "trajectory.tum")
                        cell.gps_m = gps_end_error(tr.stamps, tr.poses[:, :2], gps)
                cells.append(cell)
                if progress is not None:
                    progress(cell)
    return cells


# ---------------------------------------------------------------------------- the table
def paired(cells: list[Cell]) -> dict[tuple[str, str], dict[str, Cell]]:
    """Cells by (log, configuration), then by back-end."""
    out: dict[tuple[str, str], dict[str, Cell]] = {}
    for c in cells:
        out.setdefault((c.log, c.variant), {})[c.backend] = c
    return out


def _err(c: Cell | None) -> str:
    if c is None:
        return "-"
    if c.error_m is None:
        return "ERROR"
    return f"{c.error_m:.3f} {'pass' if c.passed else 'FAIL'}"


def _diverged(c: Cell) -> float | None:
    """s of the run the back-end reported its fused heading following none of its heading sources."""
    v = getattr(c.stats, "backend", {}).get("heading_diverged_s") if c.stats else None
    return None if v is None else float(v)


def _exit(c: Cell | None) -> str:
    """What `fgloc run` exits with: 0, or 3 when it calls the run unusable; - when it did not run."""
    if c is None or c.error_m is None:
        return "-"
    return "3" if c.failure else "0"


def table(cells: list[Cell], markdown: bool = True) -> str:
    """The matrix, one row per (log, configuration), a column per back-end."""
    backends = list(dict.fromkeys(c.backend for c in cells))
    has_gps = any(c.gps_m is not None for c in cells)
    head = ["log", "configuration", "tolerance m", *[f"{b} m" for b in backends]]
    if has_gps:
        head += [f"{b}: GPS m" for b in backends]
    div = [b for b in backends if any(c.backend == b and _diverged(c) is not None for c in cells)]
    head += [f"{b}: heading diverged s" for b in div]
    head.append("exit " + " / ".join(backends))
    rows = []
    for (log, var), by in paired(cells).items():
        any_cell = next(iter(by.values()))
        row = [log, var, f"{any_cell.tolerance_m:.3f}", *[_err(by.get(b)) for b in backends]]
        if has_gps:
            row += [("-" if by.get(b) is None or by[b].gps_m is None else f"{by[b].gps_m:.1f}") for b in backends]
        for b in div:
            d = _diverged(by[b]) if b in by else None
            row.append("-" if d is None else f"{d:.0f}")
        row.append(" / ".join(_exit(by.get(b)) for b in backends))
        rows.append(row)
    if markdown:
        lines = ["| " + " | ".join(head) + " |", "|" + "|".join(["---"] * 2 + ["--:"] * (len(head) - 2)) + "|"]
        lines += ["| " + " | ".join(r) + " |" for r in rows]
        return "\n".join(lines)
    width = [max(len(str(r[i])) for r in [head, *rows]) for i in range(len(head))]
    return "\n".join("  ".join(str(v).ljust(w) for v, w in zip(r, width, strict=True)).rstrip() for r in [head, *rows])


@dataclass
class Verdict:
    """The matrix's two checks: the smoother's median error at most the EKF's, and the smoother
    within tolerance wherever the EKF is."""

    median: dict[str, float]
    passes: dict[str, int]
    cells: int
    worse: list[tuple[str, str, float, float]]  # (log, configuration, EKF m, smoother m): EKF pass, smoother not

    def lines(self) -> list[str]:
        out = ["median m from r_l's answer: " + ", ".join(f"{b} {m:.3f}" for b, m in self.median.items()),
               f"within tolerance (of {self.cells}): " + ", ".join(f"{b} {n}" for b, n in self.passes.items()),
               f"EKF within tolerance, smoother not: {len(self.worse)}"]
        out += [f"  {log}, {var}: EKF {e:.3f} m, smoother {s:.3f} m" for log, var, e, s in self.worse]
        return out


def verdict(cells: list[Cell], a: str = "ekf", b: str = "smoother") -> Verdict:
    """:class:`Verdict` over the pairs both back-ends ran (a failed run counts as infinitely far; a
    pair where both failed, e.g. a log whose topics the defaults cannot choose, is left out)."""
    pairs = [(k, by) for k, by in paired(cells).items()
             if a in by and b in by and (by[a].error_m is not None or by[b].error_m is not None)]
    errs = {be: [by[be].error_m if by[be].error_m is not None else math.inf for _, by in pairs] for be in (a, b)}
    median = {be: statistics.median(v) if v else math.nan for be, v in errs.items()}
    passes = {be: sum(by[be].passed for _, by in pairs) for be in (a, b)}
    worse = [(k[0], k[1], by[a].error_m or math.inf, by[b].error_m if by[b].error_m is not None else math.inf)
             for k, by in pairs if by[a].passed and not by[b].passed]
    return Verdict(median, passes, len(pairs), worse)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("folders", nargs="+", type=Path, help="folders with r_l's test bags and launch files")
    ap.add_argument("--backends", nargs="+", default=["ekf", "smoother"])
    ap.add_argument("--only", nargs="+", default=None, help="these logs only (noetic test1, groovy test3, ...)")
    ap.add_argument("--variants", nargs="+", default=None, help="these configurations only (names as printed)")
    ap.add_argument("--out", type=Path, default=None, help="where fgloc writes (default: a temporary folder)")
    ap.add_argument("--markdown", action="store_true", help="print the table as Markdown")
    ap.add_argument("--heading-check", type=Path, default=None, metavar="PNG",
                    help="only compare the heading sources with the log's GPS (plot into PNG), no runs")
    ap.add_argument("--overlay", type=Path, default=None,
                    help="a YAML of fgloc settings merged into every configuration (what-if runs)")
    a = ap.parse_args(argv)
    from tqdm import tqdm

    tool = _rl_tool()
    work = a.out or Path(tempfile.mkdtemp(prefix="eval_rl_matrix_"))
    work.mkdir(parents=True, exist_ok=True)
    cases = [c for c in tool.find_cases(a.folders) if a.only is None or log_label(c) in a.only]
    if not cases:
        print(f"no r_l test cases (testN.bag + its launch file) in {', '.join(map(str, a.folders))}")
        return 0
    if a.heading_check is not None:
        for case in cases:
            gps = read_gps(case.bag)
            if gps is not None:
                print("\n".join(heading_check(case, gps, a.heading_check)))
        return 0
    t0 = time.perf_counter()
    bar = tqdm(desc="runs", unit="run", file=sys.stderr)

    def tick(c: Cell) -> None:
        bar.update(1)
        bar.set_postfix_str(f"{c.log}, {c.variant}, {c.backend}")

    overlay = yaml.safe_load(a.overlay.read_text()) if a.overlay else None
    cells = run_matrix(cases, a.backends, work, a.variants, tick, overlay)
    bar.close()
    print(table(cells, markdown=a.markdown))
    print()
    if {"ekf", "smoother"} <= set(a.backends):
        for line in verdict(cells).lines():
            print(line)
    for c in cells:
        if c.failure:
            print(f"exit 3: {c.log}, {c.variant}, {c.backend}: {c.failure}")
    failed = [c for c in cells if c.error_m is None]
    for c in failed:
        print(f"run failed: {c.log}, {c.variant}, {c.backend}: {c.note}")
    print(f"\n{len(cells)} runs in {time.perf_counter() - t0:.0f} s (fgloc outputs in {work})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
