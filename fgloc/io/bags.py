"""What ROS 1 bags and rosbag2 folders share: read with ``rosbags`` (no ROS install needed).

Topics of the types fgloc reads are converted with the same rules as the MCAP reader
(:mod:`fgloc.io.ros`).  Messages come in record-time order (the bag's log time); a type the
bag defines that the type store lacks is registered from the bag's own definition.  A ROS 2
bag's messages keep their CDR bytes for copying (:class:`fgloc.io.source.Record`).

Topic names are the ones ROS resolves: a relative name a recorder stored (``scan``, as format-1.2
bags and some writers do) is the root namespace's ``/scan`` (:func:`resolved_topic`).
"""

from __future__ import annotations

import logging
import struct
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from fgloc.errors import LogError
from fgloc.io.ros import FROM_ROS, tf_flips
from fgloc.io.source import ChannelInfo, LogSource, Record, TopicInfo
from fgloc.io.topics import TF_MESSAGE, Topics, normalize_type

log = logging.getLogger(__name__)


def resolved_topic(name: str) -> str:
    """A bag's topic name as ROS resolves it: a relative name (no leading ``/``) is in the root
    namespace, as the recording node in the root namespace published it (``scan`` -> ``/scan``)."""
    return name if name.startswith("/") or not name else "/" + name


