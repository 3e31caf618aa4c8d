"""A ROS 2 peer written for the tests with Cyclone DDS directly (not fgloc's code): the message types
typed out by hand from the ROS 2 ``.msg`` files, the names and QoS as a ROS 2 node's, so that what
fgloc publishes is read back by something that shares nothing with it but DDS.

(No ``from __future__ import annotations`` here: Cyclone DDS reads the field types at class creation.)"""


import math
import threading
import time
from dataclasses import dataclass

import cyclonedds.idl.types as t
from cyclonedds.core import Listener
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy, Qos
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic


@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: t.int32
    nanosec: t.uint32


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time
    frame_id: str


@dataclass
class Point(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
    x: t.float64
    y: t.float64
    z: t.float64


@dataclass
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: t.float64
    y: t.float64
    z: t.float64


@dataclass
class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: t.float64
    y: t.float64
    z: t.float64
    w: t.float64


@dataclass
class Pose(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
    position: Point
    orientation: Quaternion


@dataclass
class PoseWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::PoseWithCovariance_"):
    pose: Pose
    covariance: t.array[t.float64, 36]


@dataclass
class PoseWithCovarianceStamped(IdlStruct, typename="geometry_msgs::msg::dds_::PoseWithCovarianceStamped_"):
    header: Header
    pose: PoseWithCovariance


@dataclass
class Transform(IdlStruct, typename="geometry_msgs::msg::dds_::Transform_"):
    translation: Vector3
    rotation: Quaternion


@dataclass
class TransformStamped(IdlStruct, typename="geometry_msgs::msg::dds_::TransformStamped_"):
    header: Header
    child_frame_id: str
    transform: Transform


@dataclass
class TFMessage(IdlStruct, typename="tf2_msgs::msg::dds_::TFMessage_"):
    transforms: t.sequence[TransformStamped]


@dataclass
class KeyValue(IdlStruct, typename="diagnostic_msgs::msg::dds_::KeyValue_"):
    key: str
    value: str


@dataclass
class DiagnosticStatus(IdlStruct, typename="diagnostic_msgs::msg::dds_::DiagnosticStatus_"):
    level: t.uint8
    name: str
    message: str
    hardware_id: str
    values: t.sequence[KeyValue]


@dataclass
class DiagnosticArray(IdlStruct, typename="diagnostic_msgs::msg::dds_::DiagnosticArray_"):
    header: Header
    status: t.sequence[DiagnosticStatus]


@dataclass
class MapMetaData(IdlStruct, typename="nav_msgs::msg::dds_::MapMetaData_"):
    map_load_time: Time
    resolution: t.float32
    width: t.uint32
    height: t.uint32
    origin: Pose


@dataclass
class OccupancyGrid(IdlStruct, typename="nav_msgs::msg::dds_::OccupancyGrid_"):
    header: Header
    info: MapMetaData
    data: t.sequence[t.int8]


def yaw(q: Quaternion) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def stamp(h: Header) -> float:
    return h.stamp.sec + h.stamp.nanosec * 1e-9


def _qos(reliable: bool, transient_local: bool, depth: int) -> Qos:
    return Qos(Policy.Reliability.Reliable(0) if reliable else Policy.Reliability.BestEffort,
               Policy.Durability.TransientLocal if transient_local else Policy.Durability.Volatile,
               Policy.History.KeepLast(depth), Policy.DataRepresentation(use_cdrv0_representation=True))


class Peer:
    """Reads /amcl_pose (as nav2 consumers do: reliable, transient local), /tf and /fgloc/status;
    writes /initialpose as RViz does (reliable, volatile) and /map as map_server does (reliable,
    transient local, keep last 1)."""

    def __init__(self, domain: int, interface: str = "lo") -> None:
        xml = (f'<CycloneDDS><Domain id="any"><General><Interfaces><NetworkInterface name="{interface}"/>'
               '</Interfaces></General></Domain></CycloneDDS>')
        try:
            self.domain = Domain(domain, xml)  # kept: the participant's configuration lives with it
        except Exception:  # noqa: BLE001 - this process configured the domain already (on loopback)
            self.domain = None
        self.dp = DomainParticipant(domain)
        self.poses: list[tuple[float, float, float, float, str]] = []  # stamp, x, y, yaw, frame
        self.tfs: list[tuple[float, str, str, float, float, float]] = []  # stamp, parent, child, x, y, yaw
        self.status: list[DiagnosticArray] = []
        self._lock = threading.Lock()
        self._pose = DataReader(self.dp, Topic(self.dp, "rt/amcl_pose", PoseWithCovarianceStamped),
                                _qos(True, True, 5000))
        self._tf = DataReader(self.dp, Topic(self.dp, "rt/tf", TFMessage), _qos(True, False, 5000))
        self._status = DataReader(self.dp, Topic(self.dp, "rt/fgloc/status", DiagnosticArray), _qos(True, False, 100))
        self._init = DataWriter(self.dp, Topic(self.dp, "rt/initialpose", PoseWithCovarianceStamped),
                                _qos(True, False, 1), listener=Listener())
        self._map: DataWriter | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True)
        self._thread.start()

    def _loop(self) -> None:
        while not self._stop.is_set():
            for s in self._pose.take(500):
                if isinstance(s, PoseWithCovarianceStamped):
                    p = s.pose.pose
                    with self._lock:
                        self.poses.append((stamp(s.header), p.position.x, p.position.y, yaw(p.orientation),
                                           s.header.frame_id))
            for s in self._tf.take(500):
                if isinstance(s, TFMessage):
                    with self._lock:
                        for tr in s.transforms:
                            v = tr.transform.translation
                            self.tfs.append((stamp(tr.header), tr.header.frame_id, tr.child_frame_id, v.x, v.y,
                                             yaw(tr.transform.rotation)))
            for s in self._status.take(50):
                if isinstance(s, DiagnosticArray):
                    with self._lock:
                        self.status.append(s)
            time.sleep(0.01)

    def initial_pose(self, t: float, x: float, y: float, th: float, sigma_xy: float = 0.1,
                     sigma_yaw: float = 0.1) -> None:
        cov = [0.0] * 36
        cov[0] = cov[7] = sigma_xy ** 2
        cov[35] = sigma_yaw ** 2
        msg = PoseWithCovarianceStamped(
            Header(Time(int(math.floor(t)), int(round((t - math.floor(t)) * 1e9)) % 1_000_000_000), "map"),
            PoseWithCovariance(Pose(Point(x, y, 0.0), Quaternion(0.0, 0.0, math.sin(th / 2), math.cos(th / 2))), cov))
        self._init.write(msg)

    def publish_map(self, cells, width: int, height: int, resolution: float, x: float, y: float) -> None:
        """An OccupancyGrid: ``cells`` row-major from the origin (100 occupied, 0 free, -1 unknown)."""
        if self._map is None:
            self._map = DataWriter(self.dp, Topic(self.dp, "rt/map", OccupancyGrid), _qos(True, True, 1))
        now = time.time()
        st = Time(int(now), int((now % 1.0) * 1e9))
        info = MapMetaData(st, resolution, width, height,
                           Pose(Point(x, y, 0.0), Quaternion(0.0, 0.0, 0.0, 1.0)))
        self._map.write(OccupancyGrid(Header(st, "map"), info, [int(v) for v in cells]))

    def initial_pose_matched(self) -> bool:
        return len(self._init.get_matched_subscriptions()) > 0

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)


