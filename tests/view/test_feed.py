"""The view's pieces without a network: the feed, pacing, addresses, the layout, the MCAP channels."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from fgloc.errors import ConfigError
from fgloc.geometry import compose
from fgloc.localization import Localizer, Session
from fgloc.view import channels as ch
from fgloc.view.feed import ACCEPTED, NO_FIX, PREDICTED, REJECTED, TrajectoryDecimator, ViewFeed, json_ready
from fgloc.view.pace import check_rate, paced
from fgloc.view.server import parse_view_address

REPO = Path(__file__).resolve().parents[2]


class Collect:
    """A view sink that keeps everything it is given."""

    def __init__(self) -> None:
        self.maps: list = []
        self.scans: list = []
        self.particles: list = []
        self.trajectories: list = []
        self.health: list = []
        self.closed = 0

    def on_map(self, occ_map, stamp):
        self.maps.append(occ_map)

    def on_scan(self, view):
        self.scans.append(view)

    def on_particles(self, stamp, frame_id, poses):
        self.particles.append((stamp, frame_id, poses))

    def on_trajectory(self, stamp, frame_id, poses):
        self.trajectories.append((stamp, frame_id, poses))

    def on_health(self, stamp, health):
        self.health.append(health)

    def close(self):
        self.closed += 1


def _run(sim, frontend="native", config=None, backend="smoother", **kw):
    loc = Localizer(sim.map, sim.laser_mount, backend=backend, frontend=frontend,
                    initial_pose=sim.ground_truth.poses[0], config=config)
    sink = Collect()
    feed = ViewFeed(loc, [sink], **kw)
    final = Session(loc, sinks=[feed]).run(sim.messages)
    return loc, sink, final


def test_feed_shows_every_scan_with_status_transforms_and_health(short_sim):
    loc, sink, _ = _run(short_sim)
    n_scans = len(short_sim.topic("/scan"))
    assert len(sink.maps) == 1 and sink.maps[0] is short_sim.map
    assert len(sink.scans) == n_scans and sink.closed == 1
    status = [v.status for v in sink.scans]
    # the counts the localizer keeps, scan by scan
    assert status.count(ACCEPTED) + status.count(REJECTED) == loc.stats["fixes"]
    assert status.count(REJECTED) == loc.stats["rejected"]
    assert status.count(NO_FIX) == loc.stats["no_fix"]
    assert status.count(PREDICTED) > 0  # frontend_every: every other scan is not matched
    for v in sink.scans:
        if v.status in (ACCEPTED, REJECTED):
            assert v.fix is not None and v.fix.stamp == v.stamp
        else:
            assert v.fix is None and v.reason
        if v.fused is None:
            continue
        frames = [(t.parent, t.child) for t in v.transforms]
        assert frames[-1] == ("base_link", "laser")
        assert np.allclose(v.transforms[-1].pose, short_sim.laser_mount.pose)
        if frames[0] == ("map", "odom"):  # map->odom (+) odom->base_link is the fused pose
            via = compose(v.transforms[0].pose, v.transforms[1].pose)
            assert np.allclose(via[:2], v.fused.pose[:2], atol=1e-9)
            assert math.remainder(via[2] - v.fused.pose[2], 2 * math.pi) == pytest.approx(0.0, abs=1e-9)
    # odom -> base_link is the odometry's own pose (the sim's /odom carries one)
    odom = short_sim.topic("/odom")
    last = sink.scans[-1]
    o = [t for t in last.transforms if t.child == "base_link"][0]
    before = [m for m in odom if m.stamp <= last.fused.stamp][-1]
    assert np.hypot(*(o.pose[:2] - before.pose[:2])) < 0.05  # carried on by <= one odometry period
    # health once a second of log time: rates of the simulated sensors
    assert len(sink.health) >= 9
    h = sink.health[-2]
    assert h["sources"]["scan"]["rate_hz"] == pytest.approx(10.0, rel=0.25)
    assert h["sources"]["odom"]["rate_hz"] == pytest.approx(50.0, rel=0.1)
    assert h["sources"]["imu"]["rate_hz"] == pytest.approx(20.0, rel=0.15)
    assert sink.health[-1]["sources"]["scan"]["fixes"] == loc.stats["fixes"]
    assert json.loads(json.dumps(sink.health[-1])) == sink.health[-1]  # plain JSON
    # the trajectory so far, growing, in the map frame
    sizes = [len(p) for _, _, p in sink.trajectories]
    assert sizes == sorted(sizes) and sizes[-1] > 10 and sink.trajectories[-1][1] == "map"
    assert not sink.particles  # native: no particle cloud


@pytest.mark.parametrize("backend", ["smoother", "ekf"])
def test_health_shows_the_backends_estimates(short_sim, backend):
    """The health panel's ``estimates`` are what the back-end estimated (Backend.estimates): the
    compass offset, the odometry's scales, the gyro's bias and the scans' latency, near the
    simulation's truth (offset -23.9 deg, gyro bias 0.002 rad/s, exact wheels, no scan delay)."""
    loc, sink, _ = _run(short_sim, backend=backend)
    est = sink.health[-1]["estimates"]
    assert set(est) == {"compass_offset_rad", "odom_speed_scale", "odom_yaw_rate_scale", "gyro_bias_radps",
                        "latency_s", "latency_estimate_s", "latency_sigma_s"}
    assert math.degrees(abs(est["compass_offset_rad"] - short_sim.compass_offset_rad)) < 1.0
    assert est["odom_speed_scale"] == pytest.approx(1.0, abs=0.05)
    assert est["odom_yaw_rate_scale"] == pytest.approx(1.0, abs=0.05)
    assert set(est["gyro_bias_radps"]) == {"imu"}
    assert est["gyro_bias_radps"]["imu"] == pytest.approx(0.002, abs=0.002)
    assert est["latency_s"] == 0.0 and abs(est["latency_estimate_s"]) < 0.01
    # early on, nothing is estimated yet but the compass offset's guess: only what is known is shown
    assert "latency_estimate_s" not in sink.health[0]["estimates"]


