"""Trajectory evaluation: the paper's error metrics, APE/RPE, plots and the comparison table.

* :mod:`fgloc.eval.metrics` -- :func:`associate`, :func:`evaluate` -> :class:`Metrics`,
  :func:`error_series`, :func:`align_se2` (pure maths, no I/O).
* :mod:`fgloc.eval.plots` -- PNG figures like the paper's figures 6-10 (:func:`plot_all`).
* :mod:`fgloc.eval.paper` -- the paper's reported numbers and :func:`comparison_table`.
* :mod:`fgloc.eval.relations` -- the relations metric (Kuemmerle et al. 2009).
* :mod:`fgloc.eval.nees` -- :func:`~fgloc.eval.nees.evaluate_nees`: how honest per-pose covariances are.
* :mod:`fgloc.eval.checks` -- notes on what the numbers may hide (a sparse reference, two frames), the
  start alignment of two odometry frames.

Only the metrics are imported here so that ``import fgloc.eval`` stays cheap (no matplotlib).
"""

from fgloc.eval.metrics import (
    Association,
    AssociationError,
    ErrorSeries,
    Metrics,
    align_se2,
    associate,
    error_series,
    evaluate,
)

__all__ = [
    "Association",
    "AssociationError",
    "ErrorSeries",
    "Metrics",
    "align_se2",
    "associate",
    "error_series",
    "evaluate",
]