class BagSource(LogSource):
    """Base of :class:`~fgloc.io.rosbag1.Rosbag1Source` and :class:`~fgloc.io.rosbag2.Rosbag2Source`."""

    ros2: bool = True
    what = "bag"

    def __init__(self, path: str | Path, topics: Topics | None = None) -> None:
        super().__init__(path, topics)
        self._store: Any = None
        self._cdr_store: Any = None  # the ROS 2 type store a ROS 1 bag's other types are converted with
        reader = self._open_reader()
        try:
            conns = list(reader.connections)
            for c in conns:
                info = self._topic_info.setdefault(resolved_topic(c.topic), TopicInfo(normalize_type(c.msgtype)))
                info.count += int(c.msgcount)
            self._n = sum(int(c.msgcount) for c in conns)
            self._conns = self._storage_connections(reader, conns)
            if self._n:
                self._start_ns, self._end_ns = int(reader.start_time), int(reader.end_time)
        finally:
            reader.close()
        if self._n == 0:
            raise LogError(f"{self.path}: empty {self.what} (no messages)")

    # -- subclass hooks ----------------------------------------------------------------------
    def _reader(self) -> Any:
        raise NotImplementedError

    def _reader_errors(self) -> tuple[type[Exception], ...]:
        raise NotImplementedError

    def _storage_connections(self, reader: Any, conns: list[Any]) -> list[Any]:
        """The connections to read by (a format whose index can disagree with its files adds to them)."""
        return conns

    def _open_reader(self) -> Any:
        try:
            reader = self._reader()
            reader.open()
        except (OSError, ValueError, KeyError, *self._reader_errors()) as e:  # type: ignore[misc]
            raise LogError(f"{self.path}: cannot read {self.what} ({e})") from None
        return reader

    # -- decoding ----------------------------------------------------------------------------
    def _typestore(self) -> Any:
        if self._store is None:
            from rosbags.typesys import Stores, get_types_from_msg, get_typestore

            store = get_typestore(Stores.ROS2_HUMBLE if self.ros2 else Stores.ROS1_NOETIC)
            for c in self._conns:  # types the store lacks come with the bag's own definitions
                msgdef = getattr(getattr(c, "msgdef", None), "data", "")
                if c.msgtype not in store.fielddefs and msgdef:
                    try:
                        store.register(get_types_from_msg(msgdef, c.msgtype))
                    except Exception as e:  # noqa: BLE001 - that topic will be undecodable
                        log.warning("%s: cannot parse the definition of %s (%s)", self.path, c.msgtype, e)
            self._store = store
        return self._store

    def _channel_info(self, c: Any) -> ChannelInfo:
        topic = resolved_topic(c.topic)
        if not self.ros2:
            return ChannelInfo(topic, normalize_type(c.msgtype))
        md = getattr(c, "msgdef", None)
        fmt = getattr(getattr(md, "format", None), "name", "NONE")
        text = getattr(md, "data", "") or ""
        enc = {"MSG": "ros2msg", "IDL": "ros2idl"}.get(fmt, "") if text else ""
        return ChannelInfo(topic, normalize_type(c.msgtype), c.msgtype, enc, text.encode(), "cdr")

    def _records(self, want: set[str]) -> Iterator[Record]:
        store = self._typestore()
        deserialize = store.deserialize_cdr if self.ros2 else store.deserialize_ros1
        conns = [c for c in self._conns if resolved_topic(c.topic) in want]
        convs: dict[int, Any] = {}
        infos: dict[int, ChannelInfo] = {}
        raw: dict[int, Any] = {}  # types fgloc does not read, kept (keep_other_types): CDR bytes of a message
        for c in conns:
            fn = FROM_ROS.get(normalize_type(c.msgtype))
            if fn is None and self.keep_other_types:
                conv = self._to_cdr(c)
                if conv is not None:
                    raw[c.id] = conv
                    infos[c.id] = conv[1]
                    continue
            if fn is None:
                log.warning("%s: topic %s has type %s, which fgloc does not read; skipped",
                            self.path, resolved_topic(c.topic), c.msgtype)
            convs[c.id] = fn
            infos[c.id] = self._channel_info(c)
        if not conns:
            return
        reader = self._open_reader()
        try:
            for conn, t, data in self._resumable(reader, conns):
                fn = convs.get(conn.id)
                if fn is None:
                    keep = raw.get(conn.id)
                    if keep is not None:
                        try:
                            yield Record(keep[1].topic, None, int(t), bytes(keep[0](data)), keep[1])
                        except Exception:  # noqa: BLE001 - counted as undecodable, as a read type's would be
                            self.undecodable[keep[1].topic] = self.undecodable.get(keep[1].topic, 0) + 1
                    continue
                topic = infos[conn.id].topic
                try:
                    ros = deserialize(data, conn.msgtype)
                    out = fn(ros, topic)
                    if normalize_type(conn.msgtype) == TF_MESSAGE:
                        self.note_tf(out, tf_flips(ros))
                except Exception as e:  # noqa: BLE001 - an undecodable message is skipped
                    n = self.undecodable.get(topic, 0)
                    self.undecodable[topic] = n + 1
                    if n == 0:
                        log.warning("%s: cannot decode %s (%s): %s; skipping such messages",
                                    self.path, topic, conn.msgtype, e)
                    continue
                yield Record(topic, out, int(t), bytes(data) if self.ros2 else None, infos[conn.id])
        finally:
            reader.close()

    def _to_cdr(self, c: Any) -> tuple[Any, ChannelInfo] | None:
        """``(bytes -> ROS 2 CDR bytes, channel)`` of a connection whose type fgloc does not read: a
        ROS 2 bag's bytes as they are, a ROS 1 bag's converted by rosbags (the header's ``seq``
        dropped, as rosbags' own bag converter does) with the ROS 2 definition it generates; None
        when rosbags cannot."""
        if self.ros2:
            return (lambda d: d), self._channel_info(c)
        try:
            from rosbags.convert.converter import generate_message_converter
            from rosbags.typesys import Stores, get_typestore

            src = self._typestore()
            if self._cdr_store is None:
                dst = get_typestore(Stores.EMPTY)
                header = get_typestore(Stores.ROS2_HUMBLE).fielddefs["std_msgs/msg/Header"]
                dst.register({**src.fielddefs, "std_msgs/msg/Header": header})
                self._cdr_store = dst
            dst = self._cdr_store
            conv = generate_message_converter(src, dst, c.msgtype, c.msgtype, {}, src_is2=False, dst_is2=True)
            text = dst.generate_msgdef(c.msgtype, ros_version=2)[0]
        except Exception as e:  # noqa: BLE001 - that topic is not imported (said by fgloc import)
            log.info("%s: cannot convert %s (%s) to ROS 2: %s", self.path, resolved_topic(c.topic), c.msgtype, e)
            return None
        return conv, ChannelInfo(resolved_topic(c.topic), normalize_type(c.msgtype), c.msgtype, "ros2msg",
                                 text.encode(), "cdr")

    def _resumable(self, reader: Any, conns: list[Any]) -> Iterator[tuple[Any, int, Any]]:
        """``reader.messages(conns)``; when it fails on damaged data, the rest from
        :meth:`_resume` (after the ``(time, count at that time)`` already given), else stop
        there with :attr:`truncated` saying why."""
        errors: tuple[type[Exception], ...] = (*self._reader_errors(), AssertionError, struct.error, EOFError,
                                                OSError, ValueError, KeyError, IndexError, RuntimeError)
        last_t, at_last = -1, 0
        it = reader.messages(connections=conns)
        while True:
            try:
                conn, t, raw = next(it)
            except StopIteration:
                return
            except errors as e:
                rest = self._resume(conns, last_t, at_last, e)
                if rest is None:
                    self.truncated = f"{self.what} data unreadable after the messages read so far ({e})"
                    log.warning("%s: %s; stopping there", self.path, self.truncated)
                    return
                yield from rest
                return
            if t == last_t:
                at_last += 1
            else:
                last_t, at_last = int(t), 1
            yield conn, t, raw

    def _resume(self, conns: list[Any], after_t: int, n_at_t: int,
                error: Exception) -> Iterator[tuple[Any, int, Any]] | None:
        """The messages of ``conns`` after the first ``n_at_t`` at log time ``after_t`` (and
        all before it), read another way after ``error``; None: no other way (the default)."""
        return None
