"""Frames and mounts, one home: where each sensor is on the robot.

* :mod:`fgloc.frames.tf` - tf frame names (:func:`~fgloc.frames.tf.frame_name`, the robot's own
  :data:`~fgloc.frames.tf.BASE_FRAMES`), a log's tf chains to the laser
  (:class:`~fgloc.frames.tf.TfTree`, upside-down links), a user's laser mount as a level or
  upside-down 2-D mount (:func:`~fgloc.frames.tf.planar_mount`);
* :mod:`fgloc.frames.static` - static transforms a user gives (``sources.static_transforms``,
  ``--static-transform``, a launch file's ``static_transform_publisher``): parsed and checked;
* :mod:`fgloc.frames.mounts` - :class:`~fgloc.frames.mounts.MountTable`: the sensors' mounts a
  session looks up: the transform chain from the robot's base frame (REP 105: ``sources.base_frame``,
  else the odometry's ``child_frame_id``, else ``base_link`` / ``base_footprint``) to a sensor's
  frame, through the configured links and the log's tf, either way round;
* :mod:`fgloc.frames.imu` - a ``sensor_msgs/Imu`` through its mount into ``base_link`` (REP 145),
  the mount's rotation.

Bottom layer (like :mod:`fgloc.geometry`): every other package may import it.  The command-line
options that give a mount (their help texts and option-named errors) are in
:mod:`fgloc.app.mounts`.
"""
