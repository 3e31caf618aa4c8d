"""A differential orientation source in the EKF (robot_localization's ``imuN_differential``):
``z = theta + c`` with the source's own offset ``c`` a state, anchored at its first reading.

Gating tells two failures apart by how the innovation got past the gate:

* it **jumped** from one reading to the next by more than the gate's width: the source was
  re-initialized (an AHRS reset) or a reading is an outlier. The reading is gated; after
  ``recover_after`` gated in a row the offset is re-anchored (the source's new frame);
* it **crept** there reading by reading: the filter's heading drifted while the source's increments
  stayed smooth (a wheel yaw rate that lies: a skid steer's scrub reports 1.4-2.5x the turn). The
  heading is re-opened to the source at once, as a compass's is: waiting would let the drift run
  away (every later reading gated) and a re-anchor would then keep it for good.
"""

from __future__ import annotations

import math

import numpy as np

from fgloc.backends.ekf import EKF, TH
from fgloc.geometry import wrap_scalar

ANCHORED, REOPENED, USED, GATED = "anchored", "reopened", "used", "gated"


def jumped(innov: float, prev: float, width: float) -> bool:
    """Whether an innovation got past a gate of ``width`` (rad) by a jump from the previous one
    (a re-initialized source, an outlier) rather than by creeping there reading by reading."""
    return abs(wrap_scalar(innov - prev)) > width


class RelativeYaw:
    """One differential orientation source's offset state and gating in an :class:`EKF`."""

    def __init__(self, key: str, q: float, gate: float | None, recover_after: int) -> None:
        self.key = key
        self.q = q
        self.gate = gate
        self.recover_after = recover_after
        self.gated_run = 0
        self.innov: float | None = None   # the last reading's innovation (before its update)
        self.jumped = True                # whether the current gated run began with a jump

    def first(self, ekf: EKF, yaw: float, var: float) -> str:
        """Apply a reading (the filter predicted to its stamp); returns what was applied."""
        i = ekf.aug.get(self.key)
        if i is None or self.gated_run >= self.recover_after:
            self.anchor(ekf, yaw, var)
            self.gated_run = 0
            self.innov = 0.0
            return ANCHORED
        P = ekf.P
        innov = wrap_scalar(yaw - float(ekf.x[TH]) - float(ekf.x[i]))
        s = float(P[TH, TH] + P[i, i] + 2.0 * P[TH, i]) + var
        prev = innov if self.innov is None else self.innov
        self.innov = innov
        if self.update(ekf, yaw, var, self.gate):
            self.gated_run = 0
            return USED
        if self.gated_run == 0:
            self.jumped = jumped(innov, prev, math.sqrt((self.gate or 0.0) * max(s, 0.0)))
            if not self.jumped:
                self.reopen(ekf, yaw, var)
                self.update(ekf, yaw, var, None)
                return REOPENED
        self.gated_run += 1
        return GATED

    def again(self, ekf: EKF, how: str, yaw: float, var: float) -> None:
        """Apply a reading again as :meth:`first` decided (the filter replayed to its stamp)."""
        if how == ANCHORED:
            self.anchor(ekf, yaw, var)
        elif how == REOPENED:
            self.reopen(ekf, yaw, var)
            self.update(ekf, yaw, var, None)
        elif how == USED:
            self.update(ekf, yaw, var, None)

    def anchor(self, ekf: EKF, yaw: float, var: float) -> None:
        """``c = z - theta``: correlated with the heading (and through it with the rest)."""
        i = ekf.add_state(self.key, 0.0, 1.0, self.q)
        P = ekf.P
        P[i, :] = -P[TH, :]
        P[:, i] = -P[:, TH]
        P[i, i] = P[TH, TH] + var
        ekf.x[i] = wrap_scalar(yaw - float(ekf.x[TH]))

    def update(self, ekf: EKF, yaw: float, var: float, gate: float | None) -> bool:
        i = ekf.aug[self.key]
        H = np.zeros((1, ekf.n))
        H[0, TH] = 1.0
        H[0, i] = 1.0
        hx = np.array([float(ekf.x[TH]) + float(ekf.x[i])])
        if ekf.update_h(np.array([yaw]), hx, H, np.array([[var]]), gate, "relative_yaw", (0,)):
            ekf.x[i] = wrap_scalar(float(ekf.x[i]))
            return True
        return False

    def reopen(self, ekf: EKF, yaw: float, var: float) -> None:
        """The heading's variance at least the innovation squared plus ``var``."""
        innov = wrap_scalar(yaw - float(ekf.x[TH]) - float(ekf.x[ekf.aug[self.key]]))
        ekf.P[TH, TH] = max(ekf.P[TH, TH], innov * innov + var)
