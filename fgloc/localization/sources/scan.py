"""The scan source (``sensor_msgs/LaserScan``): each scan to the localizer's tracking.

The localizer matches the scan with its front-end from the back-end's prediction and hands the
fix to the back-end (:meth:`~fgloc.localization.localizer.Localizer.on_scan`); the handler
then tells its ``localized(scan, fix)`` callback (the session's sinks).  Its health report is
:func:`~fgloc.localization.sources.report.scan_report`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from fgloc.types import LaserScan, PoseFix


class ScanHandler:
    """Scans into the localizer, then ``localized(scan, fix or None)`` (see the module docstring)."""

    def __init__(self, loc: Any, localized: Callable[[LaserScan, PoseFix | None], None] | None = None) -> None:
        self.loc = loc
        self.localized = localized

    def __call__(self, msg: object) -> None:
        if not isinstance(msg, LaserScan):
            return
        fix = self.loc.on_scan(msg)
        if self.localized is not None:
            self.localized(msg, fix)
