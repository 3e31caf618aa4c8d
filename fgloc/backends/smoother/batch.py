"""The batch smoother: the fixed-lag smoother's factors, all kept, optimized over the whole run."""

from __future__ import annotations

from typing import Any

import gtsam
import numpy as np

from fgloc.backends.base import FloatArray
from fgloc.backends.contract import Capability
from fgloc.backends.smoother.config import BatchConfig, SmootherConfig
from fgloc.backends.smoother.sliding_window import SlidingWindowSmoother
from fgloc.types import Trajectory


class BatchSmoother(SlidingWindowSmoother):
    """All factors of the run, optimized at :meth:`finish` by Levenberg-Marquardt."""

    name = "batch"
    #: every factor is kept until the end
    capabilities = SlidingWindowSmoother.capabilities - {Capability.LIVE}

    @classmethod
    def from_config(cls, config: Any = None) -> BatchSmoother:
        """With ``config.smoother`` and ``config.batch``."""
        return cls(None, None) if config is None else cls(config.smoother, config.batch)

    def __init__(self, config: SmootherConfig | None = None, batch: BatchConfig | None = None) -> None:
        self.max_iterations = (batch or BatchConfig()).max_iterations
        self.all_graph: list[gtsam.NonlinearFactor | None] = []
        self.isam_to_all: dict[int, int] = {}
        self.key_t: dict[int, float] = {}
        self.init_vals = gtsam.Values()
        self._pending_register: list[int] = []
        super().__init__(config)

    def initialize(self, t: float, pose: FloatArray, cov: FloatArray | None = None) -> None:
        super().initialize(t, pose, cov)
        # the prior / offset of (re)initialization go into the batch graph too
        g = self.isam.getFactors()
        ballast = set(self._ballast)
        for i in range(g.size()):
            f = g.at(i)
            if f is not None and not ballast.intersection(f.keys()):
                self.all_graph.append(f)
        for key in self.isam.getLinearizationPoint().keys():
            if key not in ballast and not self.init_vals.exists(key):
                self.key_t[key] = t
                c = gtsam.Symbol(key).chr()
                if c == ord("x"):
                    self.init_vals.insert(key, self.isam.calculateEstimatePose2(key))
                elif c == ord("o"):
                    self.init_vals.insert(key, self.isam.calculateEstimatePose2(key))
                else:
                    self.init_vals.insert(key, self.isam.calculateEstimateVector(key))

    def _register(self, graph: gtsam.NonlinearFactorGraph, vals: gtsam.Values, ts: dict) -> None:
        self._pending_register = []
        for i in range(graph.size()):
            self._pending_register.append(len(self.all_graph))
            self.all_graph.append(graph.at(i))
        for key in vals.keys():
            c = gtsam.Symbol(key).chr()
            if c == ord("x"):
                self.init_vals.insert(key, vals.atPose2(key))
            elif c == ord("o"):
                self.init_vals.insert(key, vals.atPose2(key))
            else:
                self.init_vals.insert(key, vals.atVector(key))
            self.key_t[key] = ts.get(key, 0.0)

    def _update(self, graph: gtsam.NonlinearFactorGraph, vals: gtsam.Values, ts: dict,
                remove: list[int] | None = None) -> list[int]:
        idx = super()._update(graph, vals, ts, remove)
        if self._pending_register and len(self._pending_register) == len(idx):
            for a, b in zip(idx, self._pending_register, strict=True):
                self.isam_to_all[a] = b
        self._pending_register = []
        return idx

    def _remove_registered(self, isam_index: int) -> None:
        j = self.isam_to_all.get(isam_index)
        if j is not None:
            self.all_graph[j] = None

    def _after_keyframe(self, t: float) -> None:
        super()._after_keyframe(t)
        # refresh the initial guess with the fixed-lag estimate as keyframes leave the window
        for kk, (_, p) in list(self.smoothed.items())[-4:]:
            if self.init_vals.exists(kk):
                self.init_vals.update(kk, gtsam.Pose2(*p))

    def finish(self) -> Trajectory:
        fl = super().finish()
        for kk, (_, p) in self.smoothed.items():
            if self.init_vals.exists(kk):
                self.init_vals.update(kk, gtsam.Pose2(*p))
        graph = gtsam.NonlinearFactorGraph()
        for f in self.all_graph:
            if f is not None:
                graph.add(f)
        if graph.size() == 0:
            return fl
        params = gtsam.LevenbergMarquardtParams()
        params.setMaxIterations(self.max_iterations)
        try:
            result = gtsam.LevenbergMarquardtOptimizer(graph, self.init_vals, params).optimize()
        except RuntimeError:
            self.stats["batch_failed"] = 1
            return fl
        ts, ps = [], []
        for key, t in self.key_t.items():
            if gtsam.Symbol(key).chr() == ord("x") and result.exists(key):
                rp = result.atPose2(key)
                ts.append(t)
                ps.append([rp.x(), rp.y(), rp.theta()])
        self.stats["batch_error"] = float(graph.error(result))
        return Trajectory.from_unsorted(np.array(ts), np.array(ps))
