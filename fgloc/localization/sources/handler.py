"""What every source handler shares: its state, the skip counting, the message check.

A handler takes the messages of one configured source (:class:`SourceHandler.__call__`):
it counts each, checks its type, and hands it to :meth:`SourceHandler.handle`, which checks
the fields the source uses and passes the result on to the localizer or the back-end.  Bad
input is counted and skipped (:meth:`SourceHandler.skip`, on the source and in the
localizer's summary), never raised.  The handlers of one session share a
:class:`SourceContext`: the localizer, the sensor mounts and the base's tilt.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from fgloc.backends.health import SourceHealth
from fgloc.frames.mounts import MountTable
from fgloc.localization.sources.spec import SourceSpec

if TYPE_CHECKING:
    from fgloc.localization.sources.report import SourceReport


def cov_bad(c: Any) -> bool:
    """A covariance (3x3, or its diagonal) with a NaN / inf / negative variance (scalar checks:
    every odometry message passes here)."""
    if c is None:
        return False
    a = c if isinstance(c, np.ndarray) else np.asarray(c, dtype=float)
    return values_bad(a.ravel().tolist())


def values_bad(d: list[float]) -> bool:
    """:func:`cov_bad` of a covariance's entries as floats (9, row by row, or its diagonal)."""
    if len(d) == 9:
        return not (0.0 <= d[0] < math.inf and 0.0 <= d[4] < math.inf and 0.0 <= d[8] < math.inf)  # NaN too
    return not all(math.isfinite(v) and v >= 0 for v in d)


_F64 = np.dtype(np.float64)


def flat_floats(v: Any) -> np.ndarray:
    """``np.asarray(v, dtype=float).reshape(-1)``, and ``v`` itself when it is a 1-D float64 array
    already (a message's twist or pose as every reader gives it: no conversion per message)."""
    if type(v) is np.ndarray and v.ndim == 1 and v.dtype is _F64:
        return v
    return np.asarray(v, dtype=float).reshape(-1)


@dataclass
class SourceState:
    """One source's running state (its health, the previous message of a differential source)."""

    health: SourceHealth
    prev_pose: tuple[float, np.ndarray] | None = None
    prev_yaw: tuple[float, float] | None = None
    fused: bool = True
    messages: int = 0          # every message routed to the source, whatever became of it
    vy_max: float = 0.0        # the largest |lateral velocity| an odometry's messages reported (m/s)
    extra: dict = field(default_factory=dict)


@dataclass
class SourceContext:
    """What the handlers of one session share: the localizer, the sensors' mounts, and the base's
    roll / pitch from the first levelling IMU (``tilt``: stamp, roll, pitch)."""

    loc: Any
    mounts: MountTable
    tilt: tuple[float, float, float] | None = None
    tilt_source: str | None = None


class SourceHandler:
    """Takes the messages of one source (subclasses: one per source type)."""

    #: the message classes a source of this type takes (others are counted skips)
    accepts: ClassVar[tuple[type, ...]] = ()
    #: the back-ends integrate one twist source and one heading frame: the first source of a
    #: ``group`` is fused as such; a later one is ``second``, fused only when ``second_fused``
    group: ClassVar[str | None] = None
    second_fused: ClassVar[bool] = True

    def __init__(self, spec: SourceSpec, ctx: SourceContext, fused: bool = True, second: bool = False) -> None:
        self.spec = spec
        self.ctx = ctx
        self.loc: Any = ctx.loc  # (the session's localizer: every message reaches it)
        self.state = SourceState(SourceHealth(spec.name, spec.type), fused=fused)
        if second:
            self.state.extra["second"] = True

    def __call__(self, msg: object) -> None:
        st = self.state
        st.messages += 1
        try:
            if isinstance(msg, self.accepts):
                self.handle(msg)
            else:
                self.skip(f"{type(msg).__name__} on a {self.spec.type} source")
        except (ValueError, FloatingPointError, np.linalg.LinAlgError) as e:
            self.skip(f"bad message ({e.__class__.__name__})")

    def handle(self, msg: Any) -> None:
        raise NotImplementedError

    def skip(self, reason: str) -> None:
        """Count a skipped input on its source and in the localizer's summary."""
        h = self.state.health
        h.skip(reason)
        stats = self.loc.stats
        stats["skipped"] = stats.get("skipped", 0) + 1
        r = stats.setdefault("skipped_reasons", {})
        key = f"{h.name}: {reason}"
        r[key] = r.get(key, 0) + 1

    def finish(self) -> None:
        """At the end of the log (a warning left to give)."""

    # ------------------------------------------------------------------ report (report.py)
    def backend_streams(self) -> list[str]:
        """The names the back-end files this source's measurements under (its health, its noise)."""
        return [self.spec.name]

    def reports_noise(self) -> bool:
        """Whether the noise the back-end saw on this source's streams is reported."""
        return True

    def report_estimates(self, r: SourceReport) -> None:
        """Add what the back-end estimated about this source to its report ``r``."""
