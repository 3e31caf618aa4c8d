"""What the jump gate (:mod:`fgloc.localization.gate`) remembers of the fixes it judged: a fix with the
odometry pose at its stamp, and a run of held fixes that follow each other as the odometry says."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

FloatArray = np.ndarray


@dataclass
class FixRecord:
    """A fix the gate judged (the previous one, taken and sure; an anchor; a held one): its pose and
    covariance, the odometry pose and stamp then."""

    pose: FloatArray
    cov: FloatArray
    odom: FloatArray
    t: float


@dataclass
class HeldRun:
    """A run of held fixes that follow each other as the odometry says: the last one, how many, the first's
    stamp and the prediction's position covariance when the first was judged."""

    last: FixRecord
    n: int
    t0: float
    pred_pos_cov: FloatArray


__all__ = ["FixRecord", "HeldRun"]
