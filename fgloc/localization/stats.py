"""What a run counted, typed: :class:`RunStats` (``fgloc run``'s result, its summary, the batch).

The localizer counts into ``Localizer.stats`` as it goes (a counter per event, the sources'
reports and the motion model at the end); :meth:`RunStats.of` is that bag after the run as a
record: the counters every summary prints as fields, the per-source reports
(:class:`~fgloc.localization.sources.report.SourceReport`), the back-end's own counters (its
contract's ``stats``), and the localizer's rarer counters by name.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any

from fgloc.localization.sources.report import SourceReport


@dataclass
class RunStats:
    """The localizer's counters after a run (see the module docstring)."""

    scans: int = 0
    odometry: int = 0
    compass: int = 0
    fixes: int = 0
    no_fix: int = 0
    rejected: int = 0
    gated: int = 0  # fixes the back-end rejected
    skipped: int = 0  # inputs skipped as bad (every source's, with the reasons below)
    relocalizations: int = 0
    global_searches: int = 0
    lost_events: int = 0  # times the localizer got lost after tracking
    lost_s: float = 0.0
    ended_lost: bool = False
    skipped_reasons: dict[str, int] = field(default_factory=dict)
    no_fix_reasons: dict[str, int] = field(default_factory=dict)  # grouped by kind
    sources: dict[str, SourceReport] = field(default_factory=dict)
    motion_model: str = ""
    backend: dict[str, Any] = field(default_factory=dict)  # the back-end's counters
    odom_clock: dict[str, Any] = field(default_factory=dict)  # a slow odometry's clock (localization/clock.py)
    #: the localizer's other counters (odometry folded, bursts, held fixes, ...), by name
    counters: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def of(cls, stats: Mapping[str, Any]) -> RunStats:
        """The record of a ``Localizer.stats`` bag (after :meth:`Session.finish`)."""
        named = {f.name for f in fields(cls)} - {"counters"}
        kw = {k: v for k, v in stats.items() if k in named}
        return cls(**kw, counters={k: v for k, v in stats.items() if k not in named})

    def to_dict(self) -> dict[str, Any]:
        """Plain values (YAML / JSON)."""
        out: dict[str, Any] = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "counters"}
        out["sources"] = {k: r.to_dict() for k, r in self.sources.items()}
        out.update(self.counters)
        return out
