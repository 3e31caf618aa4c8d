"""`fgloc run --view`: a real Foxglove WebSocket client against the real server (subprocess)."""

from __future__ import annotations

import asyncio
import math
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from fgloc.geometry import compose, quaternion_to_yaw
from fgloc.io.tum import read_tum
from fgloc.maps import OccupancyMap
from fgloc.view import channels as ch

from .conftest import free_port
from .foxglove_ws import SUBPROTOCOL, stamp, watch

FGLOC = [sys.executable, "-m", "fgloc.cli"]


def _run_args(d: Path, out: Path, port: int, realtime: float) -> list[str]:
    return FGLOC + ["run", str(d / "log.mcap"), "--map", str(d / "map.yaml"), "--initial-pose", "2.5", "3.0", "0",
                    "-o", str(out), "-q", "--view", f"127.0.0.1:{port}", "--realtime", str(realtime)]


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(Path(__file__).resolve().parents[2]) + os.pathsep + env.get("PYTHONPATH", "")
    return env


def _pose2(p) -> np.ndarray:
    return np.array([p.position.x, p.position.y,
                     quaternion_to_yaw(p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w)])


def _tf2(t) -> np.ndarray:
    r = t.rotation
    return np.array([t.translation.x, t.translation.y, quaternion_to_yaw(r.x, r.y, r.z, r.w)])


def test_run_view_speaks_foxglove_and_shows_the_run(short_dir, short_sim, tmp_path):
    """The issue's first must-show: subprotocol, advertise, subscribe, schema-decoded map /
    scan / pose / transforms whose content is the map file, the sim's laser and online.tum."""
    pytest.importorskip("google.protobuf")
    pytest.importorskip("websockets")
    port = free_port()
    out = tmp_path / "out"
    proc = subprocess.Popen(_run_args(short_dir, out, port, realtime=4.0), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=_env())
    try:
        want = {ch.MAP, ch.SCAN, ch.POSE, ch.TF, ch.FIX, ch.HEALTH}
        session = asyncio.run(watch(f"ws://127.0.0.1:{port}", want, connect_timeout_s=60, max_s=60))
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, stderr
    assert f"Foxglove view on ws://127.0.0.1:{port}" in stderr
    assert "Traceback" not in stderr
    # protocol: negotiated subprotocol, serverInfo, advertised Foxglove schemas
    assert session.subprotocol == SUBPROTOCOL
    assert session.server_info is not None and session.server_info["op"] == "serverInfo"
    adv = {c["topic"]: c for c in session.channels.values()}
    for spec in ch.CHANNELS:
        assert spec.topic in adv, f"{spec.topic} not advertised"
        if spec.schema != "json":
            assert adv[spec.topic]["schemaName"] == spec.schema
            assert adv[spec.topic]["encoding"] == "protobuf" and adv[spec.topic]["schemaEncoding"] == "protobuf"
        else:
            assert adv[spec.topic]["encoding"] == "json"
    assert session.closed_by_server  # the run ended and closed its server
    # the map: the map file's size, resolution, origin and cells
    maps = session.by_topic(ch.MAP)
    assert len(maps) >= 1
    grid = maps[-1].message
    occ = OccupancyMap.load(short_dir / "map.yaml")
    assert grid.column_count == occ.width
    assert grid.cell_size.x == pytest.approx(occ.resolution) and grid.cell_size.y == pytest.approx(occ.resolution)
    assert len(grid.data) == grid.row_stride * occ.height
    assert grid.frame_id == "map"
    assert grid.pose.position.x == pytest.approx(occ.origin[0]) and grid.pose.position.y == pytest.approx(occ.origin[1])
    fields = {f.name: f.offset for f in grid.fields}
    occupancy = np.frombuffer(grid.data, dtype=np.int8)[fields["occupancy"]::grid.cell_stride]
    assert np.array_equal(occupancy.reshape(occ.height, occ.width), np.clip(occ.data, -1, 100))
    # scans: in the laser frame, the simulated laser's beams
    scans = session.by_topic(ch.SCAN)
    assert len(scans) >= 5
    sim_scan = short_sim.topic("/scan")[0]
    for m in scans:
        assert m.message.frame_id == sim_scan.frame_id
        assert len(m.message.ranges) == len(sim_scan.ranges)
        assert m.message.start_angle == pytest.approx(sim_scan.angle_min)
    # transforms: map -> odom -> base_link -> laser, the laser at its mount
    tfs = session.by_topic(ch.TF)
    assert len(tfs) >= 5
    chain = [(t.parent_frame_id, t.child_frame_id) for t in tfs[-1].message.transforms]
    assert chain == [("map", "odom"), ("odom", "base_link"), ("base_link", sim_scan.frame_id)]
    mount = _tf2(tfs[-1].message.transforms[2])
    assert mount == pytest.approx(np.asarray(short_sim.laser_mount.pose), abs=1e-9)
    # the fused pose: the run's online trajectory at that stamp, and map->odom (+) odom->base
    online = read_tum(out / "online.tum")
    poses = session.by_topic(ch.POSE)
    assert len(poses) >= 5
    tf_at = {m.log_time_ns: m.message for m in tfs}
    errors = []
    for m in poses:
        t = stamp(m.message.timestamp)
        p = _pose2(m.message.pose)
        assert m.message.frame_id == "map"
        # the fused pose is the estimate at the newest odometry stamp; online.tum holds the
        # estimates at the scan stamps as they were known online: interpolate it there
        q = online.interpolate(t)[0]
        errors.append(float(np.hypot(*(p[:2] - q[:2]))))
        assert abs(math.remainder(p[2] - q[2], 2 * math.pi)) < math.radians(0.5)
        tf = tf_at.get(m.log_time_ns)
        if tf is not None:  # map -> (odom ->) base_link composed along the chain
            via, frame = np.zeros(3), "map"
            for t_ in tf.transforms:
                if t_.parent_frame_id == frame and frame != "base_link":
                    via, frame = compose(via, _tf2(t_)), t_.child_frame_id
            assert frame == "base_link"
            assert via[:2] == pytest.approx(p[:2], abs=1e-6)
    assert max(errors) < 0.005 and float(np.median(errors)) < 0.001
    # the front-end's result of each scan, with a reason when there is no fix
    fixes = [m.message for m in session.by_topic(ch.FIX)]
    assert fixes and {f["status"] for f in fixes} <= {"accepted", "rejected", "no_fix", "predicted", "searching",
                                                       "skipped", "odom_only"}
    assert any(f["status"] == "accepted" for f in fixes)
    assert all(f["reason"] for f in fixes if f["status"] != "accepted")
    health = [m.message for m in session.by_topic(ch.HEALTH)]
    assert health and health[-1]["sources"]["scan"]["count"] > 0 and "view" in health[-1]
    # run.mcap holds the same channels with the same schemas (next to the ROS topics)
    from mcap.reader import make_reader

    with (out / "run.mcap").open("rb") as f:
        summ = make_reader(f).get_summary()
    in_file = {c.topic: summ.schemas[c.schema_id] for c in summ.channels.values()}
    for topic, c in adv.items():
        if topic in (ch.FIX_REJECTED, ch.PARTICLES):  # none in this run
            continue
        assert in_file[topic].name == c["schemaName"] and in_file[topic].encoding == c["schemaEncoding"]
    assert "/scan" in in_file and "/fused_pose" in in_file


