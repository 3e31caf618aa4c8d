"""Two real processes over real DDS on loopback: ``fgloc replay --ros2`` publishes a simulated log,
``fgloc live --ros2`` localizes it, and an independent ROS 2 peer (tests/ros2/independent.py, Cyclone DDS
directly) reads /amcl_pose, map -> odom on /tf and /fgloc/status, and sends /initialpose.

The reference is ``fgloc run`` on the same log: its ``online.tum`` is the same session's pose at each
scan's stamp as it was known then (what /amcl_pose carries), so the live one must agree within 5 mm (the
live runner releases odometry by stamp, the log by log time: a message in another order moves a
smoothed pose by far less)."""

from __future__ import annotations

import json
import math
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from .conftest import LOOPBACK, wait_for

TOL_M = 0.005


def _simulate(out: Path, route: list[list[float]], faults: dict | None = None, seed: int = 0) -> Path:
    from fgloc.sim import run_scenario, write_sim

    write_sim(run_scenario({"name": "ros2", "route": route, "faults": faults or {}}, seed=seed), out)
    return out


@pytest.fixture(scope="module")
def short_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 7-second paper-hall run (5 m straight), and fgloc run on it."""
    from fgloc.app.run import RunRequest, run_log

    d = _simulate(tmp_path_factory.mktemp("ros2sim"), [[2.5, 3.0], [7.5, 3.0]])
    run_log(RunRequest(log=d / "log.mcap", outdir=d / "run", map_yaml=d / "map.yaml", initial_pose=(2.5, 3.0, 0.0)))
    return d


def _fgloc(*args: str) -> list[str]:
    return [sys.executable, "-m", "fgloc.cli", *args]


def _live(domain: int, d: Path, *extra: str) -> subprocess.Popen:
    return subprocess.Popen(_fgloc("live", "--ros2", "--domain", str(domain), "--interface", LOOPBACK, "--quiet",
                                   "--json", "--duration", "900", *extra),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=d)


def _replay(domain: int, log: Path, *extra: str) -> subprocess.CompletedProcess:
    return subprocess.run(_fgloc("replay", str(log), "--ros2", "--domain", str(domain), "--interface", LOOPBACK,
                                 "--wait", "60", "--quiet", *extra),
                          capture_output=True, text=True, timeout=300)


def _stop(p: subprocess.Popen) -> tuple[int, dict, str]:
    p.send_signal(signal.SIGTERM)  # handled as Ctrl-C; a SIGINT stays ignored when the tests run in the background
    out, err = p.communicate(timeout=120)
    return p.returncode, (json.loads(out) if out.strip().startswith("{") else {}), err


def _pose_statuses(peer) -> list[dict[str, str]]:
    """The "fgloc: pose" entries of every /fgloc/status the peer received, as key -> value."""
    return [{v.key: v.value for v in st.values} for a in list(peer.status) for st in a.status
            if st.name == "fgloc: pose"]


def _settle(peer, n_scans: int, timeout: float = 180.0) -> None:
    """Wait until fgloc live is done with the replay: its /fgloc/status says every one of the ``n_scans``
    scans was handled (fused or skipped as a backlog) and nothing more was published over a status
    period (two statuses in a row alike), and the peer holds the last /amcl_pose published.  Conditions,
    not times: a loaded machine only makes it later (``timeout`` is the bound of a hung node)."""
    def done() -> bool:
        st = _pose_statuses(peer)[-2:]
        if len(st) < 2 or any("scans" not in s for s in st):
            return False
        handled = int(st[-1]["scans"]) + int(st[-1]["scans_skipped_backlog"])
        if handled < n_scans or st[0].get("poses_published") != st[1].get("poses_published"):
            return False
        last = st[-1].get("pose_published_stamp")
        return last is None or any(abs(p[0] - float(last)) < 5e-6 for p in list(peer.poses)[-50:])

    wait_for(done, timeout, step=0.1)


class _Online:
    """fgloc run's online.tum, looked up by stamp: ``offset_s`` later (the replay moved the stamps onto the
    wall clock), within ``tol_s`` (TUM files keep 9 decimals; a stamp since 1970 as float64, ~0.2 us)."""

    def __init__(self, d: Path, offset_s: float = 0.0, tol_s: float = 1e-6) -> None:
        from fgloc.io.tum import read_tum

        tr = read_tum(d / "run" / "online.tum")
        self.t, self.p = tr.stamps, tr.poses
        self.offset_s, self.tol_s = offset_s, tol_s

    def __len__(self) -> int:
        return len(self.t)

    def get(self, t: float) -> np.ndarray | None:
        t = t - self.offset_s
        k = int(np.searchsorted(self.t, t - self.tol_s))
        return self.p[k] if k < len(self.t) and abs(self.t[k] - t) <= self.tol_s else None

    def find_offset(self, stamps: list[float]) -> None:
        """The one offset that puts the most of ``stamps`` on this file's (tried: from the first stamp)."""
        first = min(stamps)

        def matches(offset: float) -> int:
            self.offset_s = offset
            return sum(self.get(s) is not None for s in stamps)

        self.offset_s = float(max((first - t for t in self.t[:100]), key=matches))


