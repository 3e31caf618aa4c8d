"""A minimal Foxglove WebSocket protocol client for the tests (the ``websockets`` package).

Speaks what Foxglove's app speaks: subprotocol negotiation (``foxglove.sdk.v1``), the
``serverInfo`` and ``advertise`` text messages, ``subscribe``, and binary message data
(opcode 1: uint32 subscription id, uint64 log time ns, payload; opcode 2: server time).
Payloads are decoded with the schema each channel advertised: protobuf through a
descriptor pool built from the FileDescriptorSet, JSON as JSON.
"""

from __future__ import annotations

import asyncio
import base64
import json
import struct
import time
from dataclasses import dataclass, field
from typing import Any

SUBPROTOCOL = "foxglove.sdk.v1"
OP_MESSAGE_DATA = 1
OP_TIME = 2


def protobuf_class(schema_name: str, schema: str, schema_encoding: str = "protobuf") -> Any:
    """The message class for ``schema_name`` from an advertised (base64) FileDescriptorSet."""
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    assert schema_encoding == "protobuf"
    fds = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(schema))
    pool = descriptor_pool.DescriptorPool()
    pending, added = list(fds.file), set()
    while pending:  # add each file after its dependencies
        ready = [f for f in pending if all(d in added for d in f.dependency)]
        assert ready, "unresolvable protobuf dependencies in the advertised schema"
        for f in ready:
            pool.Add(f)
            added.add(f.name)
            pending.remove(f)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(schema_name))


@dataclass
class Received:
    topic: str
    log_time_ns: int
    message: Any


@dataclass
class Session:
    subprotocol: str | None = None
    server_info: dict[str, Any] | None = None
    channels: dict[int, dict[str, Any]] = field(default_factory=dict)  # channel id -> advertised channel
    messages: list[Received] = field(default_factory=list)
    times_ns: list[int] = field(default_factory=list)
    closed_by_server: bool = False

    def by_topic(self, topic: str) -> list[Received]:
        return [m for m in self.messages if m.topic == topic]


async def _connect(url: str, timeout_s: float) -> Any:
    import websockets

    deadline = time.monotonic() + timeout_s
    while True:
        try:
            return await websockets.connect(url, subprotocols=[SUBPROTOCOL], max_size=None, open_timeout=2)
        except (TimeoutError, OSError):
            if time.monotonic() > deadline:
                raise
            await asyncio.sleep(0.05)


async def watch(url: str, topics: set[str], until: Any = None, connect_timeout_s: float = 30.0,
                max_s: float = 30.0) -> Session:
    """Connect, subscribe to ``topics`` once advertised, collect decoded messages until the
    server closes the connection, ``until(session)`` is true, or ``max_s`` passed."""
    import websockets

    s = Session()
    ws = await _connect(url, connect_timeout_s)
    s.subprotocol = ws.subprotocol
    decoders: dict[int, Any] = {}
    subs: dict[int, int] = {}  # subscription id -> channel id
    deadline = time.monotonic() + max_s
    try:
        while time.monotonic() < deadline and not (until is not None and until(s)):
            try:
                raw = await asyncio.wait_for(ws.recv(), 0.5)
            except TimeoutError:
                continue
            except websockets.ConnectionClosed:
                s.closed_by_server = True
                break
            if isinstance(raw, str):
                msg = json.loads(raw)
                if msg["op"] == "serverInfo":
                    s.server_info = msg
                elif msg["op"] == "advertise":
                    new = []
                    for c in msg["channels"]:
                        s.channels[c["id"]] = c
                        if c["topic"] in topics:
                            new.append(c)
                    for c in new:
                        if c["encoding"] == "protobuf":
                            cls = protobuf_class(c["schemaName"], c["schema"], c["schemaEncoding"])
                            decoders[c["id"]] = lambda b, cls=cls: cls.FromString(b)
                        elif c["encoding"] == "json":
                            decoders[c["id"]] = lambda b: json.loads(bytes(b).decode())
                        else:
                            raise AssertionError(f"unexpected encoding {c['encoding']}")
                        subs[100 + c["id"]] = c["id"]
                    if new:
                        await ws.send(json.dumps({"op": "subscribe", "subscriptions": [
                            {"id": 100 + c["id"], "channelId": c["id"]} for c in new]}))
                continue
            op = raw[0]
            if op == OP_MESSAGE_DATA:
                sub_id, log_time = struct.unpack_from("<IQ", raw, 1)
                cid = subs[sub_id]
                s.messages.append(Received(s.channels[cid]["topic"], log_time, decoders[cid](raw[13:])))
            elif op == OP_TIME:
                s.times_ns.append(struct.unpack_from("<Q", raw, 1)[0])
    finally:
        await ws.close()
    return s


def stamp(ts: Any) -> float:
    """A decoded ``foxglove.Timestamp`` (protobuf ``google.protobuf.Timestamp``) in seconds."""
    return float(ts.seconds) + float(ts.nanos) * 1e-9
