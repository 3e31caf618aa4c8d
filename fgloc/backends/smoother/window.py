"""The fixed-lag window on ``gtsam.IncrementalFixedLagSmoother``: updates (with the inert ballast that
keeps iSAM2's re-elimination incremental), the keyframes leaving the window (their smoothed value),
the marginal covariance, and the restart after a solver failure."""

from __future__ import annotations

import math
from bisect import bisect_right
from collections import deque
from collections.abc import Iterator

import gtsam
import numpy as np

from fgloc.backends.base import FloatArray
from fgloc.backends.smoother.calibration import Calibration
from fgloc.backends.smoother.covariance import RESTART_VAR_MAX
from fgloc.backends.smoother.keys import BALLAST, X, symbol

_ZERO1 = np.zeros(1)


_UNIT1 = gtsam.noiseModel.Isotropic.Sigma(1, 1.0)


class FixedLagWindow(Calibration):
    """iSAM2's window: updates, marginalization, outputs of the solved keyframes."""

    def _new_x(self, t: float) -> int:
        k = X(self.next_x)
        self.next_x += 1
        return k

    def _update(self, graph: gtsam.NonlinearFactorGraph, vals: gtsam.Values, ts: dict,
                remove: list[int] | None = None) -> list[int]:
        tsm = gtsam.FixedLagSmootherKeyTimestampMap()
        stamp = self._window_stamp
        for k, t in ts.items():
            tsm.insert((k, stamp(t)))
        if ts:
            t_new = max(ts.values())
            self._capture_leaving(t_new)
            self._t_latest = t_new if t_new > self._t_latest else self._t_latest
        self._stamp_chains(ts, tsm)
        n = graph.size()
        graph, vals = self._with_ballast(graph, vals, tsm)
        self.isam.update(graph, vals, tsm, remove or [])
        return list(self.isam.getISAM2Result().getNewFactorsIndices())[:n]

    def _window_stamp(self, t: float) -> float:
        """The stamp iSAM2's window keeps a variable of time ``t`` by: ``t`` rounded up to a multiple of
        ``marginalize_every_s``, so that the variables leave the window in groups, one update in
        that many seconds (an update that marginalizes re-eliminates the window from its oldest
        variables to the root; the others only the newest cliques).  Rounded up, and the window's
        clock with them, a variable leaves no earlier than ``lag_s`` after its time (its smoothed
        value is taken then, :meth:`_capture_leaving`) and at most ``marginalize_every_s`` later."""
        q = self.cfg.marginalize_every_s
        return math.ceil(t / q) * q if q > 0.0 else t

    def _stamp_chains(self, ts: dict, tsm: gtsam.FixedLagSmootherKeyTimestampMap) -> None:
        """Keep each calibration chain's current variable in the window while its factors pause
        (a visual odometer's gap, a gyro that stopped): stamped anew every half lag.  Left to leave
        the window, it was marginalized, and the chain's next factor named a variable iSAM2 no
        longer had (``timestamp supplied for key 'a125', but no value exists``)."""
        t = self._t_latest
        if not math.isfinite(t):
            return
        for ch in self.chains.values():
            if ch.key is None:
                continue
            if ch.key in ts:
                ch.stamped = max(ch.stamped, float(ts[ch.key]))
            elif t - ch.stamped > 0.5 * self.cfg.lag_s:
                tsm.insert((ch.key, self._window_stamp(t)))
                ch.stamped = t

    def _with_ballast(self, graph: gtsam.NonlinearFactorGraph, vals: gtsam.Values,
                      tsm: gtsam.FixedLagSmootherKeyTimestampMap) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values]:
        """The update's factors and values with enough inert variables in iSAM2 (``z<j>``: a
        ``Vector1`` each, under its own prior, tied to nothing, kept in the window) that its
        re-elimination stays incremental.

        iSAM2 re-eliminates in batch, relinearizing every factor of the window, whenever the
        variables an update affects reach 65 % of all it holds (GTSAM's fixed ``batchThreshold``).
        The fixed-lag marginalization marks the path from the oldest keyframe to the root at
        every update that marginalizes, so on a small window those updates would go batch, relinearizing factors whose
        variables have not moved, which give the cached linear factors again (a factor's
        linearization depends on its variables' linearization points only).  With at least 0.6
        inert variables per live one the affected share stays below 0.65: the same linear
        systems, solved incrementally (results equal to rounding; the inert ones never move, so
        they are never relinearized)."""
        live = self.isam.getLinearizationPoint().size() - len(self._ballast) + vals.size()
        want = int(0.6 * live) + 2
        if len(self._ballast) < want:
            graph, vals = gtsam.NonlinearFactorGraph(graph), gtsam.Values(vals)
            for _ in range(want - len(self._ballast)):
                n = self._next_sym.get(BALLAST, 0)
                self._next_sym[BALLAST] = n + 1
                k = symbol(BALLAST, n)
                graph.add(gtsam.PriorFactorVector(k, _ZERO1, _UNIT1))
                vals.insert(k, _ZERO1)
                self._ballast.append(k)
        t = self._t_latest if math.isfinite(self._t_latest) else 0.0
        if t - self._ballast_t > 0.5 * self.cfg.lag_s or len(self._ballast) > self._ballast_n:
            # stamped anew every half lag (new ones at once): they stay in the window, never among the
            # keys the update marginalizes, and every key keeps its ordering group (GTSAM puts every
            # stamped key in group 1 whatever its stamp), so the same update as stamping them every time
            tb = self._window_stamp(t)
            for k in self._ballast:
                tsm.insert((k, tb))
            self._ballast_t, self._ballast_n = t, len(self._ballast)
        return graph, vals

    def _flush_acc(self) -> None:
        """Hand the accumulated keyframes' factors to iSAM2 (one update)."""
        if self._acc is None:
            return
        graph, vals, ts, pairs, keys = self._acc
        self._acc = None
        self._register(graph, vals, ts)
        try:
            idx = self._update(graph, vals, ts)
        except RuntimeError:
            self._restart_after_failure(keys)
            return
        for pair, pos in pairs:
            self.between_idx[pair] = idx[pos]
        self._refresh_chains()
        for kk in keys[:-1]:
            p = self.isam.calculateEstimatePose2(kk)
            self.kf_pose[kk] = np.array([p.x(), p.y(), p.theta()])
        self._after_keyframe(self.kf_t[-1])

    def _restart_after_failure(self, drop: list[int]) -> None:
        """GTSAM found the system ill-conditioned (e.g. ``Indeterminate linear system`` on degenerate
        input): counted, and the smoother restarts at the newest keyframe's prediction with the
        last marginal as its prior (bounded, :data:`RESTART_VAR_MAX`); the keyframes in ``drop``
        (not solved) leave the window."""
        self.stats["solver_failures"] = self.stats.get("solver_failures", 0) + 1
        t_last, k_last = self.kf_t[-1], self.kf_key[-1]
        pose = self.kf_pose.get(k_last)
        if pose is None or not np.all(np.isfinite(pose)):
            pose = next((p for _, p in sorted(self.smoothed.values(), key=lambda v: -v[0])
                         if np.all(np.isfinite(p))), np.zeros(3))
        self.window = deque(w for w in self.window if w[1] not in drop)
        self.initialize(t_last, np.array(pose, dtype=float), np.diag(np.minimum(
            np.abs(np.diag(self._last_cov)), RESTART_VAR_MAX)))

    def _register(self, graph: gtsam.NonlinearFactorGraph, vals: gtsam.Values, ts: dict) -> None:
        """Hook for the batch smoother (keeps a copy of every factor)."""

    def _after_keyframe(self, t: float) -> None:
        k = self.kf_key[-1]
        pose = self.isam.calculateEstimatePose2(k)
        self.kf_pose[k] = np.array([pose.x(), pose.y(), pose.theta()])
        self._cov_stale = k
        if self.cfg.online_covariance:
            self._update_covariance()
        self.stats["keyframes"] += 1
        self._record_online(t, self.kf_pose[k], self._last_cov)
        self._check_heading(t, float(self.kf_pose[k][2]))

    def _check_heading(self, t: float, yaw: float) -> None:
        """Hand the solved keyframe's heading and what its sources said to :attr:`heading_check`."""
        incs, absolute = self._heading_inputs
        if not incs and not absolute:
            return
        self.heading_check.add(t, yaw, incs, absolute)
        self._heading_inputs = ({}, {})
        hc = self.heading_check
        self.stats["heading_diverged_s"] = round(hc.diverged_total_s(t), 3)
        self.stats["heading_divergence_spans"] = hc.spans
        if hc.worst is not None:
            self.stats["heading_divergence_worst_deg"] = round(abs(hc.worst.off_deg), 2)

    def _capture_leaving(self, t_new: float) -> None:
        """Record the keyframes the next update will marginalize (their final smoothed value)."""
        horizon = t_new - self.cfg.lag_s + 1e-6
        while self.window and self.window[0][0] < horizon:
            tk, kk = self.window.popleft()
            try:
                p = self.isam.calculateEstimatePose2(kk)
                self.smoothed[kk] = (tk, np.array([p.x(), p.y(), p.theta()]))
            except (RuntimeError, IndexError):
                if kk in self.kf_pose:
                    self.smoothed[kk] = (tk, self.kf_pose[kk].copy())
            self.kf_pose.pop(kk, None)
        h = self.history_s
        if h is not None and self.kf_t and t_new - self.kf_t[0] > 2.0 * h:
            self._forget_before(t_new - h)

    def _forget_before(self, t: float) -> None:
        """Drop what a bounded history (``history_s``) no longer keeps: the smoothed keyframes, the
        keyframe times and keys, the between-factor indices from before ``t`` (never the window's)."""
        if self.window:
            t = min(t, self.window[0][0])
        k = bisect_right(self.kf_t, t) - 1  # keep the keyframe before t: an interval needs both ends
        if k <= 0:
            return
        gone = set(self.kf_key[:k])
        del self.kf_t[:k], self.kf_key[:k]
        self.smoothed = {kk: v for kk, v in self.smoothed.items() if v[0] >= t}
        self.between_idx = {pair: i for pair, i in self.between_idx.items() if pair[0] not in gone}

    def _remove_registered(self, isam_index: int) -> None:
        """Hook for the batch smoother."""

    def _update_covariance(self) -> None:
        """Marginal covariance of the newest solved keyframe, rotated into the map frame."""
        k = self._cov_stale
        if k is None or k not in self.kf_pose:
            return
        self._cov_stale = None
        self._pred_cache = None
        try:
            body = np.asarray(self.isam.marginalCovariance(k))
        except (RuntimeError, IndexError):
            return
        c, s_ = math.cos(self.kf_pose[k][2]), math.sin(self.kf_pose[k][2])
        R = np.fromiter((c, -s_, 0.0, s_, c, 0.0, 0.0, 0.0, 1.0), float, 9).reshape(3, 3)
        self._last_cov = R @ body @ R.T

    def current(self, covariance: bool = True) -> tuple[float, FloatArray, FloatArray] | None:
        """Newest keyframe estimate; its covariance is computed here on demand (iSAM2 marginal;
        ``covariance=False``: the last one computed)."""
        if not self.kf_key:
            return None
        if covariance:
            self._update_covariance()
        return self.kf_t[-1], self.kf_pose[self.kf_key[-1]].copy(), self._last_cov.copy()

    def _flush_window(self) -> None:
        for tk, kk in self.window:
            try:
                p = self.isam.calculateEstimatePose2(kk)
            except (RuntimeError, IndexError):
                continue
            self.smoothed[kk] = (tk, np.array([p.x(), p.y(), p.theta()]))
        self.window.clear()

    def _covered_intervals(self, t_now: float, done: float,
                           last_t: float) -> Iterator[tuple[float, float, int, int]]:
        """The keyframe intervals ``(ta, tb, ka, kb)`` a source's readings up to ``last_t`` now cover and
        that have no factor of it yet: starting at a keyframe >= ``done`` (the end of its last interval)
        and inside the window (never on a keyframe about to be marginalized)."""
        horizon = t_now - self.cfg.lag_s + 0.25
        i = bisect_right(self.kf_t, (horizon if horizon > done else done) - 1e-9)   # max(..., 1) as conditionals
        i = 1 if 1 > i else i
        while i < len(self.kf_t):
            ta, tb = self.kf_t[i - 1], self.kf_t[i]
            if tb > last_t + 1e-9:
                return
            ka, kb = self.kf_key[i - 1], self.kf_key[i]
            i += 1
            if ta < done - 1e-9 or ta < horizon or ka not in self.kf_pose or kb not in self.kf_pose:
                continue
            yield ta, tb, ka, kb
