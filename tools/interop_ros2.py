"""fgloc beside a real ROS 2 node: rclpy on rmw_fastrtps_cpp (eProsima Fast DDS), in another process.

ROS 2 itself is not installed here, but its Python client library and the Fast DDS middleware come as
wheels (ROS 2 Kilted: ``pip install ros-rclpy ros-rmw-fastrtps-cpp ros-geometry-msgs ros-nav-msgs
ros-sensor-msgs ros-diagnostic-msgs`` in a virtual environment of its own; give its python with
``--ros-python``).  Three processes on the loopback interface, one DDS domain:

* a ROS 2 node (rclpy, ``rmw_fastrtps_cpp``) publishing the map on ``/map`` as nav2's map_server does
  (reliable, transient local), reading ``/amcl_pose`` and ``/fgloc/status``, and asking the ROS 2 graph
  what ``ros2 node list``, ``ros2 node info`` and ``ros2 topic info -v`` ask;
* ``fgloc live --ros2`` without ``--map`` (the map from that node);
* ``fgloc replay LOG --ros2`` publishing the sensors (a simulated hall run unless ``--log``).

It prints what the ROS 2 node saw: the nodes, fgloc's publishers and subscriptions by node, the
endpoints' QoS and type hashes as rmw reports them, and /amcl_pose against ``fgloc run``'s online.tum
at the same stamps.

    python tools/interop_ros2.py --ros-python ROSVENV/bin/python
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

NODE = r'''
import array, json, math, signal, sys, time
import rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy, DurabilityPolicy
from nav_msgs.msg import OccupancyGrid
from geometry_msgs.msg import PoseWithCovarianceStamped
from diagnostic_msgs.msg import DiagnosticArray

meta = json.load(open(sys.argv[1]))
cells = open(sys.argv[2], "rb").read()
out = sys.argv[3]
stop = [False]
signal.signal(signal.SIGTERM, lambda *a: stop.__setitem__(0, True))
from rclpy.signals import SignalHandlerOptions
rclpy.init(signal_handler_options=SignalHandlerOptions.NO)  # SIGTERM: this script's, to write its answer
signal.signal(signal.SIGTERM, lambda *a: stop.__setitem__(0, True))
node = Node("nav2_probe")
latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
m = OccupancyGrid()
m.header.frame_id = "map"
m.header.stamp = node.get_clock().now().to_msg()
m.info.resolution = meta["resolution"]
m.info.width, m.info.height = meta["width"], meta["height"]
m.info.origin.position.x, m.info.origin.position.y = meta["x"], meta["y"]
m.info.origin.orientation.w = 1.0
m.data = array.array("b", cells)
node.create_publisher(OccupancyGrid, "/map", latched).publish(m)
poses, status = [], []
def on_pose(p):
    q = p.pose.pose.orientation
    poses.append((p.header.stamp.sec + p.header.stamp.nanosec * 1e-9, p.pose.pose.position.x, p.pose.pose.position.y,
                  math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z)), p.header.frame_id))
node.create_subscription(PoseWithCovarianceStamped, "/amcl_pose",
                         on_pose, QoSProfile(depth=5000, reliability=ReliabilityPolicy.RELIABLE,
                                             durability=DurabilityPolicy.TRANSIENT_LOCAL))
node.create_subscription(DiagnosticArray, "/fgloc/status", lambda a: status.append(
    [(s.name, s.level, s.message) for s in a.status]), 10)
graph = {}
def ask():
    nodes = [list(n) for n in node.get_node_names_and_namespaces_with_enclaves()]
    g = {"nodes": nodes, "by_node": {}, "endpoints": {}}
    for name, ns, _ in nodes:
        if name.startswith("fgloc"):
            g["by_node"][name] = {
                "publishers": node.get_publisher_names_and_types_by_node(name, ns),
                "subscriptions": node.get_subscriber_names_and_types_by_node(name, ns)}
    for topic in ("/amcl_pose", "/tf", "/fgloc/status", "/scan", "/map", "/initialpose"):
        infos = [("pub", i) for i in node.get_publishers_info_by_topic(topic)] + \
                [("sub", i) for i in node.get_subscriptions_info_by_topic(topic)]
        g["endpoints"][topic] = [{"kind": k, "node": i.node_name, "type": i.topic_type,
                                  "type_hash": str(getattr(i, "topic_type_hash", "")),
                                  "reliability": i.qos_profile.reliability.name,
                                  "durability": i.qos_profile.durability.name} for k, i in infos]
    return g
while not stop[0]:
    rclpy.spin_once(node, timeout_sec=0.05)
    if poses and not graph:
        graph.update(ask())
json.dump({"poses": poses, "status": status[-1:], "status_messages": len(status), "graph": graph,
           "graph_at_end": ask()}, open(out, "w"), default=str)
rclpy.shutdown()
'''


def fgloc(*args: str) -> list[str]:
    return [sys.executable, "-m", "fgloc.cli", *args]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ros-python", required=True, help="a python with rclpy and rmw_fastrtps_cpp")
    ap.add_argument("--log", type=Path, help="a log (default: the paper hall simulated, 5 m)")
    ap.add_argument("--map", type=Path, help="its map (published by the ROS 2 node)")
    ap.add_argument("--initial-pose", nargs=3, type=float, default=(2.5, 3.0, 0.0))
    ap.add_argument("--domain", type=int, default=1 + os.getpid() % 100)
    a = ap.parse_args()
    from fgloc.maps import load_map

    tmp = Path(tempfile.mkdtemp(prefix="interop_ros2_"))
    if a.log is None:
        from fgloc.sim import run_scenario, write_sim

        write_sim(run_scenario({"name": "interop", "route": [[2.5, 3.0], [7.5, 3.0]]}, seed=0), tmp)
        log, map_yaml = tmp / "log.mcap", tmp / "map.yaml"
    else:
        log, map_yaml = a.log, a.map
    init = [str(v) for v in a.initial_pose]
    subprocess.run(fgloc("run", str(log), "--map", str(map_yaml), "--initial-pose", *init, "-o", str(tmp / "run")),
                   check=True, capture_output=True)
    occ = load_map(map_yaml)
    meta = {"resolution": float(occ.resolution), "width": occ.width, "height": occ.height,
            "x": float(occ.origin[0]), "y": float(occ.origin[1])}
    if abs(float(occ.origin[2])) > 1e-9:
        raise SystemExit("a map with a rotated origin: not handled here")
    (tmp / "map.json").write_text(json.dumps(meta))
    (tmp / "cells.bin").write_bytes(np.clip(occ.data, -1, 100).astype(np.int8).tobytes())
    env = dict(os.environ, ROS_DOMAIN_ID=str(a.domain), RMW_IMPLEMENTATION="rmw_fastrtps_cpp")
    ros = subprocess.Popen([a.ros_python, "-c", NODE, str(tmp / "map.json"), str(tmp / "cells.bin"),
                            str(tmp / "ros.json")], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    common = ["--domain", str(a.domain), "--interface", "lo"]
    live = subprocess.Popen(fgloc("live", "--ros2", *common, "--quiet", "--json", "--initial-pose", *init),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        rep = subprocess.run(fgloc("replay", str(log), "--ros2", *common, "--wait", "60", "--quiet"),
                             capture_output=True, text=True, timeout=600)
        print(rep.stdout.strip().splitlines()[0] if rep.stdout.strip() else rep.stderr[-500:])
        time.sleep(3.0)
    finally:
        live.send_signal(signal.SIGTERM)
        out, err = live.communicate(timeout=120)
        time.sleep(1.0)
        ros.send_signal(signal.SIGTERM)
        ros_out, ros_err = ros.communicate(timeout=60)
    if not (tmp / "ros.json").exists():
        print("the ROS 2 node wrote nothing:", ros_err[-2000:])
        return 1
    got = json.loads((tmp / "ros.json").read_text())
    report = json.loads(out) if out.strip().startswith("{") else {}
    events = [ln for ln in err.splitlines() if "map from" in ln or "localizing" in ln]
    print("fgloc live: " + ("; ".join(e.removeprefix("fgloc live: ") for e in events) or err[-500:]))
    g = got["graph_at_end"] if got["graph_at_end"].get("by_node") else got["graph"]
    print("nodes (ros2 node list):", ", ".join(f"{ns.rstrip('/')}/{n}" for n, ns, _ in g.get("nodes", [])))
    for name, ents in g.get("by_node", {}).items():
        print(f"ros2 node info /{name}: publishers " + ", ".join(t for t, _ in ents["publishers"])
              + "; subscriptions " + ", ".join(t for t, _ in ents["subscriptions"]))
    for topic, eps in got["graph"].get("endpoints", {}).items():
        for e in eps:
            if e["node"] != "nav2_probe":
                print(f"ros2 topic info -v {topic}: {e['kind']} node {e['node']} {e['type']} {e['reliability']} "
                      f"{e['durability']} {e['type_hash']}")
    from fgloc.io.tum import read_tum

    ref = read_tum(tmp / "run" / "online.tum")
    d = []
    for t, x, y, _, _frame in got["poses"]:
        k = int(np.searchsorted(ref.stamps, t - 1e-6))
        if k < len(ref.stamps) and abs(ref.stamps[k] - t) <= 1e-6:
            d.append(float(np.hypot(x - ref.poses[k, 0], y - ref.poses[k, 1])))
    frames = sorted({p[4] for p in got["poses"]})
    print(f"/amcl_pose read by the ROS 2 node: {len(got['poses'])} poses (frame {', '.join(frames) or '-'}), "
          f"{len(d)} at fgloc run's {len(ref.stamps)} online stamps"
          + (f", max {1e3 * max(d):.2f} mm, median {1e3 * float(np.median(d)):.2f} mm from them" if d else ""))
    print(f"/fgloc/status read by the ROS 2 node: {got['status_messages']} DiagnosticArray messages"
          + (f", last: {got['status'][-1][-1]}" if got["status"] else ""))
    probs = (report.get("ros2") or {}).get("problems") or []
    print("fgloc's DDS problems: " + ("; ".join(probs) or "none"))
    return 0 if d else 1


if __name__ == "__main__":
    sys.exit(main())
