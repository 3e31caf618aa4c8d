"""One source, checked: :class:`SourceSpec`, and what a source type declares (:class:`SourceType`).

The components are robot_localization's 15-element vector reduced to the planar six
(:data:`COMPONENTS`); an IMU may add its attitude (:data:`TILT`: roll, pitch), which levels the
odometry.  The covariance policies (:data:`POLICIES`) say how a message's covariance becomes
the variance fused: ``message`` (as the message says), ``fixed`` (``sigmas``, one per used
component), ``scaled`` (the message's times ``scale^2``), ``floor`` (the message's, at least
``sigmas^2``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

COMPONENTS = ("x", "y", "yaw", "vx", "vy", "vyaw")
TILT = ("roll", "pitch")   # an IMU's attitude: levels the odometry (not estimated)
POLICIES = ("message", "fixed", "scaled", "floor")
UNUSED_VAR = 1e6   # a component a source does not contribute: its variance
#: a differential source's message stamped before the previous one: skipped, so that the next
#: increment spans from the newest pose (none is lost)
OUT_OF_ORDER = "differential: stamp not after the previous message's (out of order)"


@dataclass(frozen=True)
class SourceType:
    """What a source type declares: its name in ``sources.inputs.NAME.type``, the ROS message it
    reads (as :func:`fgloc.io.topics.normalize_type` spells it), its default topic and ``use``,
    the components it may use, the handler class that takes its messages
    (:class:`~fgloc.localization.sources.handler.SourceHandler`), and whether its messages have
    poses whose increments ``differential`` can use."""

    name: str
    message_type: str
    default_topic: str
    default_use: tuple[str, ...]
    components: tuple[str, ...]
    handler: Any  # type[SourceHandler]
    differential: bool = True


@dataclass
class SourceSpec:
    """One input source, checked."""

    name: str
    type: str
    topic: str
    use: tuple[str, ...]
    differential: bool = False
    covariance: str = "message"
    sigmas: tuple[float, ...] = ()
    scale: float = 1.0
    gate: float | None = None
    frame_id: str | None = None

    def uses(self, comp: str) -> bool:
        return comp in self.use

    @property
    def fused(self) -> tuple[str, ...]:
        """The used components the back-end fuses (``use`` without an IMU's levelling roll, pitch),
        in order: one sigma each for the ``fixed`` / ``floor`` policies."""
        return fused_components(self.use)

    def variance(self, comp: str, msg_var: float) -> float:
        """The variance of ``comp`` under the source's covariance policy (NaN: the back-end default)."""
        if not self.uses(comp):
            return UNUSED_VAR
        pol = self.covariance
        if pol == "fixed":
            return self.sigmas[self.fused.index(comp)] ** 2
        if pol == "scaled":
            return msg_var * self.scale**2 if math.isfinite(msg_var) else msg_var
        if pol == "floor":
            s2 = self.sigmas[self.fused.index(comp)] ** 2
            return max(msg_var, s2) if math.isfinite(msg_var) else s2
        return msg_var


def fused_components(use: Sequence[str]) -> tuple[str, ...]:
    return tuple(u for u in use if u in COMPONENTS)
