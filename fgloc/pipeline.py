"""Old import path of the localizer (kept for callers that still use it).

The localizer lives in :mod:`fgloc.localization` (:class:`~fgloc.localization.Localizer`,
:class:`~fgloc.localization.Session`); the configuration in :mod:`fgloc.config`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from fgloc.config.loader import FglocConfig
from fgloc.config.loader import load_config as _load_config
from fgloc.localization.localizer import Localizer
from fgloc.localization.session import CallbackSink, Routes, Session
from fgloc.types import PoseFix, Trajectory

__all__ = ["Localizer", "load_config", "run_messages"]


def load_config(path: str | Path | None = None) -> FglocConfig:
    """:func:`fgloc.config.load_config`."""
    return _load_config(path)


def run_messages(loc: Localizer, messages: Iterable[tuple[str, object]], topics: Any = None,
                 on_message: Callable[[str, object], None] | None = None,
                 on_fused: Callable[[PoseFix, PoseFix | None], None] | None = None) -> Trajectory:
    """Feed ``(topic, message)`` pairs to ``loc`` through a :class:`~fgloc.localization.Session`
    and return ``loc.finish()``; ``on_fused(fused, fix)`` after each scan with a fused pose."""
    sinks = []
    if on_message is not None or on_fused is not None:
        def scan_cb(stamp: float, scan: Any, fix_or_reason: PoseFix | str, fused: PoseFix | None) -> None:
            if on_fused is not None and fused is not None:
                on_fused(fused, fix_or_reason if isinstance(fix_or_reason, PoseFix) else None)

        sinks.append(CallbackSink(on_message, scan_cb))
    return Session(loc, Routes.default(topics), sinks).run(messages)