def test_feed_never_changes_the_localization(short_sim):
    loc_a = Localizer(short_sim.map, short_sim.laser_mount, backend="smoother", frontend="native",
                      initial_pose=short_sim.ground_truth.poses[0])
    from fgloc.localization import BaseSink

    final_a = Session(loc_a, sinks=[BaseSink()]).run(short_sim.messages)
    _, _, final_b = _run(short_sim)
    assert np.array_equal(final_a.poses, final_b.poses) and np.array_equal(final_a.stamps, final_b.stamps)


def test_amcl_particles_reach_the_view(short_sim):
    loc, sink, _ = _run(short_sim, frontend="amcl", max_particles=300)
    assert len(sink.particles) == len(sink.scans)
    stamp, frame, poses = sink.particles[-1]
    assert frame == "map" and poses.shape[1] == 3 and 0 < len(poses) <= 300
    # the cloud is around the fused pose
    fused = sink.scans[-1].fused.pose
    assert np.hypot(*(np.median(poses[:, :2], axis=0) - fused[:2])) < 0.5


def test_a_thinned_sink_gets_the_last_scan_at_close(short_sim):
    class Thinned(Collect):
        def wants_scan(self, status):
            return False

    loc = Localizer(short_sim.map, short_sim.laser_mount, backend="smoother", frontend="native",
                    initial_pose=short_sim.ground_truth.poses[0])
    thin, full = Thinned(), Collect()
    Session(loc, sinks=[ViewFeed(loc, [thin, full])]).run(short_sim.messages)
    assert len(full.scans) == len(short_sim.topic("/scan"))
    assert len(thin.scans) == 1 and thin.scans[0].stamp == full.scans[-1].stamp


