"""The sources of one session: their handlers, built once, and what the session routes to them.

:class:`SourceRouter` builds one handler per configured source (its type's handler class,
:data:`~fgloc.localization.sources.config.SOURCE_TYPES`) with the context they share (the
localizer, the sensors' mounts, the base's tilt), and the scan source's
(:class:`~fgloc.localization.sources.scan.ScanHandler`).  The session routes each source's topic to
its handler (:meth:`SourceRouter.topic_kinds`, :meth:`SourceRouter.kinds`); messages
dispatched by kind (``odom``, ``imu``: ``fgloc live``'s sensor threads) go to the first source
of that type, so they are checked and counted the same way; ``/tf_static`` / ``/tf`` feed the
mounts.  At the end (:meth:`SourceRouter.finish`) the health of every source
(:mod:`~fgloc.localization.sources.report`) and the motion model go into the localizer's stats.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from typing import Any

from fgloc.frames.mounts import MountTable
from fgloc.frames.static import parse_static_transforms
from fgloc.io.topics import normalize_type
from fgloc.localization.sources.config import SOURCE_TYPES, parse_sources
from fgloc.localization.sources.handler import SourceContext, SourceHandler, SourceState
from fgloc.localization.sources.odometry import OdometryHandler
from fgloc.localization.sources.report import SourceReport, scan_report, source_report
from fgloc.localization.sources.scan import ScanHandler
from fgloc.localization.sources.spec import SourceSpec
from fgloc.types import LaserScan, PoseFix, StaticTransform

log = logging.getLogger(__name__)

#: the topics whose transforms feed the mounts (when the session routes them nowhere else)
TF_TOPICS = ("/tf_static", "/tf")
#: the kinds a message may be dispatched by (live), and the source type each goes to
DISPATCH_KINDS = {"odom": "odometry", "imu": "imu"}


class SourceRouter:
    """The handlers of ``specs`` (see the module docstring); ``static``: configured mounts."""

    def __init__(self, loc: Any, specs: list[SourceSpec], static: Sequence[StaticTransform] | None = None,
                 localized: Callable[[LaserScan, PoseFix | None], None] | None = None, base_frame: str = "") -> None:
        self.loc = loc
        self.specs = specs
        self.scan = ScanHandler(loc, localized)
        self.ctx = SourceContext(loc, MountTable(static, base_frame))
        self.configured_inputs = False  # the specs came from a config's sources.inputs (from_config)
        #: the log's topics and their message types (``{"/imu": "sensor_msgs/msg/Imu"}``), when the
        #: caller knows them: a silent source's warning names the log's topics of its type
        self.log_topics: dict[str, str] | None = None
        self.handlers: dict[str, SourceHandler] = {}
        first: dict[str, str] = {}
        for s in specs:
            cls = SOURCE_TYPES[s.type].handler
            second = cls.group is not None and cls.group in first
            if cls.group is not None:
                first.setdefault(cls.group, s.name)
            self.handlers[s.name] = cls(s, self.ctx, fused=not second or cls.second_fused, second=second)

    @classmethod
    def from_config(cls, loc: Any, topics: dict[str, str] | None = None,
                    localized: Callable[[LaserScan, PoseFix | None], None] | None = None) -> SourceRouter:
        """The router of the localizer's ``sources:`` section; ``topics`` (``odom`` / ``imu`` ->
        topic) names the default layout's topics; ``localized(scan, fix)``: after each scan."""
        cfg = getattr(getattr(loc, "config", None), "sources", None)
        specs = parse_sources(cfg, topics)
        static = cfg.get("static_transforms") if isinstance(cfg, dict) else getattr(cfg, "static_transforms", None)
        base = cfg.get("base_frame") if isinstance(cfg, dict) else getattr(cfg, "base_frame", "")
        router = cls(loc, specs, parse_static_transforms(static), localized, str(base or ""))
        inputs = cfg.get("inputs") if isinstance(cfg, dict) else getattr(cfg, "inputs", None)
        router.configured_inputs = bool(inputs)
        return router

    @property
    def state(self) -> dict[str, SourceState]:
        """Each source's running state by name."""
        return {name: h.state for name, h in self.handlers.items()}

    @property
    def mounts(self) -> MountTable:
        return self.ctx.mounts

    # ------------------------------------------------------------------ routing
    def topic_kinds(self) -> dict[str, str]:
        """``topic -> kind`` of every source (``source:NAME``)."""
        return {s.topic: f"source:{s.name}" for s in self.specs}

    def kinds(self) -> dict[str, Callable[[object], None]]:
        """``kind -> handler``: ``scan``, each source's, the dispatch kinds' (the first source of their
        type) and ``tf`` (the mounts)."""
        out: dict[str, Callable[[object], None]] = {"scan": self.scan}
        out.update({f"source:{s.name}": self.handlers[s.name] for s in self.specs})
        for kind, typ in DISPATCH_KINDS.items():
            first = next((s for s in self.specs if s.type == typ), None)
            if first is not None:
                out[kind] = self.handlers[first.name]
        out["tf"] = self.on_tf
        return out

    def on_message(self, spec: SourceSpec, msg: object) -> None:
        self.handlers[spec.name](msg)

    def on_tf(self, msg: object) -> None:
        self.ctx.mounts.add_tf(msg)

    # ------------------------------------------------------------------ health
    def health(self) -> dict[str, SourceReport]:
        """Per source: counts, and what the back-end estimated about it (:mod:`.report`)."""
        out = {s.name: source_report(self.handlers[s.name], self.loc) for s in self.specs}
        scan = scan_report(self.loc)
        if scan is not None:
            out["scan"] = scan
        return out

    def finish(self) -> None:
        for s in self.specs:
            self.handlers[s.name].finish()
        for line in self.silent_sources():
            log.warning("%s", line)
        self.loc.stats["sources"] = self.health()
        odo = [h for h in self.handlers.values() if isinstance(h, OdometryHandler) and h.state.fused]
        h0 = odo[0] if odo else None
        vy = None if h0 is None or not h0.state.messages or h0.spec.differential else h0.state.vy_max
        self.loc.stats["motion_model"] = self.loc.backend.motion_summary(vy)

    def silent_sources(self) -> list[str]:
        """One line per configured source (``sources.inputs``) that got no message in the whole run:
        the run went on without it (a ported robot_localization config naming a topic the log does
        not have).  The log's topics of that type are named when :attr:`log_topics` (topic ->
        message type, set by the caller that read the log) is known.  The default layout's sources
        are not configured: a log without ``/imu`` is a wheels-only log, not a mistake."""
        if not self.configured_inputs:
            return []
        out = []
        for s in self.specs:
            if self.handlers[s.name].state.messages:
                continue
            line = f"sources.inputs.{s.name}: no message on {s.topic} in the whole log; ran without it"
            if self.log_topics is not None:
                want = SOURCE_TYPES[s.type].message_type
                have = sorted(t for t, typ in self.log_topics.items() if normalize_type(typ) == want)
                what = want.split("/")[-1]
                line += f" (the log's {what} topics: {', '.join(have) if have else 'none'})"
            out.append(line)
        return out
