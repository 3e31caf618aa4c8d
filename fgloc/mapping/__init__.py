"""Offline 2-D SLAM: build map_server maps and trajectories from logged scans and odometry."""

from fgloc.mapping.slam import GraphSlam, MapperConfig, SlamResult, build_occupancy, run_slam

__all__ = ["GraphSlam", "MapperConfig", "SlamResult", "build_occupancy", "run_slam"]
