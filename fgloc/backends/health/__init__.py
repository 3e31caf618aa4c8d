"""Sensors that check each other: per-source noise from the sources' disagreement, and health.

The back-ends weight each source by the noise it *shows*, not only by what its messages
claim.  :class:`Arbiter` compares the increments several sources give for one quantity (the
yaw change: wheel odometry, gyro, IMU orientation, scan fixes; or the distance driven) over
fixed blocks of time (``block_s``).  A rate source (a yaw rate, a speed) is integrated over
the block, an absolute source (a heading, a position) is differenced across it, so a
compass offset or a map frame never enters.  For every pair of sources ``a, b`` seen in a
block, ``(d_a - d_b)^2`` estimates ``var_a + var_b`` (the two sources' errors are
independent): with three or more sources the pairs determine every source's own variance
(the "N-cornered hat" of clock metrology), so when two disagree, the one the third agrees
with keeps its weight and the other is down-weighted.  With only two sources the excess is
shared in proportion to their priors (claimed noise; ``rel_prior`` for the motion-
proportional part).

Each source's noise is modelled as ``var = k^2 * claimed + c^2 * increment^2``: ``k >= 1``
inflates what the messages claim (estimated on blocks with little motion), ``c`` is a
fraction of the motion (a skid-steer's scrub, a wheel's slip, a gyro's scale error;
estimated on blocks with motion).  Both are exponentially weighted means over the last
``halflife_blocks`` / ``halflife_moving_blocks`` blocks; one block adds at most ``cap``
times the current estimate, so a short genuine disturbance (a +25 deg compass step, 3 s of
wheel slip) moves them little while a persistent disagreement takes over within a minute.
The back-ends still reject short disturbances with their robust kernels and gates.

:class:`SourceHealth` counts each source's accepted, gated and skipped inputs for the run
summary and the live status line (what the back-end estimated about its inputs is
:meth:`fgloc.backends.contract.Backend.estimates`).  Core maths only: no I/O.

Modules: :mod:`.arbiter` (the arbiter) and :mod:`.cornered_hat` (its solver), :mod:`.source_health`,
:mod:`.latency` (the scans' latency), :mod:`.gyro_bias` (a gyro's bias beside the estimator).
"""

from fgloc.backends.health.arbiter import ABSOLUTE, ANGLE_ABSOLUTE, INSTANT_RATE, RATE, Arbiter
from fgloc.backends.health.cornered_hat import cornered_hat
from fgloc.backends.health.gyro_bias import MAX_GYRO_GAP_S, GyroBias
from fgloc.backends.health.latency import LatencyEstimator, bracket, fix_speed
from fgloc.backends.health.source_health import SourceHealth

__all__ = ["ABSOLUTE", "ANGLE_ABSOLUTE", "INSTANT_RATE", "MAX_GYRO_GAP_S", "RATE", "Arbiter", "GyroBias",
           "LatencyEstimator", "SourceHealth", "bracket", "cornered_hat", "fix_speed"]