# ----------------------------------------------------------------------------- the ROS 2 graph
# rmw_dds_common/msg/{Gid,NodeEntitiesInfo,ParticipantEntitiesInfo}.msg (ROS 2 Iron and later)
@dataclass
class Gid(IdlStruct, typename="rmw_dds_common::msg::dds_::Gid_"):
    data: t.array[t.uint8, 16]  # char[16]: uint8 in IDL (rosidl_adapter)


@dataclass
class NodeEntitiesInfo(IdlStruct, typename="rmw_dds_common::msg::dds_::NodeEntitiesInfo_"):
    node_namespace: t.bounded_str[256]
    node_name: t.bounded_str[256]
    reader_gid_seq: t.sequence[Gid]
    writer_gid_seq: t.sequence[Gid]


@dataclass
class ParticipantEntitiesInfo(IdlStruct, typename="rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_"):
    gid: Gid
    node_entities_info_seq: t.sequence[NodeEntitiesInfo]


class GraphPeer:
    """What rmw_dds_common's GraphCache gathers: ``ros_discovery_info`` (reliable, transient local,
    keep all, as rmw_cyclonedds_cpp's discovery reader) and DDS's built-in participant, publication
    and subscription topics.  Everything is kept by GUID, the newest sample of each."""

    def __init__(self, domain: int, interface: str = "lo") -> None:
        from cyclonedds.builtin import (
            BuiltinDataReader,
            BuiltinTopicDcpsParticipant,
            BuiltinTopicDcpsPublication,
            BuiltinTopicDcpsSubscription,
        )

        xml = (f'<CycloneDDS><Domain id="any"><General><Interfaces><NetworkInterface name="{interface}"/>'
               '</Interfaces></General></Domain></CycloneDDS>')
        try:
            self.domain = Domain(domain, xml)
        except Exception:  # noqa: BLE001 - this process configured the domain already (on loopback)
            self.domain = None
        self.dp = DomainParticipant(domain)
        self.info: dict[bytes, ParticipantEntitiesInfo] = {}  # participant GID -> its newest sample
        # GID -> alive, properties, user data
        self.participants: dict[bytes, tuple[bool, dict[str, str], bytes]] = {}
        # GID -> kind, participant GID, topic, type, user data
        self.endpoints: dict[bytes, tuple[str, bytes, str, str, bytes]] = {}
        self._lock = threading.Lock()
        self._info = DataReader(self.dp, Topic(self.dp, "ros_discovery_info", ParticipantEntitiesInfo),
                                Qos(Policy.Reliability.Reliable(0), Policy.Durability.TransientLocal,
                                    Policy.History.KeepAll, Policy.DataRepresentation(use_cdrv0_representation=True)))
        self._builtin = [(BuiltinDataReader(self.dp, BuiltinTopicDcpsParticipant), "participant"),
                         (BuiltinDataReader(self.dp, BuiltinTopicDcpsPublication), "writer"),
                         (BuiltinDataReader(self.dp, BuiltinTopicDcpsSubscription), "reader")]
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True)
        self._thread.start()

    @staticmethod
    def _user_data(q) -> bytes:
        return bytes(q[Policy.Userdata].data) if q is not None and Policy.Userdata in q else b""

    def _loop(self) -> None:
        from cyclonedds.core import InstanceState

        while not self._stop.is_set():
            with self._lock:
                for s in self._info.take(100):
                    if isinstance(s, ParticipantEntitiesInfo):
                        self.info[bytes(s.gid.data)] = s
                for reader, kind in self._builtin:
                    for s in reader.take(100):
                        alive = s.sample_info.instance_state == InstanceState.Alive
                        key = s.key.bytes
                        if kind == "participant":
                            props = {p.key: p.value for p in (s.qos or []) if type(p).__name__ == "Property"}
                            old = self.participants.get(key)
                            if old is not None and not alive:
                                self.participants[key] = (False, old[1], old[2])
                            elif alive:
                                self.participants[key] = (True, props, self._user_data(s.qos))
                        elif alive:
                            self.endpoints[key] = (kind, s.participant_key.bytes, s.topic_name, s.type_name,
                                                   self._user_data(s.qos))
            time.sleep(0.02)

    def snapshot(self):
        with self._lock:
            return dict(self.info), dict(self.participants), dict(self.endpoints)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
