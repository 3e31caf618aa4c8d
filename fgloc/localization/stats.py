"""What a run counted, typed: :class:`RunStats` (``fgloc run``'s result, its summary, the batch),
and :class:`LiveCounts` (the counters the view follows while the run goes on).

The localizer counts into ``Localizer.stats`` as it goes (a counter per event, the sources'
reports and the motion model at the end); :meth:`RunStats.of` is that bag after the run as a
record: the counters every summary prints as fields, the per-source reports
(:class:`~fgloc.localization.sources.report.SourceReport`), the back-end's own counters (its
contract's ``stats``), and the localizer's rarer counters by name.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any, NamedTuple

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


class LiveCounts(NamedTuple):
    """The localizer's counters while it runs (``Localizer.stats`` now), for the view: read after
    every scan, so a tuple of the few it shows (:meth:`of` is a handful of lookups)."""

    scans: int = 0
    fixes: int = 0
    no_fix: int = 0
    rejected: int = 0
    global_searches: int = 0
    skipped: int = 0
    relocalizations: int = 0
    odometry_from_poses: int = 0  # odometry twists the tracker replaced by pose increments
    skipped_reasons: Mapping[str, int] = {}  # the live bag's own (not a copy)

    @classmethod
    def of(cls, stats: Mapping[str, Any]) -> LiveCounts:
        """The counters of a ``Localizer.stats`` bag as they are now."""
        g = stats.get  # the counters are ints already: read as they are (after every scan)
        return cls(g("scans", 0), g("fixes", 0), g("no_fix", 0), g("rejected", 0), g("global_searches", 0),
                   g("skipped", 0), g("relocalizations", 0), g("odometry_from_poses", 0), g("skipped_reasons") or {})
