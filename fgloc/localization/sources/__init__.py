"""Per-source inputs, robot_localization style: which topic is what, what each contributes.

The ``sources:`` config section lists input sources by name (``inputs:``); empty, the
default layout is used: ``odom`` (``nav_msgs/Odometry`` on ``/odom``: vx, vy, vyaw) and
``imu`` (``sensor_msgs/Imu`` on ``/imu``: yaw, vyaw, and roll, pitch to level the odometry where
its orientation carries them: ``sources.level_by_imu``), the paper robot's layout.  Each source::

    inputs:
      wheels:   {type: odometry, topic: /husky_velocity_controller/odom, use: [vx, vyaw]}
      imu:      {type: imu, topic: /imu/data, use: [yaw, vyaw], covariance: floor, sigmas: [0.01, 0.005]}
      mocap:    {type: pose, topic: /vicon/pose, use: [x, y, yaw], frame_id: map, gate: 16.3}

``type``: ``odometry`` | ``imu`` | ``pose`` (``geometry_msgs/PoseWithCovarianceStamped``).
``use``: a subset of ``x, y, yaw, vx, vy, vyaw`` (robot_localization's 15-element vector
reduced to the planar six); an IMU may add ``roll, pitch``: its attitude then levels the
odometry (the body velocity projected onto the ground plane, as robot_localization does in
3-D: a robot climbing a 10 deg slope drives 1.5 % less in the plane than its wheels say) and
its yaw rate is the heading's rate ``(sin(roll) w_y + cos(roll) w_z) / cos(pitch)``.  A tilt
beyond 30 deg (no ground robot's: a wrong mount) or a roll / pitch variance that says "not
estimated" (beyond that bound's square) is not used, and counted.
``differential``: use the increments of the source's poses
(odometry: as a twist; an IMU's orientation: as a yaw rate).  ``covariance``: ``message``
(as the message says), ``fixed`` (``sigmas``, one per used component), ``scaled`` (the
message's times ``scale^2``) or ``floor`` (the message's, at least ``sigmas^2``).  ``gate``:
a Mahalanobis (squared) gate against the prediction (pose sources).  ``frame_id``: the frame a
pose source must be in.  The scan-to-map front-end is always a source (``scan``).

An IMU is rotated into ``base_link`` through its mount (``/tf_static`` ``base_link ->
header.frame_id``; :mod:`.imu`, the maths in :mod:`fgloc.frames.imu`): any 3-D mount when the message is a whole
:class:`~fgloc.types.Imu` (every log reader gives one) and the transform a
:class:`~fgloc.types.Transform3D` (every log reader's tf, and ``static_transforms``); with a
planar transform or a yaw-only reading (:class:`~fgloc.types.CompassHeading`: fgloc's serial
link, the paper simulator), the yaw mount is undone.  A frame without a transform is identity,
with one warning once :data:`MOUNT_WAIT_S` of its stamps passed without one (a ROS 2 recorder
logs ``/tf_static`` after the first IMU messages; a mount that arrives is applied from then on and
the summary says after how many).  A configured source (``sources.inputs``) that gets no message
in the whole log is a warning at the end (:meth:`SourceRouter.silent_sources`).

The package: :mod:`.config` (the section, :func:`parse_sources`, the source types),
:mod:`.spec` (a checked source, the covariance policies), one handler module per source type
(:mod:`.odometry`, :mod:`.imu`, :mod:`.pose`) on :mod:`.handler`'s base, :mod:`.router` (the
handlers of a session: what the session routes to them) and :mod:`.report` (per-source health
with the back-end's estimates, the summary and status lines).  To add a source type: a module
with its :class:`~fgloc.localization.sources.spec.SourceType` and handler, one entry in
:data:`~fgloc.localization.sources.config.SOURCE_TYPES`.

Bad input is counted and skipped, never raised: an IMU quaternion of zeros or not of unit
length, a covariance with a NaN or negative diagonal (each only when the source uses that
field: a gyro-only source's zero quaternion is not a fault), a pose in another frame than the
one configured.  :meth:`SourceRouter.health` (and ``Localizer.stats['sources']`` after the run)
reports per source: accepted / gated / skipped counts with reasons, the estimated scale,
bias and latency, and the noise it showed against what its messages claimed;
:func:`status_line` is the one-line form for a live display.
"""

from fgloc.localization.sources.config import SOURCE_TYPES, SourcesConfig, parse_sources, source_topics
from fgloc.localization.sources.odometry import differential_cov
from fgloc.localization.sources.report import status_line, summary_lines
from fgloc.localization.sources.router import SourceRouter
from fgloc.localization.sources.spec import COMPONENTS, OUT_OF_ORDER, TILT, UNUSED_VAR, SourceSpec, fused_components

__all__ = ["COMPONENTS", "OUT_OF_ORDER", "SOURCE_TYPES", "TILT", "UNUSED_VAR", "SourceRouter", "SourceSpec",
           "SourcesConfig", "differential_cov", "fused_components", "parse_sources",
           "source_topics", "status_line", "summary_lines"]
