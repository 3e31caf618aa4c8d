"""Readers and writers: ROS 2 MCAP logs, CARMEN / ROS 1 bag import, TUM trajectories."""
