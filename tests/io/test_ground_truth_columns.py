"""``McapSource.ground_truth`` read as columns equals the message-by-message reading bit for bit.

The column reading (no Odometry objects, ``fgloc run``'s evaluation of a simulated log) must give
the trajectory :meth:`fgloc.io.source.LogSource.ground_truth` gives: the same stamps and poses,
bit for bit, in the same order (duplicate stamps keep the last), messages without a pose (REP 145)
left out, and a layout the fixed decoders decline read the generic way.
"""

from __future__ import annotations

import numpy as np

from fgloc.io import fastcdr, open_log
from fgloc.io.mcap_writer import LogWriter
from fgloc.io.source import LogSource
from fgloc.types import Odometry


def _same(a, b) -> None:
    assert a is not None and b is not None
    assert a.stamps.tobytes() == b.stamps.tobytes()
    assert a.poses.tobytes() == b.poses.tobytes()
    assert a.frame_id == b.frame_id


def _gt_log(path, n: int = 700, every_absent: int = 7, dup_every: int = 50, child: str = "base_link") -> None:
    """A log of /ground_truth odometry in several chunks: some messages without a pose, some
    stamps repeated (later message, other pose), yaws all round the circle."""
    rng = np.random.default_rng(3)
    with LogWriter(path, chunk_size=16 * 1024) as w:
        for i in range(n):
            stamp = 10.0 + 0.01 * (i - (i % dup_every == 1))  # message i repeats i-1's stamp
            pose = None if i % every_absent == 3 else np.array([rng.normal(), rng.normal(), rng.uniform(-3.2, 3.2)])
            w.write("/ground_truth", Odometry(stamp, np.zeros(3), None, pose, None, "map", child))
            w.write("/odom", Odometry(stamp, np.array([0.1, 0.0, 0.0])))


def test_columns_equal_message_by_message(tmp_path) -> None:
    _gt_log(tmp_path / "a.mcap")
    src = open_log(tmp_path / "a.mcap")
    assert src._ground_truth_columns() is not None  # the column path was taken
    fast, slow = src.ground_truth(), LogSource.ground_truth(src)
    _same(fast, slow)
    assert len(fast) == len({round(10.0 + 0.01 * (i - (i % 50 == 1)), 6) for i in range(700) if i % 7 != 3})


def test_simulated_log_columns_equal_message_by_message(tmp_path) -> None:
    from fgloc.sim import run_scenario, write_sim

    sim = run_scenario({"route": [[2.5, 3.0], [3.5, 3.0], [3.5, 4.0]], "laser": {"rate_hz": 10.0}}, seed=1)
    write_sim(sim, tmp_path / "log")
    src = open_log(tmp_path / "log" / "log.mcap")
    fast = src.ground_truth()
    _same(fast, LogSource.ground_truth(src))
    assert len(fast) > 100


def test_odd_frame_names_share_nothing_but_the_reading(tmp_path) -> None:
    # another child frame length moves the doubles: its own layout group inside each batch
    with LogWriter(tmp_path / "b.mcap", chunk_size=4096) as w:
        for i in range(300):
            pose = np.array([0.01 * i, -0.02 * i, 0.05 * i - 3.0])
            w.write("/ground_truth", Odometry(1.0 + 0.1 * i, np.zeros(3), None, pose, None, "map",
                                              "base_link" if i % 3 else "robot_footprint_xyz"))
    src = open_log(tmp_path / "b.mcap")
    _same(src.ground_truth(), LogSource.ground_truth(src))


def test_a_message_the_fixed_layout_declines_reads_the_generic_way(tmp_path, monkeypatch) -> None:
    _gt_log(tmp_path / "c.mcap", n=200)
    src = open_log(tmp_path / "c.mcap")
    slow = LogSource.ground_truth(src)
    real = fastcdr.decode_columns

    def decline_the_first(datas, strings, n_doubles):  # as for a big-endian or odd message
        got = real(datas, strings, n_doubles)
        if got is None:
            return None
        idx, texts, stamps, v = got
        return idx[1:], texts[1:], stamps[1:], v[1:]

    monkeypatch.setattr(fastcdr, "decode_columns", decline_the_first)
    assert fastcdr.odometry_stamped_poses([b"\x00\x01\x00\x00"]) is None
    assert src._ground_truth_columns() is None  # falls back to the message-by-message reading
    _same(src.ground_truth(), slow)


def test_no_ground_truth_is_none(tmp_path) -> None:
    with LogWriter(tmp_path / "d.mcap") as w:
        w.write("/odom", Odometry(1.0, np.zeros(3), None, np.zeros(3)))
    assert open_log(tmp_path / "d.mcap").ground_truth() is None
    with LogWriter(tmp_path / "e.mcap") as w:  # ground truth without a pose in any message
        w.write("/ground_truth", Odometry(1.0, np.zeros(3), None, None))
    src = open_log(tmp_path / "e.mcap")
    assert src.ground_truth() is None and LogSource.ground_truth(src) is None


def _records(src, want):
    return [(r.topic, r.log_time_ns, r.data) for r in src.records(want)]


def test_collected_on_the_way_through_the_log(tmp_path) -> None:
    """fgloc run's reading: the ground truth collected while records() reads the other topics, the
    same records handed on, the same trajectory, nothing read again."""
    _gt_log(tmp_path / "f.mcap")
    plain, src = open_log(tmp_path / "f.mcap"), open_log(tmp_path / "f.mcap")
    src.collect_ground_truth = True
    assert _records(src, {"/odom"}) == _records(plain, {"/odom"})
    assert src._gt_collected is not None
    src.path = tmp_path / "gone.mcap"  # ground_truth() must not open the file again
    _same(src.ground_truth(), LogSource.ground_truth(plain))


def test_an_interrupted_pass_collects_nothing(tmp_path) -> None:
    _gt_log(tmp_path / "g.mcap")
    src = open_log(tmp_path / "g.mcap")
    src.collect_ground_truth = True
    it = src.records({"/odom"})
    next(it)
    it.close()
    assert src._gt_collected is None
    _same(src.ground_truth(), LogSource.ground_truth(open_log(tmp_path / "g.mcap")))


def test_ground_truth_in_chunks_the_pass_skips_is_read_after_it(tmp_path) -> None:
    # the ground truth after all the odometry, in chunks of its own: the pass over /odom does not
    # read them (its chunks and order stay as they are), ground_truth() reads them afterwards
    with LogWriter(tmp_path / "h.mcap", chunk_size=2048) as w:
        for i in range(200):
            w.write("/odom", Odometry(1.0 + 0.01 * i, np.array([0.1, 0.0, 0.0])))
        for i in range(200):
            w.write("/ground_truth", Odometry(5.0 + 0.01 * i, np.zeros(3), None, np.array([0.1 * i, 0.0, 0.01 * i])))
    plain, src = open_log(tmp_path / "h.mcap"), open_log(tmp_path / "h.mcap")
    src.collect_ground_truth = True
    assert _records(src, {"/odom"}) == _records(plain, {"/odom"})
    assert src._gt_collected is None
    _same(src.ground_truth(), LogSource.ground_truth(plain))