def test_trajectory_decimator():
    d = TrajectoryDecimator(min_step_m=0.1, min_turn_rad=0.1, max_gap_s=1.0, period_s=1.0, poses_per_s=10.0)
    for i in range(100):
        d.add(i * 0.01, np.array([i * 0.01, 0.0, 0.0]))  # 1 cm steps: one pose per 10 cm
    assert len(d) == 10
    d.add(1.0, np.array([0.995, 0.0, 0.5]))  # a turn is kept
    assert len(d) == 11
    assert d.due(0.0) and not d.due(0.5) and d.due(1.1)  # once a second ...
    for i in range(100):
        d.add(2.0 + i, np.array([2.0 + i, 0.0, 0.0]))
    assert len(d) == 111
    assert not d.due(12.0) and d.due(12.2)  # ... or less often as it grows (111 / 10 per s)


def test_json_ready():
    v = json_ready({"a": np.float64(1.5), "b": np.int64(2), "c": [np.nan, math.inf], "d": np.arange(2),
                    3: (True, None)})
    assert v == {"a": 1.5, "b": 2, "c": [None, None], "d": [0, 1], "3": [True, None]}


@pytest.mark.parametrize("text, want", [
    ("8765", ("127.0.0.1", 8765)), ("0.0.0.0:9000", ("0.0.0.0", 9000)), ("localhost:1", ("localhost", 1)),
    ("[::1]:8765", ("::1", 8765)), (None, ("127.0.0.1", 8765)), ("0", ("127.0.0.1", 0)),
])
def test_view_address(text, want):
    assert parse_view_address(text) == want


@pytest.mark.parametrize("text", ["x", "host:", ":80", "65536", "::1:80", "[::1]", "1.2.3.4:-1"])
def test_bad_view_address(text):
    with pytest.raises(ConfigError, match="--view"):
        parse_view_address(text)


def test_paced_replay_follows_the_log_clock():
    class M:
        def __init__(self, stamp):
            self.stamp = stamp

    now = [100.0]
    slept: list[float] = []

    def sleep(dt):
        slept.append(dt)
        now[0] += dt

    msgs = [("/tf_static", [1]), ("/a", M(5.0)), ("/b", M(5.5)), ("/a", M(7.0)), ("/b", M(6.0))]
    seen = []
    for topic, _msg in paced(msgs, 2.0, clock=lambda: now[0], sleep=sleep):
        seen.append((topic, now[0]))
    # at 2x: 5.5 s -> +0.25 s, 7.0 s -> +1.0 s; a stamp going back is passed on at once
    assert [t for t, _ in seen] == ["/tf_static", "/a", "/b", "/a", "/b"]
    assert [round(w - 100.0, 6) for _, w in seen] == [0.0, 0.0, 0.25, 1.0, 1.0]
    assert all(s <= 0.5 for s in slept)  # in slices: Ctrl-C stays prompt
    assert list(paced(msgs, None)) == msgs
    assert check_rate(None) is None and check_rate(0.5) == 0.5
    for bad in (0.0, -1.0, math.nan, math.inf):
        with pytest.raises(ConfigError, match="--realtime"):
            check_rate(bad)


def test_saved_layout_is_the_generated_one_and_names_real_channels():
    from fgloc.view.layout import layout_dict, layout_json

    saved = (REPO / "docs" / "foxglove" / "fgloc-layout.json").read_text()
    assert saved == layout_json(), "docs/foxglove/fgloc-layout.json is stale: fgloc view layout -o it"
    lay = layout_dict()
    three_d = next(v for k, v in lay["configById"].items() if k.startswith("3D!"))
    topics = {c.topic for c in ch.CHANNELS}
    assert set(three_d["topics"]) <= topics
    assert {ch.MAP, ch.SCAN, ch.POSE, ch.POSE_COVARIANCE, ch.FIX_ACCEPTED, ch.FIX_REJECTED, ch.PARTICLES,
            ch.TRAJECTORY} <= set(three_d["topics"])
    assert three_d["fixedFrame"] == "map"
    for k, cfg in lay["configById"].items():  # plots and raw messages name view channels
        for path in [p["value"] for p in cfg.get("paths", [])] + [cfg.get("topicPath", "")]:
            if path:
                assert path.split(".")[0] in topics, (k, path)
    ids: list[str] = []

    def leaves(node):
        if isinstance(node, str):
            ids.append(node)
        else:
            leaves(node["first"])
            leaves(node["second"])

    leaves(lay["layout"])
    assert sorted(ids) == sorted(lay["configById"])  # every panel placed once