def test_ctrl_c_stops_the_run_and_its_server_cleanly(short_dir, tmp_path):
    """SIGINT while a viewer is connected: exit 0 or 130, no traceback, the port free again."""
    port = free_port()
    # SIGINT at its default in the child even when this test runs with it ignored (a background job
    # of a non-interactive shell): a Python started with SIGINT ignored never raises KeyboardInterrupt
    proc = subprocess.Popen(_run_args(short_dir, tmp_path / "out", port, realtime=0.5), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=_env(),
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        session = asyncio.run(watch(f"ws://127.0.0.1:{port}", {ch.SCAN}, until=lambda s: len(s.messages) >= 2,
                                    connect_timeout_s=60, max_s=60))
        assert len(session.messages) >= 2  # it is running and serving
        t0 = time.monotonic()
        proc.send_signal(signal.SIGINT)
        _, stderr = proc.communicate(timeout=30)
        stop_s = time.monotonic() - t0
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode in (0, 130), stderr
    assert "Traceback" not in stderr
    assert stop_s < 15
    with socket.socket() as s:  # the server (its own process too) is gone: the port binds again
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        s.bind(("127.0.0.1", port))


def test_port_in_use_is_a_one_line_error(short_dir, tmp_path, capsys):
    from fgloc.cli import main

    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        code = main(["run", str(short_dir / "log.mcap"), "--map", str(short_dir / "map.yaml"), "-o",
                     str(tmp_path / "out"), "-q", "--view", str(port)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1
    assert err[0].startswith(f"fgloc: error: --view 127.0.0.1:{port}: cannot serve the Foxglove view:")
    assert "in use" in err[0]


def test_view_without_foxglove_sdk_is_a_one_line_hint(short_dir, tmp_path, capsys, monkeypatch):
    from fgloc.cli import main

    monkeypatch.setitem(sys.modules, "foxglove", None)  # as if foxglove-sdk were not installed
    code = main(["run", str(short_dir / "log.mcap"), "--map", str(short_dir / "map.yaml"), "-o",
                 str(tmp_path / "out"), "-q", "--view", "127.0.0.1:0"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert err == ['fgloc: error: the Foxglove view needs foxglove-sdk: pip install "fgloc[view]"']


@pytest.mark.parametrize("bad", ["http", "1.2.3.4:", "70000", "::1:8765", "[::1]8765"])
def test_bad_view_address_is_a_one_line_error(bad, short_dir, tmp_path, capsys):
    from fgloc.cli import main

    code = main(["run", str(short_dir / "log.mcap"), "-o", str(tmp_path / "out"), "-q", "--view", bad])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("fgloc: error: --view")
