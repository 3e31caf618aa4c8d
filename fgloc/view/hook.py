"""What a localization run attaches to show itself: ``fgloc run/live --view`` and run.mcap's view channels.

A :class:`fgloc.localization.Session` sink::

    with ViewHook(loc, topics, view="127.0.0.1:8765", record_to=writer) as hook:
        Session(loc, routes, [recorder, hook]).run(paced(messages, realtime))

``view`` (``[HOST:]PORT``) starts the Foxglove WebSocket server; ``record_to`` is where the
same channels are recorded: an object with ``write_raw`` (the run's MCAP writer) or a path
(a separate MCAP).  Without foxglove-sdk, ``view`` is a one-line error with the install
hint and recording is skipped (``notes`` says so).  A failure inside the view is counted
(``stats['view_errors']``) and never stops the localization.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from fgloc.types import LaserScan, PoseFix
from fgloc.view.feed import ViewFeed, ViewSink


class ViewHook:
    def __init__(self, loc: Any, topics: Any = None, view: str | None = None, record_to: Any = None,
                 wait_for_viewer_s: float = 0.0, announce: Callable[[str], None] | None = None,
                 server_options: dict[str, Any] | None = None) -> None:
        self.server: Any = None
        self.recorder: Any = None
        self.notes: list[str] = []
        self.errors = 0
        self.first_error: str | None = None
        self._own_file: Any = None
        sinks: list[ViewSink] = []
        if view is not None:
            from fgloc.view.server import FoxgloveServerSink, parse_view_address

            host, port = parse_view_address(view)
            self.server = FoxgloveServerSink(host, port, **(server_options or {}))
            sinks.append(self.server)
            if announce is not None:
                announce(f"Foxglove view on {self.server.url} (Foxglove: Open connection -> Foxglove WebSocket; "
                         "layout: `fgloc view layout -o fgloc-layout.json`, then Layouts -> Import from file)")
        if record_to is not None:
            from fgloc.view.server import ViewUnavailableError, require_foxglove

            try:
                require_foxglove()
            except ViewUnavailableError as e:
                self.notes.append(f"view channels not recorded ({e})")
            else:
                from fgloc.view.record import McapFile, McapViewRecorder

                try:
                    if isinstance(record_to, str | Path):
                        self._own_file = McapFile(record_to)
                        record_to = self._own_file
                    self.recorder = McapViewRecorder(record_to)
                except BaseException:
                    if self.server is not None:
                        self.server.close()
                    raise
                sinks.append(self.recorder)
        self.feed = ViewFeed(loc, sinks, topics) if sinks else None
        if self.server is not None and wait_for_viewer_s > 0:
            self.wait_for_viewer(wait_for_viewer_s, announce)

    @property
    def active(self) -> bool:
        return self.feed is not None

    def wait_for_viewer(self, timeout_s: float, announce: Callable[[str], None] | None = None) -> bool:
        """Block until a viewer subscribed (then 0.5 s more for its other subscriptions) or ``timeout_s``."""
        if self.server is None:
            return False
        if announce is not None:
            announce(f"waiting up to {timeout_s:g} s for a viewer to subscribe")
        deadline = time.monotonic() + timeout_s
        while self.server.stats["subscriptions"] == 0 and time.monotonic() < deadline:
            time.sleep(0.05)
            self.server.poll()
        if self.server.stats["subscriptions"] == 0:
            return False
        time.sleep(min(0.5, max(0.0, deadline - time.monotonic())))
        self.server.poll()
        return True

    # ------------------------------------------------------------------ session sink
    def _failed(self, e: Exception) -> None:
        self.errors += 1
        if self.first_error is None:
            self.first_error = f"{type(e).__name__}: {e}"

    def on_message(self, topic: str, msg: object) -> None:
        if self.feed is not None:
            try:
                self.feed.on_message(topic, msg)
            except Exception as e:  # noqa: BLE001 - the view must never stop the localizer
                self._failed(e)

    def on_scan(self, stamp: float, scan: LaserScan, fix_or_reason: PoseFix | str, fused: PoseFix | None) -> None:
        if self.feed is not None:
            try:
                self.feed.on_scan(stamp, scan, fix_or_reason, fused)
            except Exception as e:  # noqa: BLE001
                self._failed(e)

    # ------------------------------------------------------------------ end
    def stats(self) -> dict[str, Any]:
        out: dict[str, Any] = {"view_errors": self.errors}
        if self.first_error:
            out["first_view_error"] = self.first_error
        if self.server is not None:
            out["server"] = {"url": self.server.url, **self.server.stats}
        if self.recorder is not None:
            out["recorded"] = self.recorder.count
        if self.notes:
            out["notes"] = list(self.notes)
        return out

    def close(self) -> None:
        """Flush and close the sinks (the server stops); idempotent.  Counters: :meth:`stats`."""
        try:
            if self.feed is not None:
                feed, self.feed = self.feed, None
                try:
                    feed.close()
                except Exception as e:  # noqa: BLE001
                    self._failed(e)
                    if self.server is not None:
                        self.server.close()
        finally:
            if self._own_file is not None:
                self._own_file.close()
                self._own_file = None

    def __enter__(self) -> ViewHook:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
