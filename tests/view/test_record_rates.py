"""The view's channels in run.mcap at a bounded rate (issue 14): the scan thinned in log time, the
covariance drawn in the robot's frame (frame-locked) and re-drawn on a period or a change, the
light per-scan channels untouched; the drawn ellipse is the same as the live view's."""

from __future__ import annotations

import base64
import json
import math

import numpy as np
import pytest

from fgloc.localization import Localizer, Session
from fgloc.types import PoseFix
from fgloc.view import channels as ch

from .foxglove_ws import protobuf_class, stamp


def _decode(path):
    from mcap.reader import make_reader

    out: dict[str, list] = {}
    with path.open("rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            if channel.message_encoding == "protobuf":
                cls = protobuf_class(schema.name, base64.b64encode(schema.data).decode())
                out.setdefault(channel.topic, []).append(cls.FromString(message.data))
            else:
                out.setdefault(channel.topic, []).append(message.data)
    return out


def test_bounded_scan_and_covariance_channels(short_sim, tmp_path):
    pytest.importorskip("google.protobuf")
    from fgloc.view.hook import ViewHook

    loc = Localizer(short_sim.map, short_sim.laser_mount, backend="smoother", frontend="native",
                    initial_pose=short_sim.ground_truth.poses[0])
    path = tmp_path / "view.mcap"
    with ViewHook(loc, record_to=path) as hook:
        hook.recorder.scan_period_s = 0.5
        hook.recorder.covariance_period_s = 2.0
        Session(loc, sinks=[hook]).run(short_sim.messages)
    assert hook.errors == 0 and hook.recorder.errors == 0
    got = _decode(path)
    n_scans = len(short_sim.topic("/scan"))
    duration = float(short_sim.ground_truth.duration)
    scans = [stamp(m.timestamp) for m in got[ch.SCAN]]
    assert len(scans) <= duration / 0.5 + 2 < n_scans
    assert np.all(np.diff(scans) >= 0.5 - 1e-6)
    assert len(got[ch.FIX]) == n_scans and len(got[ch.TF]) == n_scans  # the light channels: every scan
    covs = got[ch.POSE_COVARIANCE]
    assert 1 <= len(covs) <= duration / 2.0 + 5
    for upd in covs:
        (ent,) = upd.entities
        assert ent.frame_id == "base_link" and ent.frame_locked  # carried along with the robot by /fgloc/tf
        assert len(ent.lines) == 2


def test_body_frame_covariance_is_the_same_ellipse():
    """Drawn in base_link and placed by the robot's pose, the ellipse is the live view's map-frame one."""
    from fgloc.view import encode
    from fgloc.view.record import body_covariance_scene

    yaw = math.radians(35.0)
    cov = np.array([[4e-4, 1e-4, 0.0], [1e-4, 1e-4, 0.0], [0.0, 0.0, 3e-4]])
    fused = PoseFix(1.0, np.array([2.0, -1.0, yaw]), cov, frame_id="map")
    pytest.importorskip("google.protobuf")
    from foxglove import messages as fm

    cls = protobuf_class("foxglove.SceneUpdate", base64.b64encode(fm.SceneUpdate.get_schema().data).decode())
    body = cls.FromString(body_covariance_scene(fused).encode()).entities[0]
    world = cls.FromString(encode.covariance_scene(fused).encode()).entities[0]
    c, s = math.cos(yaw), math.sin(yaw)
    for line_b, line_w in zip(body.lines, world.lines, strict=True):
        pb = np.array([[p.x, p.y] for p in line_b.points])
        pw = np.array([[p.x, p.y] for p in line_w.points])
        placed = pb @ np.array([[c, s], [-s, c]]) + fused.pose[:2]  # base_link -> map
        assert len(pb) == len(pw)
        assert np.allclose(np.sort(placed, axis=0), np.sort(pw, axis=0), atol=1e-9)


def test_unmatched_scans_recorded_at_a_bounded_rate(short_sim, tmp_path):
    """predicted_period_s: every matched scan keeps its pose / tf / fix; the odometry-predicted
    scans between (frontend_every) are recorded at most that often in log time."""
    pytest.importorskip("google.protobuf")
    import json

    from fgloc.view.feed import PREDICTED
    from fgloc.view.hook import ViewHook

    def record(period_s, name):
        loc = Localizer(short_sim.map, short_sim.laser_mount, backend="smoother", frontend="native",
                        initial_pose=short_sim.ground_truth.poses[0])
        with ViewHook(loc, record_to=tmp_path / name) as hook:
            hook.recorder.predicted_period_s = period_s
            Session(loc, sinks=[hook]).run(short_sim.messages)
        assert hook.errors == 0 and hook.recorder.errors == 0
        return [json.loads(d) for d in _decode(tmp_path / name)[ch.FIX]]

    every = record(0.0, "every.mcap")
    bounded = record(0.5, "bounded.mcap")
    matched = [f["stamp"] for f in every if f["status"] != PREDICTED]
    predicted_all = [f["stamp"] for f in every if f["status"] == PREDICTED]
    assert len(every) == len(short_sim.topic("/scan")) and len(predicted_all) > 0
    assert [f["stamp"] for f in bounded if f["status"] != PREDICTED] == matched  # no matched scan dropped
    kept = [f["stamp"] for f in bounded if f["status"] == PREDICTED]
    assert len(kept) < len(predicted_all)  # (matched scans come more often than 0.5 s here: none kept)
    stamps = sorted(f["stamp"] for f in bounded)
    for s in kept:  # a predicted scan is kept only 0.5 s after the previous recorded scan
        prev = [t for t in stamps if t < s]
        assert not prev or s - prev[-1] >= 0.5 - 1e-6


class _RawOnly:
    """A writer with ``write_raw`` only (no ``raw_writer``): every message as given."""

    def __init__(self) -> None:
        self.messages: list[tuple] = []

    def write_raw(self, topic, schema_name, schema_data, data, log_time_ns, schema_encoding="", message_encoding=""):
        self.messages.append((topic, schema_name, bytes(schema_data), schema_encoding, message_encoding, data,
                              log_time_ns))


class _WithRawWriter(_RawOnly):
    """The same, through ``raw_writer(topic, ...)`` (as fgloc's LogWriter offers)."""

    def raw_writer(self, topic, schema_name, schema_data, schema_encoding, message_encoding):
        def write(data, log_time_ns):
            self.messages.append((topic, schema_name, bytes(schema_data), schema_encoding, message_encoding, data,
                                  log_time_ns))
        return write


def test_recorder_writes_the_same_through_write_raw_and_raw_writer(short_sim):
    pytest.importorskip("foxglove")
    from fgloc.view.feed import ViewFeed
    from fgloc.view.record import McapViewRecorder

    got = []
    for writer in (_RawOnly(), _WithRawWriter()):
        loc = Localizer(short_sim.map, short_sim.laser_mount, backend="smoother", frontend="native",
                        initial_pose=short_sim.ground_truth.poses[0])
        rec = McapViewRecorder(writer, covariance_period_s=1.0)
        feed = ViewFeed(loc, [rec])
        Session(loc, sinks=[feed]).run(short_sim.messages)
        feed.close()
        assert rec.errors == 0 and rec.count == len(writer.messages)
        got.append(writer.messages)
    assert got[0] == got[1]
    topics = {m[0] for m in got[0]}
    assert {ch.MAP, ch.SCAN, ch.TF, ch.POSE, ch.FUSED, ch.FIX, ch.HEALTH, ch.POSE_COVARIANCE} <= topics
    fused = [json.loads(m[5]) for m in got[0] if m[0] == ch.FUSED]
    assert fused and all(len(f["cov"]) == 9 and f["sigma_x_m"] > 0 for f in fused)
    ns = [m[6] for m in got[0]]
    assert ns == sorted(ns)  # no clock: each scan's messages at its stamp, the stamps in order
