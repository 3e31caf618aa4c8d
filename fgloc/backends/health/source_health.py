"""What one input source did during a run (:class:`SourceHealth`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


@dataclass
class SourceHealth:
    """What one input source did during a run: accepted, gated, skipped (with the reasons)."""

    name: str
    kind: str
    accepted: int = 0
    gated: int = 0
    skipped: int = 0
    skipped_reasons: dict[str, int] = field(default_factory=dict)

    def skip(self, reason: str) -> None:
        self.skipped += 1
        self.skipped_reasons[reason] = self.skipped_reasons.get(reason, 0) + 1

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"kind": self.kind, "accepted": self.accepted, "gated": self.gated,
                               "skipped": self.skipped}
        if self.skipped_reasons:
            out["skipped_reasons"] = dict(self.skipped_reasons)
        return out
