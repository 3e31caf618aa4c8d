"""A log's own map (nav_msgs/OccupancyGrid on /map, as nav2 / SLAM recordings and ROS 1 bags with
map_server's latched map carry it): ``fgloc info`` names it, ``fgloc export LOG:/map -o map.yaml``
writes its last message as a map_server map that ``fgloc run --map`` loads."""

from __future__ import annotations

import numpy as np
import pytest

from fgloc.maps import FREE, OCCUPIED, UNKNOWN, OccupancyMap, load_map
from fgloc.testing.cli import run_cli as cli
from fgloc.types import Odometry

T0 = 1_700_000_000



def one_error(err: str) -> str:
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    assert "Traceback" not in err and len(lines) == 1 and lines[0].startswith("fgloc: error: "), err
    return lines[0]


def room(w: int = 60, h: int = 40, walls: bool = True) -> OccupancyMap:
    """A w x h room at 0.05 m: walls on the border, unknown outside a 2-cell margin, free inside."""
    data = np.full((h, w), UNKNOWN, dtype=np.int16)
    data[2:-2, 2:-2] = OCCUPIED if walls else FREE
    data[3:-3, 3:-3] = FREE
    data[10:14, 30:33] = OCCUPIED  # a pillar, off-centre: the map is not symmetric
    return OccupancyMap(data, 0.05, np.array([-1.5, -0.75, 0.0]), mode="trinary")


def write_mcap(path, maps: list[OccupancyMap]) -> None:
    from fgloc.io.mcap_writer import LogWriter
    from fgloc.io.msgdefs import full_text
    from fgloc.ros2.codec import OCCUPANCY_GRID, encode_map

    with LogWriter(path) as w:
        for k in range(20):
            w.write("/odom", Odometry(stamp=T0 + 0.1 * k, twist=np.zeros(3), pose=np.zeros(3)))
        for k, m in enumerate(maps):  # a SLAM node republishing its growing map
            t = T0 + 0.5 + k
            w.write_raw("/map", OCCUPANCY_GRID, full_text(OCCUPANCY_GRID).encode(), encode_map(m, t), int(t * 1e9))


