"""Scan-to-map front-ends: a scan + a prior guess -> a map-frame pose with covariance.

``native`` (numba Gauss-Newton on the map's distance field after a correlative
search), ``kiss`` (kiss_icp registration against the map as a static voxel map) and
``amcl`` (particle filter, :mod:`fgloc.frontends.amcl`).  Build one with
:func:`make_frontend`.
"""

from .base import FrontendBase, MatchResult, PreprocessOptions, ScanMatcher, ScanPreprocessor, no_fix
from .factory import load_frontends_config, make_frontend

__all__ = [
    "FrontendBase",
    "MatchResult",
    "PreprocessOptions",
    "ScanMatcher",
    "ScanPreprocessor",
    "load_frontends_config",
    "make_frontend",
    "no_fix",
]
