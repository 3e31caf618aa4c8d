"""Localization: a front-end and a back-end driven one message at a time.

* :mod:`~fgloc.localization.config` - ``PipelineConfig`` (the ``pipeline:`` section);
* :mod:`~fgloc.localization.odometry` - the twist to integrate, the dead-reckoned odom pose;
* :mod:`~fgloc.localization.relocalization` - global search, relocalization candidates;
* :mod:`~fgloc.localization.localizer` - :class:`Localizer`: tracking, start-up, recovery;
* :mod:`~fgloc.localization.session` - :class:`Session`: input routing and sinks, what
  ``fgloc run``, ``fgloc live`` and the benches drive, each built by :func:`build_session`.
"""

from fgloc.localization.config import PipelineConfig
from fgloc.localization.localizer import Localizer
from fgloc.localization.session import (
    BaseSink,
    CallbackSink,
    RecorderSink,
    Routes,
    Session,
    Sink,
    UdpSink,
    build_session,
)

__all__ = ["BaseSink", "CallbackSink", "Localizer", "PipelineConfig", "RecorderSink", "Routes", "Session", "Sink",
           "UdpSink", "build_session"]