def test_view_channels_in_an_mcap_decode_with_their_schemas(short_sim, tmp_path):
    """The recorder's file: every channel with its Foxglove (protobuf) or JSON schema,
    decodable from the schema stored in the file; the map and the poses as the run's."""
    pytest.importorskip("google.protobuf")
    import base64

    from mcap.reader import make_reader

    from fgloc.view.hook import ViewHook

    from .foxglove_ws import protobuf_class, stamp

    loc = Localizer(short_sim.map, short_sim.laser_mount, backend="smoother", frontend="native",
                    initial_pose=short_sim.ground_truth.poses[0])
    path = tmp_path / "view.mcap"
    with ViewHook(loc, record_to=path) as hook:
        Session(loc, sinks=[hook]).run(short_sim.messages)
    assert hook.errors == 0 and hook.recorder.errors == 0
    online = loc.online_trajectory()
    with path.open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        topics = {c.topic: c for c in summary.channels.values()}
        assert set(topics) == {c.topic for c in ch.CHANNELS} - {ch.FIX_REJECTED, ch.PARTICLES}
        decoded: dict[str, list] = {}
        for schema, channel, message in reader.iter_messages():
            if channel.message_encoding == "protobuf":
                cls = protobuf_class(schema.name, base64.b64encode(schema.data).decode())
                decoded.setdefault(channel.topic, []).append(cls.FromString(message.data))
            else:
                assert channel.message_encoding == "json" and schema.encoding == "jsonschema"
                decoded.setdefault(channel.topic, []).append(json.loads(message.data))
    n_scans = len(short_sim.topic("/scan"))
    assert len(decoded[ch.SCAN]) == n_scans and len(decoded[ch.FIX]) == n_scans  # nothing thinned
    grid = decoded[ch.MAP][0]
    assert grid.column_count == short_sim.map.width and grid.cell_size.x == pytest.approx(short_sim.map.resolution)
    assert len(grid.data) == grid.row_stride * short_sim.map.height
    for p in decoded[ch.POSE]:
        q = online.interpolate(stamp(p.timestamp))[0]
        assert np.hypot(p.pose.position.x - q[0], p.pose.position.y - q[1]) < 0.005


class Eager(Collect):
    """A view sink that reads each scan's transforms when it is given the scan."""

    def on_scan(self, view):
        self.scans.append([(t.parent, t.child, np.array(t.pose), t.z) for t in view.transforms])


def test_transforms_read_later_are_those_of_their_scan(short_sim):
    # the feed makes a scan's transforms when a sink first reads them (the recorder skips most
    # unmatched scans): read after the run, from the odometry of their scan, not the last one
    import pickle

    loc = Localizer(short_sim.map, short_sim.laser_mount, backend="smoother", frontend="native",
                    initial_pose=short_sim.ground_truth.poses[0])
    late, eager = Collect(), Eager()
    Session(loc, sinks=[ViewFeed(loc, [late]), ViewFeed(loc, [eager])]).run(short_sim.messages)
    assert len(late.scans) == len(eager.scans) > 50
    moved = 0
    for v, now in zip(late.scans, eager.scans, strict=True):
        then = [(t.parent, t.child, t.pose, t.z) for t in v.transforms]
        assert [f[:2] for f in then] == [f[:2] for f in now] and [f[3] for f in then] == [f[3] for f in now]
        assert all(np.array_equal(a[2], b[2]) for a, b in zip(then, now, strict=True))
        moved += not np.array_equal(then[0][2], late.scans[-1].transforms[0].pose)
    assert moved > 50  # the scans' transforms differ from the last scan's
    v = pickle.loads(pickle.dumps(late.scans[len(late.scans) // 2]))
    assert [(t.parent, t.child) for t in v.transforms] == [f[:2] for f in eager.scans[len(eager.scans) // 2]]
    assert np.array_equal(v.transforms[0].pose, eager.scans[len(eager.scans) // 2][0][2])
