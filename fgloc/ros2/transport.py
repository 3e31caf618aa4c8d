"""The DDS transport: a participant in a ROS 2 domain, raw-CDR publishers and subscriptions,
and every endpoint's health.

:class:`Transport` is the interface the live node and the replay use; :class:`CycloneTransport`
implements it with Eclipse Cyclone DDS (one of ROS 2's tier-1 middlewares; its Python wheel
bundles the C library).  Messages cross it as the CDR bytes ROS 2 puts on the wire (encapsulation
header included): fgloc encodes and decodes them itself (:mod:`fgloc.ros2.codec`), Cyclone only
carries them.  Names and QoS follow ROS 2 (:mod:`fgloc.ros2.names`, :mod:`fgloc.ros2.qos`).

Health (:class:`EndpointHealth`, one per topic and direction) counts what the DDS layer reports
and what a ROS 2 node would only log: messages, undecodable ones (counted by the caller), peers
matched now, peers that vanished and came back, a peer whose QoS cannot match (the policy named),
endpoints of the same topic with another type (from DDS discovery, the built-in publication and
subscription topics), samples the reader lost, and writes dropped because a reliable
subscriber stalled (a writer waits at most :data:`fgloc.ros2.qos.MAX_BLOCKING_S`).

Threads: one receive thread waits on all readers and hands each sample's bytes to its
subscription's callback (which must not block: the live node decodes and queues); Cyclone's
own threads call the status listeners, which only update counters.  Nothing here opens a socket
of its own: the ports are DDS's (RTPS over UDP: discovery and user traffic, by domain id).
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol
from xml.sax.saxutils import quoteattr

from fgloc.errors import ConfigError
from fgloc.quantiles import LogHistogram
from fgloc.ros2.names import dds_topic, dds_type, ros_topic, ros_type
from fgloc.ros2.qos import RELIABLE, TRANSIENT_LOCAL, Profile, to_dds

#: DDS QoS policy ids (DDS 2.2.3; Cyclone's dds_qos_policy_id_t) as an incompatible-QoS status names them
POLICY_NAMES = {1: "USER_DATA", 2: "DURABILITY", 3: "PRESENTATION", 4: "DEADLINE", 5: "LATENCY_BUDGET",
                6: "OWNERSHIP", 7: "OWNERSHIP_STRENGTH", 8: "LIVELINESS", 9: "TIME_BASED_FILTER",
                10: "PARTITION", 11: "RELIABILITY", 12: "DESTINATION_ORDER", 13: "HISTORY",
                14: "RESOURCE_LIMITS", 15: "ENTITY_FACTORY", 16: "WRITER_DATA_LIFECYCLE",
                17: "READER_DATA_LIFECYCLE", 18: "TOPIC_DATA", 19: "GROUP_DATA", 20: "TRANSPORT_PRIORITY",
                21: "LIFESPAN", 22: "DURABILITY_SERVICE", 23: "PROPERTY", 24: "TYPE_CONSISTENCY_ENFORCEMENT",
                25: "DATA_REPRESENTATION"}
MAX_DOMAIN_ID = 232  # ROS 2's largest domain id (RTPS port mapping with the default port parameters)
INSTALL_HINT = 'the ROS 2 transport needs Eclipse Cyclone DDS: pip install "fgloc[ros2]"'

Callback = Callable[[bytes, float], None]  # (CDR bytes, arrival time.time())


@dataclass
class EndpointHealth:
    """What happened on one topic in one direction (see the module docstring)."""

    topic: str
    type: str
    direction: str  # "sub" | "pub"
    qos: Profile
    messages: int = 0
    undecodable: int = 0
    dropped: int = 0
    callback_errors: int = 0
    matched: int = 0
    lost: int = 0
    returned: int = 0
    incompatible_qos: int = 0
    incompatible_policy: str = ""
    sample_lost: int = 0
    other_generation: int = 0  # ros_discovery_info: peers of another ROS 2 generation (GID size)
    other_type: dict[str, int] = field(default_factory=dict)
    last_arrival: float = float("nan")
    #: written (the sample's DDS source timestamp, the writer's clock) -> handed to the callback, ms: the
    #: transport's own delay when both ends share a clock (the same machine); the whole run's, in constant memory
    delivery_ms: LogHistogram = field(default_factory=lambda: LogHistogram(lo=1e-4))
    last_error: str = ""
    _missing: int = 0  # peers lost and not back yet

    def problems(self) -> list[str]:
        """One short phrase per problem seen (empty when none)."""
        out = []
        if self.undecodable:
            out.append(f"{self.undecodable} undecodable" + (f" ({self.last_error})" if self.last_error else ""))
        if self.incompatible_qos:
            peer = "publisher" if self.direction == "sub" else "subscriber"
            out.append(f"{self.incompatible_qos} {peer}(s) with incompatible QoS ({self.incompatible_policy})")
        for t, n in self.other_type.items():
            out.append(f"{n} endpoint(s) with another type {ros_type(t)}")
        if self.lost:
            peer = "publisher" if self.direction == "sub" else "subscriber"
            out.append(f"{peer} vanished {self.lost}x, back {self.returned}x")
        if self.dropped:
            out.append(f"{self.dropped} dropped (a reliable subscriber stalled)")
        if self.sample_lost:
            out.append(f"{self.sample_lost} samples lost")
        if self.callback_errors:
            out.append(f"{self.callback_errors} handler errors")
        if self.other_generation:
            out.append(f"{self.other_generation} peer(s) of another ROS 2 generation (Humble and older write "
                       "24-byte GIDs, Iron and later 16): set ros2.ros_distro or $ROS_DISTRO to theirs")
        return out

    def as_dict(self) -> dict[str, Any]:
        d = {k: getattr(self, k) for k in ("topic", "type", "direction", "messages", "undecodable", "dropped",
                                          "matched", "lost", "returned", "incompatible_qos", "incompatible_policy",
                                          "sample_lost", "callback_errors", "other_generation")}
        d["qos"] = f"{self.qos.reliability}/{self.qos.durability}/{self.qos.depth}"
        d["other_type"] = {ros_type(k): v for k, v in self.other_type.items()}
        if self.delivery_ms.count:
            d["delivery_ms"] = {"p50": round(self.delivery_ms.percentile(50), 3),
                                "p99": round(self.delivery_ms.percentile(99), 3)}
        return d


def _user_data_of(sample: Any) -> bytes:
    """USER_DATA of a DDS built-in topic sample (b"" when none)."""
    from cyclonedds.qos import Policy

    q = getattr(sample, "qos", None)
    try:
        return bytes(q[Policy.Userdata].data) if q is not None and Policy.Userdata in q else b""
    except Exception:  # noqa: BLE001
        return b""


class Publisher(Protocol):
    health: EndpointHealth

    def write(self, data: bytes) -> bool: ...


class Transport(Protocol):
    """What the live node and the replay need from a middleware."""

    domain_id: int

    def publisher(self, topic: str, type_name: str, qos: Profile) -> Publisher: ...

    def subscribe(self, topic: str, type_name: str, qos: Profile, callback: Callback) -> EndpointHealth: ...

    def start(self) -> None: ...

    def health(self) -> list[EndpointHealth]: ...

    def remote_endpoints(self, topic: str, kind: str = "sub") -> int: ...

    def close(self) -> None: ...


def domain_from_env(value: int | None = None) -> int:
    """``value``, else ``$ROS_DOMAIN_ID``, else 0 (ROS 2's rule); a one-line error when invalid."""
    if value is None:
        raw = os.environ.get("ROS_DOMAIN_ID", "").strip()
        if not raw:
            return 0
        if not raw.isdigit():
            raise ConfigError(f"ROS_DOMAIN_ID={raw!r}: expected an integer 0..{MAX_DOMAIN_ID}")
        value = int(raw)
    if not 0 <= int(value) <= MAX_DOMAIN_ID:
        raise ConfigError(f"domain id {value}: expected 0..{MAX_DOMAIN_ID} (ROS_DOMAIN_ID)")
    return int(value)


#: DDS vendor ids whose XTypes type information Cyclone DDS is told to ignore (matching those endpoints by
#: type name, as rmw_cyclonedds_cpp's endpoints, which carry none, are matched): eProsima Fast DDS (1.15),
#: whose type objects this Cyclone cannot resolve ("invalid type object"), so that an endpoint of
#: rmw_fastrtps would never match one of fgloc's
IGNORE_TYPE_INFORMATION_OF = "1.15"


def cyclone_config(interface: str | None) -> str | None:
    """Cyclone DDS XML: the participant bound to one network interface (a name such as ``eth0`` or
    ``lo``, or an address; None: Cyclone's choice), the type information of Fast DDS peers ignored
    (:data:`IGNORE_TYPE_INFORMATION_OF`).  None when no interface is given and ``$CYCLONEDDS_URI`` is set
    (the user's configuration, as it is)."""
    compat = (f"<Compatibility><IgnoreTypeInformation>{IGNORE_TYPE_INFORMATION_OF}</IgnoreTypeInformation>"
              "</Compatibility>")
    if not interface:
        if os.environ.get("CYCLONEDDS_URI"):
            return None
        return f'<CycloneDDS><Domain id="any">{compat}</Domain></CycloneDDS>'
    iface = interface.strip()
    looks_address = iface.replace(".", "").isdigit() or ":" in iface
    attr = f"address={quoteattr(iface)}" if looks_address else f"name={quoteattr(iface)}"
    return (f'<CycloneDDS><Domain id="any"><General><Interfaces><NetworkInterface {attr}/>'
            f"</Interfaces></General>{compat}</Domain></CycloneDDS>")


_DOMAINS: dict[int, tuple[str | None, Any]] = {}  # a process configures each domain id once


def _domain(make: Any, domain_id: int, xml: str | None) -> Any:
    have = _DOMAINS.get(domain_id)
    if have is not None:
        if have[0] != xml:
            raise ConfigError(f"DDS domain {domain_id} is already joined by this process with another interface")
        return have[1]
    try:
        dom = make(domain_id, xml) if xml is not None else None
    except Exception as e:  # noqa: BLE001
        if "PRECONDITION_NOT_MET" not in str(e):
            raise
        dom = None  # configured in this process by other code (a test's own peer): joined as it is
    _DOMAINS[domain_id] = (xml, dom)
    return dom


class _Writer:
    def __init__(self, writer: Any, health: EndpointHealth) -> None:
        from cyclonedds._clayer import ddspy_write

        self._w = writer
        self._write = ddspy_write
        self.health = health

    def write(self, data: bytes) -> bool:
        """Publish ``data`` (CDR, header included); False when dropped (counted)."""
        if len(data) % 4:  # DDS payloads are padded to 4 bytes (the encapsulation's padding)
            data = data + b"\x00" * (4 - len(data) % 4)
        try:
            ret = self._write(self._w._ref, data)
        except Exception as e:  # noqa: BLE001 - a publishing failure never stops the caller
            ret = -1
            self.health.last_error = f"{type(e).__name__}: {e}"
        if ret < 0:
            self.health.dropped += 1
            return False
        self.health.messages += 1
        return True


class CycloneTransport:
    """A ROS 2 peer on DDS domain ``domain_id`` (see the module docstring).  ``interface``: the
    network interface (name or address) DDS uses; None: Cyclone's default / ``$CYCLONEDDS_URI``."""

    def __init__(self, domain_id: int | None = None, interface: str | None = None, node_name: str = "fgloc",
                 namespace: str = "/", distro: str | None = None) -> None:
        try:
            from cyclonedds.core import Listener, Qos  # noqa: F401
            from cyclonedds.domain import Domain, DomainParticipant
            from cyclonedds.qos import Policy
        except ImportError:
            raise ConfigError(INSTALL_HINT) from None
        self.domain_id = domain_from_env(domain_id)
        self.interface = interface
        xml = cyclone_config(interface)
        try:
            self._domain = _domain(Domain, self.domain_id, xml)
            # the participant's USER_DATA as rmw_cyclonedds writes it (ROS 2 tools read the enclave)
            self._dp = DomainParticipant(self.domain_id, qos=Qos(Policy.Userdata(b"enclave=/;")))
        except Exception as e:  # noqa: BLE001 - a bad interface / config: one line
            raise ConfigError(f"DDS domain {self.domain_id}"
                              + (f", interface {interface}" if interface else "") + f": {e}") from None
        self._topics: dict[str, tuple[str, Any]] = {}  # DDS topic name -> (DDS type, Topic)
        self._subs: list[tuple[Any, EndpointHealth, Callback]] = []
        self._pubs: list[tuple[Any, EndpointHealth]] = []
        self._endpoints: list[EndpointHealth] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._builtin: list[tuple[Any, str]] = []
        self._remote: dict[Any, tuple[str, str, str]] = {}  # endpoint key -> (kind, DDS topic, DDS type)
        self.receive_errors = 0
        self._graph_setup(node_name, namespace, distro)

    # ---------------------------------------------------------------- the ROS 2 graph
    def _graph_setup(self, node_name: str, namespace: str, distro: str | None) -> None:
        """This participant as one ROS 2 node on ``ros_discovery_info`` (:mod:`fgloc.ros2.graph`)."""
        from cyclonedds.pub import DataWriter
        from cyclonedds.topic import Topic

        from fgloc.ros2 import graph
        from fgloc.ros2.names import resolve

        self.distro = graph.distro_name(distro)
        self.type_hashes = not graph.before_iron(self.distro)
        self._gid_size = graph.gid_size(self.distro)
        ns = resolve(namespace) if namespace.strip("/") else "/"
        if not node_name or "/" in node_name:
            raise ConfigError(f"node name {node_name!r}: expected a name without '/'")
        self.gid = graph.gid_of(self._dp.guid)
        self.node = graph.NodeEntities(node_name, ns)
        prof = Profile(RELIABLE, TRANSIENT_LOCAL, 1, "rmw_cyclonedds_cpp ros_discovery_info")
        self.graph_health = EndpointHealth(graph.TOPIC, graph.TYPE, "pub", prof)
        topic = Topic(self._dp, graph.TOPIC, graph.idl_class(self._gid_size))
        self._graph_topic = topic
        self._graph_writer = DataWriter(self._dp, topic, qos=to_dds(prof, user_data=self._user_data(graph.TYPE)))
        self._graph_lock = threading.Lock()
        self._other_generation: set[Any] = set()
        self._publish_graph()

    def _user_data(self, type_name: str) -> bytes | None:
        """``typehash=RIHS01_...;`` as rmw_cyclonedds_cpp writes it (ROS 2 Iron and later)."""
        if not self.type_hashes:
            return None
        from fgloc.ros2.typehash import user_data

        return user_data(type_name)

    def _publish_graph(self, nodes: bool = True) -> None:
        """Write this participant's ``ParticipantEntitiesInfo`` (again: keep last 1)."""
        from cyclonedds._clayer import ddspy_write

        from fgloc.ros2 import graph

        with self._graph_lock:
            info = graph.ParticipantEntities(self.gid, [self.node] if nodes else [])
            ret = ddspy_write(self._graph_writer._ref, graph.encode(info, self._gid_size))
        if ret < 0:
            self.graph_health.dropped += 1
        else:
            self.graph_health.messages += 1

    def _add_to_node(self, entity: Any, kind: str) -> None:
        from fgloc.ros2 import graph

        gid = graph.gid_of(entity.guid)
        with self._graph_lock:
            (self.node.readers if kind == "sub" else self.node.writers).append(gid)
        self._publish_graph()

    # ---------------------------------------------------------------- entities
    def _topic(self, topic: str, type_name: str) -> tuple[str, Any]:
        from cyclonedds.topic import Topic

        from fgloc.ros2.msgtypes import idl_class

        name = dds_topic(topic)
        want = dds_type(type_name)
        have = self._topics.get(name)
        if have is not None:
            if have[0] != want:
                raise ConfigError(f"{topic}: used as {ros_type(have[0])} and as {type_name} in one node")
            return name, have[1]
        t = Topic(self._dp, name, idl_class(type_name))
        self._topics[name] = (want, t)
        return name, t

    def publisher(self, topic: str, type_name: str, qos: Profile) -> _Writer:
        from cyclonedds.core import Listener
        from cyclonedds.pub import DataWriter

        _, t = self._topic(topic, type_name)
        h = EndpointHealth(topic, type_name, "pub", qos)
        listener = Listener(on_publication_matched=lambda _w, s: self._matched(h, s),
                            on_offered_incompatible_qos=lambda _w, s: self._incompatible(h, s))
        w = DataWriter(self._dp, t, qos=to_dds(qos, user_data=self._user_data(type_name)), listener=listener)
        with self._lock:
            self._pubs.append((w, h))
            self._endpoints.append(h)
        self._add_to_node(w, "pub")
        return _Writer(w, h)

    def subscribe(self, topic: str, type_name: str, qos: Profile, callback: Callback) -> EndpointHealth:
        from cyclonedds.core import Listener
        from cyclonedds.sub import DataReader

        _, t = self._topic(topic, type_name)
        h = EndpointHealth(topic, type_name, "sub", qos)

        def lost(_r: Any, s: Any) -> None:
            h.sample_lost = int(s.total_count)

        listener = Listener(on_subscription_matched=lambda _r, s: self._matched(h, s),
                            on_requested_incompatible_qos=lambda _r, s: self._incompatible(h, s),
                            on_sample_lost=lost)
        r = DataReader(self._dp, t, qos=to_dds(qos, user_data=self._user_data(type_name)), listener=listener)
        with self._lock:
            self._subs.append((r, h, callback))
            self._endpoints.append(h)
        self._add_to_node(r, "sub")
        return h

    @staticmethod
    def _matched(h: EndpointHealth, s: Any) -> None:
        change = int(s.current_count_change)
        h.matched = int(s.current_count)
        if change < 0:
            h.lost += -change
            h._missing += -change
        elif change > 0 and h._missing > 0:
            back = min(change, h._missing)
            h.returned += back
            h._missing -= back

    @staticmethod
    def _incompatible(h: EndpointHealth, s: Any) -> None:
        h.incompatible_qos = int(s.total_count)
        h.incompatible_policy = POLICY_NAMES.get(int(s.last_policy_id), f"policy {int(s.last_policy_id)}")

    # ---------------------------------------------------------------- receiving
    def start(self) -> None:
        """Start the receive thread (subscriptions made later are read too)."""
        if self._thread is not None:
            return
        from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsPublication, BuiltinTopicDcpsSubscription

        self._builtin = [(BuiltinDataReader(self._dp, BuiltinTopicDcpsPublication), "pub"),
                         (BuiltinDataReader(self._dp, BuiltinTopicDcpsSubscription), "sub")]
        self._thread = threading.Thread(target=self._loop, name="fgloc-dds", daemon=True)
        self._thread.start()

    def _loop(self) -> None:
        from cyclonedds._clayer import ddspy_take
        from cyclonedds.core import InstanceState, ReadCondition, SampleState, ViewState, WaitSet
        from cyclonedds.util import duration

        mask = SampleState.Any | ViewState.Any | InstanceState.Any
        ws = WaitSet(self._dp)
        attached: set[int] = set()
        conds = []
        next_discovery = 0.0
        while not self._stop.is_set():
            with self._lock:
                subs = list(self._subs)
            for r, _, _ in subs:
                if id(r) not in attached:
                    c = ReadCondition(r, mask)
                    ws.attach(c)
                    conds.append(c)
                    attached.add(id(r))
            try:
                ws.wait(duration(milliseconds=50))
            except Exception:  # noqa: BLE001 - a wait interrupted at shutdown
                if self._stop.is_set():
                    break
            # every reader's samples, handed on in the order they were written (their source
            # timestamps): a scan is not fused before the odometry published just before it
            batch: list[tuple[int, int, EndpointHealth, Callback, bytes]] = []
            for r, h, cb in subs:
                while True:
                    try:
                        got = ddspy_take(r._ref, mask, 64)
                    except Exception:  # noqa: BLE001
                        self.receive_errors += 1
                        break
                    if isinstance(got, int) or not got:
                        break
                    for data, info in got:
                        if info.valid_data:
                            batch.append((int(info.source_timestamp), len(batch), h, cb, data))
                    if len(got) < 64:
                        break
            if batch:
                batch.sort(key=lambda b: (b[0], b[1]))
                now = time.time()
                for written, _, h, cb, data in batch:
                    h.last_arrival = now
                    h.delivery_ms.add(now * 1e3 - written * 1e-6)
                    h.messages += 1
                    try:
                        cb(data, now)
                    except Exception as e:  # noqa: BLE001 - a handler error is counted, never fatal
                        h.callback_errors += 1
                        h.last_error = f"{type(e).__name__}: {e}"
            now = time.monotonic()
            if now >= next_discovery:
                next_discovery = now + 0.25
                self._discovery()

    def _discovery(self) -> None:
        """Remote endpoints from DDS discovery: those on our topics with another type; the peers whose
        ``ros_discovery_info`` is of another ROS 2 generation (Humble and older: 24-byte GIDs)."""
        from fgloc.ros2 import graph

        changed = False
        for reader, kind in self._builtin:
            try:
                samples = reader.take(256)
            except Exception:  # noqa: BLE001
                continue
            for s in samples:
                info = getattr(s, "sample_info", None)
                key = getattr(s, "key", None)
                if key is None:
                    continue
                from cyclonedds.core import InstanceState

                alive = info is None or info.instance_state == InstanceState.Alive
                if alive and getattr(s, "topic_name", None):
                    self._remote[key] = (kind, s.topic_name, s.type_name)
                    if kind == "pub" and s.topic_name == graph.TOPIC and s.participant_key != self._dp.guid:
                        # rmw writes the type hash from Iron on: a peer without it sends 24-byte GIDs
                        if (b"typehash=" in _user_data_of(s)) != self.type_hashes:
                            self._other_generation.add(key)
                        else:
                            self._other_generation.discard(key)
                else:
                    self._remote.pop(key, None)
                    self._other_generation.discard(key)
                changed = True
        self.graph_health.other_generation = len(self._other_generation)
        if not changed:
            return
        with self._lock:
            ends = list(self._endpoints)
        for h in ends:
            name, want = dds_topic(h.topic), dds_type(h.type)
            peer = "pub" if h.direction == "sub" else "sub"
            other: dict[str, int] = {}
            for kind, topic, typ in self._remote.values():
                if kind == peer and topic == name and typ != want:
                    other[typ] = other.get(typ, 0) + 1
            h.other_type = other

    # ---------------------------------------------------------------- state
    def health(self) -> list[EndpointHealth]:
        with self._lock:
            return list(self._endpoints) + [self.graph_health]

    def remote_endpoints(self, topic: str, kind: str = "sub") -> int:
        """Endpoints of other participants on ROS topic ``topic`` that discovery has shown (``kind``
        ``sub``: readers, ``pub``: writers), whatever their type."""
        name = dds_topic(topic)
        return sum(1 for k, t, _ in list(self._remote.values()) if k == kind and t == name)

    def remote_topics(self) -> dict[str, set[str]]:
        """ROS topics seen in discovery, with their ROS types (writers and readers)."""
        out: dict[str, set[str]] = {}
        for _, topic, typ in self._remote.values():
            t = ros_topic(topic)
            if t is not None:
                out.setdefault(t, set()).add(ros_type(typ))
        return out

    def close(self) -> None:
        """Stop receiving and leave the domain (peers see the endpoints go at once)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        if self._dp is not None:
            try:
                self._publish_graph(nodes=False)  # the node leaves the graph (as rmw's node destruction)
            except Exception:  # noqa: BLE001
                pass
        with self._lock:
            self._subs.clear()
            self._pubs.clear()
        self._builtin = []
        self._topics.clear()
        dp, self._dp = self._dp, None  # type: ignore[assignment]
        if dp is not None:
            try:
                dp.__del__()  # dds_delete: the participant and everything in it
            except Exception:  # noqa: BLE001
                pass
