"""Calibration variables: the chains (slowly varying ``Vector`` variables tied by a random walk: the
odometry's speed and yaw-rate scales, a gyro's bias in the graph, a differential orientation's
offset, a further twist source's alignment), the compass-to-map offset variables ``o<j>`` and
the scans' latency estimate."""

from __future__ import annotations

import math

import gtsam
import numpy as np

from fgloc.backends.base import FloatArray
from fgloc.backends.factors import offset_pose, pose_offset, scaled_delta_values
from fgloc.backends.smoother.keys import O, symbol
from fgloc.backends.smoother.state import Chain
from fgloc.backends.smoother.streams import Streams
from fgloc.geometry import wrap_angle

#: m, the prior / random-walk sigma of a compass-offset variable's position (always 0: it enters
#: no other factor, any sigma holds it there; see factors.compass_factor)
OFFSET_XY_SIGMA = 1.0


class Calibration(Streams):
    """The calibration variables and estimates."""

    def set_compass_offset(self, offset: float) -> None:
        self.calib.offset = float(offset)
        self.offset_declared = True

    def _offset_held(self) -> bool:
        """The compass-to-map offset is the declared one (:meth:`set_compass_offset`: the frame is
        the compass's, as in odometry-frame runs) and nothing but the compass observes it (no fix
        yet): the compass factors measure the heading itself, as the EKF's compass updates do.
        Estimated instead, the offset would be fitted to the first keyframes' prior (one compass
        reading) and to the relative sources' integral from there."""
        return self.offset_declared and self.stats["fixes_used"] == 0

    def _chain(self, name: str, char: str, mean: list[float], sigma: list[float], rw: list[float]) -> Chain:
        ch = self.chains.get(name)
        if ch is None:
            ch = self.chains[name] = Chain(char, np.asarray(mean, dtype=float), np.asarray(sigma, dtype=float),
                                            np.asarray(rw, dtype=float))
            ch.estimate = ch.prior_mean.copy()
        return ch

    def _chain_key(self, ch: Chain, t: float, graph: gtsam.NonlinearFactorGraph, vals: gtsam.Values,
                   ts: dict) -> int:
        """The chain's variable for time ``t`` (a new one each ``offset_interval_s``), kept in the window."""
        if ch.key is None or t - ch.t >= self.cfg.offset_interval_s:
            n = self._next_sym.get(ch.char, 0)
            self._next_sym[ch.char] = n + 1
            new = symbol(ch.char, n)
            est = ch.prior_mean if ch.estimate is None else ch.estimate
            if ch.key is None:
                graph.add(gtsam.PriorFactorVector(new, ch.prior_mean, gtsam.noiseModel.Diagonal.Sigmas(ch.prior_sigma)))
            else:
                dt = max(t - ch.t, 1e-3)
                graph.add(gtsam.BetweenFactorVector(ch.key, new, np.zeros(len(ch.prior_mean)),
                                                    gtsam.noiseModel.Diagonal.Sigmas(ch.rw_sigma * math.sqrt(dt))))
                ts[ch.key] = float(t)
            vals.insert(new, np.asarray(est, dtype=float))
            ch.key, ch.t = new, float(t)
        ts[ch.key] = float(t)
        return ch.key

    def _refresh_chains(self) -> None:
        """Read the calibration estimates back after a solver update."""
        for name, ch in self.chains.items():
            if ch.key is None:
                continue
            try:
                ch.estimate = np.asarray(self.isam.calculateEstimateVector(ch.key), dtype=float)
            except (RuntimeError, IndexError):
                continue
            if name in ("odom_speed_scale", "odom_yaw_scale"):
                sc = float(ch.estimate[0])
                if math.isfinite(sc) and sc > 0.05:
                    self._gains[0 if name == "odom_speed_scale" else 1] = 1.0 / sc
                    self.inputs.arb.set_correction("odom", gain=float(self._gains[1]))
            elif name == "odom_drift":
                if bool(np.all(np.isfinite(ch.estimate))):
                    # the sideways part only for an odometry that reports sideways motion (see _odometry_factor)
                    lat = self._reports_sideways()
                    self._drift = (float(ch.estimate[0]) if lat else 0.0, float(ch.estimate[1]))
            elif name.startswith("gyro_bias:"):
                self.inputs.arb.set_correction(name.split(":", 1)[1], bias=float(ch.estimate[0]))

    def _corrected(self, d: FloatArray, t0: float, t1: float) -> FloatArray:
        """An odometry increment with the current gains (and the gyro's rotation, :meth:`_gyro_turn`),
        less the drift per metre forward (``self._drift``: the sideways creep, and the turn where no gyro
        gives it)."""
        if self._uncorrected():
            return d
        return np.array(self._corrected_values(float(d[0]), float(d[1]), float(d[2]), t0, t1))

    def _uncorrected(self) -> bool:
        """No gyro, unit gains, no drift: :meth:`_corrected` leaves an increment as it is."""
        ly, lw = self._drift
        return not self.gyro and abs(self._gains[0] - 1.0) <= 1e-8 and abs(self._gains[1] - 1.0) <= 1e-8 \
            and ly == 0.0 and lw == 0.0

    def _corrected_values(self, dx: float, dy: float, dth: float, t0: float, t1: float) -> tuple[float, float, float]:
        """:meth:`_corrected` of the increment ``(dx, dy, dth)``, as floats."""
        if self._uncorrected():
            return dx, dy, dth
        ly, lw = self._drift
        gv = float(self._gains[0])
        for name in self.gyro:  # the first gyro that covers the interval turns it
            r = self._gyro_turn(name, t0, t1)
            if r is not None:   # the chord turned as the gyro turned (where the wheels turned), its heading the gyro's
                turned = abs(dth) > 1e-9
                tx, ty, th = scaled_delta_values(dx, dy, dth, gv, r / dth if turned else float(self._gains[1]))
                return tx, ty - ly * tx, (th if turned else r)
        tx, ty, th = scaled_delta_values(dx, dy, dth, gv, float(self._gains[1]))
        if ly != 0.0 or lw != 0.0:
            ty, th = ty - ly * tx, th - lw * tx
        return tx, ty, th

    def gains(self) -> FloatArray:
        """The odometry's current ``[speed, yaw-rate]`` gains (true / reported = 1 / scale)."""
        return self._gains.copy()

    def odom_drift(self) -> FloatArray:
        """The odometry's estimated ``[sideways m, turn rad]`` per metre driven forward (what it reports
        beyond the truth; 0 before it is estimated, see ``smoother.odom_drift``)."""
        return np.array(self._drift, dtype=float)

    def odom_scales(self) -> FloatArray:
        """The odometry's estimated ``[speed, yaw-rate]`` scales (reported / true)."""
        return 1.0 / self._gains

    def _new_offset(self, t: float, graph: gtsam.NonlinearFactorGraph, vals: gtsam.Values,
                    ts: dict) -> None:
        o = O(self.next_o)
        self.next_o += 1
        if self.cur_o is None:
            if self.calib.calibrated:
                guess, sig = float(self.calib.offset or 0.0), self.cfg.calibrated_offset_sigma
            else:
                guess, sig = self._offset_guess(), self.cfg.offset_prior_sigma
            graph.add(gtsam.PriorFactorPose2(o, offset_pose(guess), gtsam.noiseModel.Diagonal.Sigmas(
                np.array([OFFSET_XY_SIGMA, OFFSET_XY_SIGMA, sig]))))
        else:
            guess = self._offset_estimate()
            dt = max(t - self.cur_o_t, 1e-3)
            sigmas = np.array([OFFSET_XY_SIGMA, OFFSET_XY_SIGMA, self.cfg.offset_rw_sigma * np.sqrt(dt)])
            graph.add(gtsam.BetweenFactorPose2(self.cur_o, o, gtsam.Pose2(0.0, 0.0, 0.0),
                                               gtsam.noiseModel.Diagonal.Sigmas(sigmas)))
            ts[self.cur_o] = float(t)
        vals.insert(o, pose2=offset_pose(guess))
        ts[o] = float(t)
        self.cur_o, self.cur_o_t = o, float(t)

    def _next_offset(self, t: float, graph: gtsam.NonlinearFactorGraph, vals: gtsam.Values,
                     ts: dict) -> None:
        """The compass-to-map offset for the keyframe at ``t``: a new variable, a random walk from
        the previous one, once a fix (a scan-to-map or pose source's, in the map frame) observes
        the offset; before, the same variable, kept in the window.  Observed by the compass and the
        relative yaw sources alone, a walking offset lets the gyro's (or the wheels') integrated
        heading pull the heading away from the compass over long horizons by as much as the walk
        allows, although nothing but that integral says the compass drifted."""
        if self.stats["fixes_used"] > 0 or self.cur_o is None:
            self._new_offset(t, graph, vals, ts)
            return
        ts[self.cur_o] = float(t)
        self.cur_o_t = float(t)

    def _offset_guess(self) -> float:
        if self.calib.offset is not None:
            return float(self.calib.offset)
        if self.calib.has_readings:
            c = self.calib.compass_at(self.t0 or 0.0)
            if c is not None:
                return float(wrap_angle(c - self._init_yaw))
        return 0.0

    def _offset_estimate(self) -> float:
        if self.cur_o is None:
            return self._offset_guess()
        if self._acc is not None and self._acc[1].exists(self.cur_o):
            return pose_offset(self._acc[1].atPose2(self.cur_o))
        try:
            return pose_offset(self.isam.calculateEstimatePose2(self.cur_o))
        except (RuntimeError, IndexError):  # not (or no longer) in the window
            return self._offset_guess()

    def compass_offset(self) -> float | None:
        """Current estimate of the compass-to-map offset (radians), None before any is known."""
        if self.cur_o is None:
            return self.calib.offset
        return self._offset_estimate()

    def latency_estimate(self) -> float:
        """The scan latency (s) in use: configured, estimated once significant, or 0."""
        return self.inputs.latency.value()

    def latency_fit(self) -> tuple[float, float] | None:
        return self.inputs.latency.fit()

    # the latency's reference (health.latency.LatencyReference): the odometry, a gyro's yaw where one covers
    def reference_covered_until(self) -> float:
        covered = self.odo_t[-1] if self.odo_t else -np.inf
        for ts_, _, _ in self.gyro.values():
            if ts_:
                covered = min(covered, ts_[-1])
        return covered

    def reference_periods(self) -> tuple[float, float]:
        return (self._period_of(self.odo_t),
                self._period_of(next(iter(self.gyro.values()))[0] if self.gyro else self.odo_t))

    def reference_yaw(self, ta: float, tb: float) -> tuple[float, float, float] | None:
        wa, wb = self._yaw_rate_at(ta), self._yaw_rate_at(tb)
        d_ref = self._rotation_between(ta, tb)
        return d_ref, -(wb - wa), (self.cfg.gyro_sigma_radps * (tb - ta)) ** 2

    def reference_distance(self, ta: float, tb: float) -> tuple[float, float] | None:
        d, c = self._integrate(ta, tb)  # the reported distance: its scale error is fitted alongside
        return float(np.hypot(d[0], d[1])), float(c[0, 0])