def _odom_poses(d: Path) -> tuple[np.ndarray, np.ndarray]:
    from fgloc.io import open_log

    r = open_log(d / "log.mcap")
    rows = [(m.stamp, *m.pose) for _, m in r.messages(["/odom"]) if m.pose is not None]
    a = np.array(rows)
    return a[:, 0], a[:, 1:]


def test_live_over_dds_matches_fgloc_run(short_log: Path, dds_domain: int, tmp_path: Path) -> None:
    from fgloc.geometry import compose, wrap_angle
    from fgloc.io import open_log

    from .independent import Peer

    d = short_log
    peer = Peer(dds_domain)
    rec = tmp_path / "live.mcap"
    live = _live(dds_domain, d, "--map", str(d / "map.yaml"), "--initial-pose", "2.5", "3.0", "0.0",
                 "--record", str(rec))
    try:
        # stamped as a robot's drivers stamp (on the wall clock): nothing waits for the host clock to pass them
        rep = _replay(dds_domain, d / "log.mcap", "--now")
        assert rep.returncode == 0, rep.stderr
        assert "/scan" in rep.stdout and "on domain" in rep.stdout
        ref = _Online(d, tol_s=5e-6)
        _settle(peer, open_log(d / "log.mcap").summary()["topics"]["/scan"]["count"])
    finally:
        code, report, err = _stop(live)
        peer.close()
    assert code == 0, err
    got = {e["topic"]: e["messages"] for e in report["ros2"]["endpoints"] if e["direction"] == "sub"}
    counts = {t: v["count"] for t, v in open_log(d / "log.mcap").summary()["topics"].items()}
    assert all(got[t] == counts[t] for t in ("/scan", "/odom", "/imu", "/tf_static")), (got, counts)
    # /amcl_pose (read back by the independent peer) against fgloc run's fused pose at the same stamps
    poses = peer.poses
    assert len(poses) >= 0.95 * len(ref), (len(poses), len(ref), err)
    assert {p[4] for p in poses} == {"map"}
    ref.find_offset([p[0] for p in poses])
    assert abs(ref.offset_s - time.time()) < 600  # the stamps were on the wall clock
    common = [(p, q) for p in poses if (q := ref.get(p[0])) is not None]
    assert len(common) >= 0.95 * len(ref)
    err_m = np.array([math.hypot(p[1] - q[0], p[2] - q[1]) for p, q in common])
    err_yaw = np.array([abs(float(wrap_angle(p[3] - q[2]))) for p, q in common])
    assert err_m.max() <= TOL_M, f"max {err_m.max():.4f} m"
    assert np.degrees(err_yaw.max()) < 0.5
    # map -> odom on /tf, post-dated by the transform tolerance (1 s), composed with the log's own
    # odom -> base_link at the pose's stamp, is fgloc run's pose too
    tfs = [t for t in peer.tfs if t[1] == "map" and t[2] == "odom"]
    assert len(tfs) >= 0.95 * len(poses)
    ts, op = _odom_poses(d)
    tf_err = []
    for s_wall, _, _, x, y, th in tfs:
        q = ref.get(s_wall - 1.0)
        s = s_wall - ref.offset_s
        if q is None:
            continue
        # the log's odom -> base_link at the pose's stamp, interpolated between its odometry messages
        odom = np.array([np.interp(s - 1.0, ts, op[:, k]) for k in range(2)] + [0.0])
        k = min(int(np.searchsorted(ts, s - 1.0)), len(ts) - 1)
        odom[2] = op[k, 2] if abs(ts[k] - (s - 1.0)) < 1e-3 else np.interp(s - 1.0, ts, np.unwrap(op[:, 2]))
        base = compose(np.array([x, y, th]), odom)
        tf_err.append(math.hypot(base[0] - q[0], base[1] - q[1]))
    assert len(tf_err) >= 0.95 * len(common)
    assert max(tf_err) <= TOL_M
    # the live report: every scan fused, none lost to a backlog, the DDS problems (a replay that ended)
    assert report["ros2"]["published"] == len(poses)
    scan_ep = next(e for e in report["ros2"]["endpoints"] if e["topic"] == "/scan" and e["direction"] == "sub")
    assert scan_ep["messages"] == open_log(d / "log.mcap").summary()["topics"]["/scan"]["count"]
    assert scan_ep["undecodable"] == 0 and scan_ep["qos"] == "best_effort/volatile/100"
    assert scan_ep["delivery_ms"]["p50"] >= 0.0  # written (the sample's source timestamp) -> received
    # map -> odom went out at each scan's match, before /amcl_pose (which waits for the odometry / IMU past
    # the scan for the smoother's keyframe): per scan, its transform before its pose; the latencies from the
    # scan, and from those inputs in
    r2 = report["ros2"]
    assert r2["tf_at_match"] and r2["tf_published"] >= 0.95 * len(poses) and r2["tf_refined"] > 0
    tf, pose, own = r2["scan_to_tf_ms"], r2["scan_to_pose_ms"], r2["inputs_in_to_pose_ms"]
    order = r2["tf_before_pose"]
    assert order["tf_first"] + order["no_tf"] == pose["n"] and order["tf_after"] == 0, order
    assert order["no_tf"] <= 0.01 * pose["n"], order
    if pose["n"]:  # none when the node started after the whole log came (a loaded machine): all fused at once
        # per scan, the inputs' wait is part of the pose's: its quantiles are at most the pose's
        assert 0.0 <= tf["p50"] and 0.0 <= own["p50"] <= pose["p50"] and own["p99"] <= pose["p99"]
    assert 0 < r2["tf_at_match_vs_online_mm"]["n"] and r2["tf_at_match_vs_online_mm"]["max"] <= 1e3 * TOL_M
    # /fgloc/status: a DiagnosticArray naming each topic and the pose
    assert peer.status, "no /fgloc/status"
    names = {s.name for s in peer.status[-1].status}
    assert {"fgloc: sub /scan", "fgloc: pub /amcl_pose", "fgloc: pose"} <= names
    # Ctrl-C left the recording complete: every scan received is in it, readable
    r = open_log(rec)
    assert r.summary()["topics"]["/scan"]["count"] == scan_ep["messages"]