def write_ros1_bag(path, m: OccupancyMap) -> None:
    """A ROS 1 bag with map_server's latched /map (ROS 1 serialization) and some odometry."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    T = ts.types
    Time, Header = T["builtin_interfaces/msg/Time"], T["std_msgs/msg/Header"]
    Pose, Point, Q = T["geometry_msgs/msg/Pose"], T["geometry_msgs/msg/Point"], T["geometry_msgs/msg/Quaternion"]
    grid = T["nav_msgs/msg/OccupancyGrid"](
        header=Header(seq=0, stamp=Time(sec=T0, nanosec=0), frame_id="map"),
        info=T["nav_msgs/msg/MapMetaData"](
            map_load_time=Time(sec=T0, nanosec=0), resolution=np.float32(m.resolution), width=m.width,
            height=m.height, origin=Pose(position=Point(x=float(m.origin[0]), y=float(m.origin[1]), z=0.0),
                                         orientation=Q(x=0.0, y=0.0, z=0.0, w=1.0))),
        data=np.asarray(m.data, dtype=np.int8).ravel())
    with Writer(path) as w:
        c = w.add_connection("/map", "nav_msgs/msg/OccupancyGrid", typestore=ts, latching=1)
        w.write(c, T0 * 10**9, ts.serialize_ros1(grid, grid.__msgtype__))


def assert_same_map(got: OccupancyMap, want: OccupancyMap) -> None:
    assert got.data.shape == want.data.shape
    assert np.array_equal(got.occupied, want.occupied)
    assert np.array_equal(got.free, want.free)
    assert np.array_equal(got.unknown, want.unknown)
    assert got.resolution == pytest.approx(want.resolution)
    assert np.allclose(got.origin, want.origin)


def test_export_writes_the_last_map_of_the_topic_as_a_map_server_map(tmp_path):
    log = tmp_path / "rec.mcap"
    first, final = room(walls=False), room()
    write_mcap(log, [first, final])
    rc, out, err = cli("export", f"{log}:/map", "-o", tmp_path / "maps" / "lab.yaml")
    assert rc == 0, err
    assert "the last of 2 message(s)" in out and "60 x 40 cells at 0.05 m" in out
    assert (tmp_path / "maps" / "lab.pgm").is_file()
    got = load_map(tmp_path / "maps" / "lab.yaml")
    assert_same_map(got, final)
    assert not np.array_equal(got.occupied, first.occupied)
    # without a topic: the log's only map topic, chosen by the YAML output
    rc, out, err = cli("export", log, "-o", tmp_path / "only.yaml")
    assert rc == 0, err
    assert_same_map(load_map(tmp_path / "only.yaml"), final)


def test_info_names_the_map_and_how_to_export_it(tmp_path):
    log = tmp_path / "rec.mcap"
    write_mcap(log, [room()])
    rc, out, err = cli("info", log)
    assert rc == 0, err
    assert f"map: /map carries a map; as a map_server map: fgloc export {log}:/map -o map.yaml" in out


def test_a_ros1_bags_latched_map_exports_the_same(tmp_path):
    bag = tmp_path / "nav.bag"
    m = room()
    write_ros1_bag(bag, m)
    rc, out, err = cli("export", f"{bag}:/map", "-o", tmp_path / "map.yaml")
    assert rc == 0, err
    assert "the last of 1 message(s)" in out
    assert_same_map(load_map(tmp_path / "map.yaml"), m)


def test_wrong_outputs_and_topics_are_one_line_errors(tmp_path):
    log = tmp_path / "rec.mcap"
    write_mcap(log, [room()])
    rc, _, err = cli("export", f"{log}:/map", "-o", tmp_path / "map.tum")
    assert rc == 2
    assert one_error(err).endswith("/map: a map (nav_msgs/OccupancyGrid): write it as a map_server map, -o map.yaml")
    assert not (tmp_path / "map.tum").exists()
    rc, _, err = cli("export", f"{log}:/odom", "-o", tmp_path / "odom.yaml")
    assert rc == 2
    assert one_error(err).endswith("/odom is nav_msgs/msg/Odometry, not nav_msgs/OccupancyGrid (its map topics: /map)")
    rc, _, err = cli("export", f"{log}:/nope", "-o", tmp_path / "x.yaml")
    assert rc == 2 and one_error(err).endswith(": no topic /nope (its map topics: /map)")


def test_an_existing_map_is_not_overwritten_without_force(tmp_path):
    log = tmp_path / "rec.mcap"
    write_mcap(log, [room()])
    (tmp_path / "map.pgm").write_bytes(b"someone else's image")
    rc, _, err = cli("export", f"{log}:/map", "-o", tmp_path / "map.yaml")
    assert rc == 2 and "map.pgm" in one_error(err) and "--force" in err
    assert not (tmp_path / "map.yaml").exists()
    assert (tmp_path / "map.pgm").read_bytes() == b"someone else's image"
    rc, _, err = cli("export", f"{log}:/map", "-o", tmp_path / "map.yaml", "--force")
    assert rc == 0, err
    assert_same_map(load_map(tmp_path / "map.yaml"), room())


def test_a_map_topic_without_messages_says_so(tmp_path):
    """A recording stopped before the map was published (IR2121's loose .db3 files: /map 0 messages)."""
    from fgloc.io.mcap_writer import LogWriter
    from fgloc.io.msgdefs import full_text
    from fgloc.ros2.codec import OCCUPANCY_GRID

    log = tmp_path / "early.mcap"
    with LogWriter(log) as w:
        w.raw_writer("/map", OCCUPANCY_GRID, full_text(OCCUPANCY_GRID).encode())  # the channel only
        for k in range(5):
            w.write("/odom", Odometry(stamp=T0 + 0.1 * k, twist=np.zeros(3), pose=np.zeros(3)))
    rc, _, err = cli("export", f"{log}:/map", "-o", tmp_path / "map.yaml")
    assert rc == 2
    assert one_error(err).endswith(": /map has no messages (the recording holds its type only; its map topics: none)")
    rc, _, err = cli("export", log, "-o", tmp_path / "map.yaml")
    assert rc == 2 and one_error(err).endswith(": no nav_msgs/OccupancyGrid topic with messages to read a map from")
    assert not (tmp_path / "map.yaml").exists() and not (tmp_path / "map.pgm").exists()


def test_a_run_without_map_names_the_logs_own_map(tmp_path):
    """A SLAM or nav2 log's /map is not used without --map: the run says so and how to use it."""
    log = tmp_path / "slam.mcap"
    write_mcap(log, [room()])
    rc, out, err = cli("run", log, "-o", tmp_path / "o", "-q")
    assert rc == 0, err
    assert (f"warning: the log's own map on /map was not used (no --map): fgloc export {log}:/map -o map.yaml, "
            f"then fgloc run {log} --map map.yaml") in out + err
    rc, out, err = cli("export", f"{log}:/map", "-o", tmp_path / "map.yaml")
    assert rc == 0, err
    rc, out, err = cli("run", log, "--map", tmp_path / "map.yaml", "--initial-pose", "1", "1", "0",
                       "-o", tmp_path / "m", "-q", "--allow-lost")
    assert "own map" not in out + err
