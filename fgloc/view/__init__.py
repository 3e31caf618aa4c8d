"""See the localizer: a Foxglove WebSocket view (live and on replay) and the same channels in MCAP.

* :mod:`fgloc.view.channels` - topic names and schemas (shared with the layout);
* :mod:`fgloc.view.feed` - :class:`ViewFeed`: localizer callbacks -> the sink interface;
* :mod:`fgloc.view.server` - :class:`FoxgloveServerSink`: the WebSocket server (foxglove-sdk),
  a bounded queue and a publisher thread, so the view never slows the localizer;
* :mod:`fgloc.view.record` - :class:`McapViewRecorder`: the same channels into an MCAP;
* :mod:`fgloc.view.hook` - :class:`ViewHook`: what ``fgloc run --view`` / ``fgloc live --view`` attach;
* :mod:`fgloc.view.pace` - ``--realtime R`` replay pacing;
* :mod:`fgloc.view.layout` - the Foxglove layout (``docs/foxglove/fgloc-layout.json``).

foxglove-sdk is optional (``pip install "fgloc[view]"``); only :mod:`~fgloc.view.encode`,
:mod:`~fgloc.view.server` and :mod:`~fgloc.view.record` need it, and they say so in one line.
"""

from __future__ import annotations

from fgloc.view.feed import ScanView, ViewFeed, ViewSink
from fgloc.view.hook import ViewHook
from fgloc.view.pace import check_rate, paced

__all__ = ["ScanView", "ViewFeed", "ViewHook", "ViewSink", "check_rate", "paced"]
