"""Sliding-window smoother on ``gtsam.IncrementalFixedLagSmoother`` and its batch twin.

Graph (variables ``x<i>``: ``Pose2`` keyframes at scan times; ``o<j>``: the compass-to-map
offset, one per ``offset_interval`` seconds, ``compass_yaw = map_yaw + offset``, as the compass
frame's pose in the map ``Pose2(0, 0, -offset)``, so that every factor on it is a C++ one):

* encoder twist factors ``x<i-1> - x<i>``: the odometry twists between the two keyframes
  integrated with propagated covariance (:func:`~fgloc.backends.factors.integrate_twist`),
  a C++ ``BetweenFactorPose2``;
* compass factors ``x<i> - o<j>``: the compass readings since the previous keyframe, each
  carried to the keyframe time by the odometry rotation in between and averaged, a
  ``BetweenFactorPose2`` measuring the heading only (:func:`~fgloc.backends.factors.compass_factor`)
  with a robust kernel;
* offset random walk ``o<j-1> - o<j>``: ``BetweenFactorPose2`` with heading sigma
  ``offset_rw_sigma * sqrt(dt)``;
* scan-to-map fixes on ``x<i>``: robust (Huber) ``PriorFactorPose2`` with the front-end
  covariance, after a coarse gate against the prediction (``fix_gate_m``, ``fix_gate_theta``;
  an optional Mahalanobis gate ``fix_gate``).  The gate is deliberately loose: a tight gate
  against an odometry prediction locks out the good fixes once the wheels slip; the robust
  kernel bounds the pull of a wrong fix instead.  After ``max_rejections`` in a row the
  back-end is reset to the fix (the pipeline normally relocalizes first).  (The measurements
  behind the loose gate and the Huber kernel: docs/results/fusion.md, "Design evidence".)
* the compass factors use a Cauchy kernel (redescending): a magnetic disturbance of tens of
  degrees is ignored rather than averaged in.
* gyro yaw-increment factors ``x<i-1> - x<i>``: the gyro integrated between the keyframes, its
  bias estimated beside the graph from absolute headings and standstill (the default,
  :class:`~fgloc.backends.health.GyroBias`, as the EKF) or, with ``gyro_bias_in_graph``, a graph
  variable (every yaw source, the wheels too, informs it there: a placeholder yaw rate 0 pulls
  it); where the gyro covers a keyframe interval the
  odometry's translation is integrated along its heading, the wheels' yaw-rate scale (``k<j>``)
  and speed scale (``g<j>``) are calibration variables.

A scan older than the newest keyframe but inside the window (late measurement) gets its own
keyframe at its own stamp: the twist factor spanning it is removed and replaced by two.
A keyframe waits (at most ``max_wait`` s) for the odometry that covers its stamp, so
odometry arriving after the scan is still integrated exactly.  Compass readings are
carried to the next keyframe's stamp by the odometry rotation in between (a late one
from further back too), so each reading counts at its own time.

``SlidingWindowSmoother`` is the online fixed-lag estimator; the online estimate is the
newest keyframe right after its update, the smoothed trajectory is each keyframe's estimate
as it leaves the window (i.e. smoothed over ``lag`` seconds of later data).
``BatchSmoother`` runs the same estimator online and keeps every factor; ``finish`` then
optimizes the whole run with Levenberg-Marquardt, initialized from the fixed-lag estimates.

The code, one module per responsibility, each a layer of the one class built on those before it:

==================  ==================================================================
``config``          the ``smoother:`` / ``batch:`` sections
``keys``            the variables' GTSAM keys
``covariance``      priors, bounded variances, a covariance carried along an increment
``state``           what the smoother keeps; per-source health and noise bookkeeping
``streams``         the sensor buffers queried between two stamps (integrals, rates)
``calibration``     calibration chains, compass-offset variables, the latency estimate
``window``          iSAM2's fixed-lag window: updates, marginalization, restarts
``further``         factors of differential orientations and further twist sources
``keyframes``       each keyframe's factors (odometry, compass, fix, gyro), late scans
``sliding_window``  :class:`SlidingWindowSmoother`: start, inputs, prediction, outputs
``batch``           :class:`BatchSmoother`: every factor kept, optimized at the end
==================  ==================================================================
"""

from fgloc.backends.smoother.batch import BatchSmoother
from fgloc.backends.smoother.config import BatchConfig, SmootherConfig
from fgloc.backends.smoother.covariance import carried_covariance, prior_covariance
from fgloc.backends.smoother.sliding_window import SlidingWindowSmoother

__all__ = ["BatchConfig", "BatchSmoother", "SlidingWindowSmoother", "SmootherConfig", "carried_covariance",
           "prior_covariance"]
