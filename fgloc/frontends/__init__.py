"""Scan-to-map front-ends: a scan + a prior guess -> a map-frame pose with covariance.

``native`` (numba Gauss-Newton on the map's distance field after a correlative
search), ``kiss`` (kiss_icp registration against the map as a static voxel map) and
``amcl`` (particle filter, :mod:`fgloc.frontends.amcl`).  Build one with
:func:`make_frontend` from its typed config section (:class:`FrontendsConfig`).
A front-end declares what the localizer needs to know about it
(:attr:`FrontendBase.is_particle_filter`, :attr:`FrontendBase.supports_global`).
"""

from .amcl import AMCLConfig
from .base import FrontendBase, MatchResult, PreprocessOptions, ScanMatcher, ScanPreprocessor, no_fix
from .factory import FRONTENDS, FrontendsConfig, canonical_name, make_frontend
from .kiss import KissConfig
from .native import NativeConfig

__all__ = [
    "AMCLConfig",
    "FRONTENDS",
    "FrontendBase",
    "FrontendsConfig",
    "KissConfig",
    "MatchResult",
    "NativeConfig",
    "PreprocessOptions",
    "ScanMatcher",
    "ScanPreprocessor",
    "canonical_name",
    "make_frontend",
    "no_fix",
]
