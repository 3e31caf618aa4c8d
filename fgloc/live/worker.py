"""The thread behind each live sensor (serial link, laser client): start / stop, the exception that
killed it, reconnect back-off and throttled event lines."""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

log = logging.getLogger(__name__)


class SensorThread:
    """Base of a sensor's reader thread: subclasses implement :meth:`serve` (the connect / read /
    reconnect loop, until ``stop_event`` is set) and name themselves with ``label`` (``serial URL``,
    ``laser HOST:PORT``) and ``role`` (``reader``, ``client``).

    A :meth:`serve` that raises ends the thread with the reason in :attr:`failure` and one
    ``on_event`` line; the session sees it and stops (``fgloc live`` exits 1).
    """

    role = "reader"
    thread_name = "sensor"

    def __init__(self, on_event: Callable[[str], None] | None, backoff_min_s: float, backoff_max_s: float) -> None:
        self.on_event = on_event or (lambda msg: log.info("%s", msg))
        self.backoff_min_s, self.backoff_max_s = backoff_min_s, backoff_max_s
        self.connected = False
        self.stop_event = threading.Event()
        self.thread: threading.Thread | None = None
        self.thread_failure: str | None = None

    @property
    def label(self) -> str:
        raise NotImplementedError

    def serve(self) -> None:
        raise NotImplementedError

    def start(self) -> None:
        self.thread = threading.Thread(target=self.run_thread, name=self.thread_name, daemon=True)
        self.thread.start()

    def stop(self, timeout: float = 2.0) -> None:
        self.stop_event.set()
        self.before_join()
        if self.thread is not None:
            self.thread.join(timeout)

    def before_join(self) -> None:
        """Called by :meth:`stop` between setting the stop event and joining (say goodbye to a device)."""

    @property
    def failure(self) -> str | None:
        """Why the thread died (``None`` while it runs or after a clean stop)."""
        return self.thread_failure

    def run_thread(self) -> None:
        try:
            self.serve()
        except BaseException as e:  # noqa: BLE001 - recorded and reported: the session must see it
            self.thread_failure = f"{type(e).__name__}: {e}"
            self.connected = False
            self.on_event(f"{self.label}: {self.role} thread died ({self.thread_failure})")
            log.debug("%s %s thread", self.label, self.role, exc_info=True)

    def retry_later(self, failures: int, what: str, backoff: float) -> float:
        """After the ``failures``-th failed connect: an event line (the 1st, 10th, every 50th), wait
        ``backoff`` (or until stopped); returns the next, doubled back-off."""
        if failures in (1, 10) or failures % 50 == 0:
            self.on_event(f"{self.label}: {what}; retrying")
        self.stop_event.wait(backoff)
        return min(backoff * 2.0, self.backoff_max_s)