def test_initialpose_relocalizes_after_a_kidnap_a_new_map_is_used_and_faults_are_named(
        tmp_path: Path, dds_domain: int) -> None:
    """The robot is carried 4 m ahead at t = 4 s; fgloc's own relocalization is switched off, so only an
    operator's /initialpose (RViz's 2D Pose Estimate) can bring it back.  The map comes on /map from two
    publishers (the replay and the peer: the same map twice is one map); later the peer publishes a new
    map, the same hall 10 cm further in y: from then on the poses are on it.  Meanwhile a publisher of
    another type on /imu and undecodable bytes on /scan are counted and named, and localization goes on."""
    from fgloc.io.tum import read_tum
    from fgloc.maps import load_map
    from fgloc.ros2 import qos
    from fgloc.ros2.replay import replay
    from fgloc.ros2.transport import CycloneTransport

    from .independent import Peer

    d = _simulate(tmp_path / "kid", [[2.5, 3.0], [14.5, 3.0]], faults={"kidnap": {"time": 4.0, "skip_s": 5.0}})
    cfg = tmp_path / "noreloc.yaml"
    cfg.write_text("pipeline: {relocalize_after: 100000, lost_after_s: 1000.0}\nros2: {status_period_s: 0.25}\n")
    gt = read_tum(d / "ground_truth.tum")
    occ = load_map(d / "map.yaml")
    shift_y = 0.1  # the new map: two cells further in y

    def publish_map(dy: float) -> None:
        peer.publish_map(occ.data.ravel(), occ.width, occ.height, occ.resolution, float(occ.origin[0]),
                         float(occ.origin[1]) + dy)

    peer = Peer(dds_domain)
    publish_map(0.0)
    live = _live(dds_domain, tmp_path, "--initial-pose", "2.5", "3.0", "0.0", "--config", str(cfg))
    rogue = CycloneTransport(dds_domain, LOOPBACK)
    try:
        rogue.start()
        rogue.publisher("/imu", "nav_msgs/msg/Odometry", qos.DEFAULT)
        garbage = rogue.publisher("/scan", "sensor_msgs/msg/LaserScan", qos.DEFAULT)
        assert wait_for(lambda: garbage.health.matched == 1, 120.0)
        sent = [0]
        # valid CDR (Cyclone DDS drops structurally broken samples itself) that is not a valid message: a
        # frame id that is not UTF-8
        from fgloc.ros2 import codec
        from fgloc.types import LaserScan

        bad = codec.encode(LaserScan(1.0, -1.0, 0.1, 0.1, 10.0, np.ones(5, np.float32), frame_id="laser"))[1]
        bad = bad.replace(b"laser", b"las\xffr")

        def counted() -> bool:  # bad scans on /scan until /fgloc/status says they were counted
            garbage.write(bad)
            sent[0] += 1
            return any(v.key == "undecodable" and v.value != "0" for a in peer.status[-1:] for st in a.status
                       if st.name == "fgloc: sub /scan" for v in st.values)

        # the log in three parts, each published once fgloc is done with the one before (a loaded machine
        # makes fgloc lag a replay at 1x: /initialpose or a new map queued behind the rest of the log would
        # find no scan after them): to t_a (the kidnap felt), to t_b (relocalized), then the rest
        t_a, t_b = 6.5, 9.8
        scans = [0]

        def play(offset_s: float = 0.0, duration_s: float | None = None, **kw: object) -> None:
            # in this process (fgloc's replay on a participant of its own; fgloc live is the other process),
            # then wait until fgloc is done with it
            tr = CycloneTransport(dds_domain, LOOPBACK, node_name="replay")
            try:
                stats = replay(d / "log.mcap", tr, wait_for_subscribers_s=60.0, start_offset_s=offset_s,
                               duration_s=duration_s, **kw)  # type: ignore[arg-type]
            finally:
                tr.close()
            scans[0] += stats.published.get("/scan", 0)
            _settle(peer, scans[0])

        # the first part starts (it waits for fgloc's subscriptions) while the bad scans are sent
        injector = threading.Thread(target=lambda: wait_for(counted, 120.0, step=0.3), daemon=True)
        injector.start()
        play(0.0, t_a, occ_map=occ)
        injector.join()
        assert counted()
        # after the kidnap: poses past t = 6 s; tell fgloc where the robot is
        assert any(p[0] > 6.0 for p in peer.poses), "no pose after the kidnap"
        assert wait_for(peer.initial_pose_matched, 60.0)
        t_now = max(p[0] for p in peer.poses)
        t_ip = t_a + 0.3
        x, y, th = (float(np.interp(t_ip, gt.stamps, gt.poses[:, k])) for k in range(3))
        peer.initial_pose(t_ip, x, y, th)
        play(t_a, t_b - t_a)
        good_poses = sum(p[0] > t_ip and math.hypot(p[1] - np.interp(p[0], gt.stamps, gt.poses[:, 0]),
                                                    p[2] - np.interp(p[0], gt.stamps, gt.poses[:, 1])) < 0.05
                         for p in list(peer.poses))
        assert good_poses >= 12, good_poses
        t_map = max(p[0] for p in peer.poses)
        publish_map(shift_y)
        play(t_b)
    finally:
        code, report, err = _stop(live)
        peer.close()
        rogue.close()
    assert code == 0, err
    poses = np.array([p[:4] for p in peer.poses])

    def error(row: np.ndarray) -> float:
        gx, gy = (float(np.interp(row[0], gt.stamps, gt.poses[:, k])) for k in range(2))
        return math.hypot(row[1] - gx, row[2] - gy)

    before = [error(r) for r in poses if 5.0 < r[0] < t_now]
    assert before and min(before) > 1.0, "the kidnap was not felt (relocalization not off?)"
    # the pose is re-initialized at the first scan fgloc fuses after /initialpose came (later than t_ip when
    # the live loop lags the replay): from there on every pose is right, until the new map
    after = [error(r) for r in sorted(poses.tolist()) if t_ip < r[0] <= t_map]
    good = next((k for k, e in enumerate(after) if e < 0.05), None)
    assert good is not None, f"never relocalized; {err[-1500:]}"
    assert max(after[good:]) < 0.05 and min(after[:good], default=math.inf) > 1.0
    assert len(after) - good >= 10
    # the new map is used from a scan after it came on: the poses move with it (the robot is shift_y
    # further in y on it), every one from there on
    rows = sorted(poses.tolist())
    on_new = [math.hypot(r[1] - float(np.interp(r[0], gt.stamps, gt.poses[:, 0])),
                         r[2] - shift_y - float(np.interp(r[0], gt.stamps, gt.poses[:, 1]))) for r in rows]
    k_new = next((k for k, r in enumerate(rows) if r[0] > t_map and on_new[k] < 0.02), None)
    assert k_new is not None, f"the new map was not used; {err[-1500:]}"
    assert len(rows) - k_new >= 20 and max(on_new[k_new:]) < 0.02, max(on_new[k_new:])
    assert all(error(np.array(r)) < 0.02 for r in rows[:k_new] if r[0] > t_map), "a pose between both maps"
    assert "a new map on /map" in err and report["ros2"]["map_changes"] == 1
    assert report["counters"]["localizer"]["reinitializations"] == 2  # /initialpose and the new map
    assert report["counters"]["localizer"]["map_changes"] == 1
    probs = "; ".join(report["ros2"]["problems"])
    scan_ep = next(e for e in report["ros2"]["endpoints"] if e["topic"] == "/scan" and e["direction"] == "sub")
    assert 1 <= scan_ep["undecodable"] <= sent[0]
    assert f"/scan {scan_ep['undecodable']} undecodable" in probs
    assert "/imu" in probs and "another type nav_msgs/msg/Odometry" in probs
