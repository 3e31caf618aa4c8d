"""The back-end contract (:mod:`fgloc.backends.contract`) under the import path callers use."""

from __future__ import annotations

from fgloc.backends.contract import Backend, Capability, Estimates, FloatArray, SourceNoise

__all__ = ["Backend", "Capability", "Estimates", "FloatArray", "SourceNoise"]
