"""What the smoother keeps: its sensor buffers, keyframes, iSAM2 instance and calibration chains
(:class:`SmootherState`, the first of the smoother's layers), and each input source's health and
noise bookkeeping."""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass

import gtsam
import numpy as np

from fgloc.backends.base import Backend, FloatArray
from fgloc.backends.compass import CompassCalibrator
from fgloc.backends.contract import SourceNoise
from fgloc.backends.health import Arbiter, SourceHealth
from fgloc.backends.health.latency import StepMedian
from fgloc.backends.inputs import InputBook
from fgloc.backends.integration import TwistValues
from fgloc.backends.smoother.config import SmootherConfig
from fgloc.backends.smoother.consistency import HeadingConsistency
from fgloc.backends.smoother.keys import BALLAST
from fgloc.types import PoseFix


@dataclass
class Chain:
    """A slowly varying calibration variable (``Vector``): one per ``offset_interval_s``, tied by a random walk."""

    char: str
    prior_mean: FloatArray
    prior_sigma: FloatArray
    rw_sigma: FloatArray           # per sqrt(s)
    key: int | None = None
    t: float = -np.inf
    estimate: FloatArray | None = None
    stamped: float = -np.inf       # the window stamp its current variable last had


class SmootherState(Backend):
    """The smoother's state (set up and reset here); the layers above add what it does with it."""

    def __init__(self, config: SmootherConfig | None = None) -> None:
        super().__init__()
        self.cfg = config or SmootherConfig()
        self.calib = CompassCalibrator(self.cfg.calibration_fixes)
        self._q_slip = np.asarray(self.cfg.q_slip, dtype=float)
        self.next_x = 0  # key counters never restart, so keys stay unique across resets
        self.next_o = 0
        self._next_sym: dict[str, int] = {}
        self.stats.update({"compass_factors": 0, "late_scans": 0, "dropped_late": 0, "gyro_factors": 0})
        # sensor streams and what is known about each source (kept across re-initializations)
        self.gyro: dict[str, tuple[list[float], list[float], list[float]]] = {}
        # the first absolute heading source's readings (stamps, unwrapped yaw), the last few seconds:
        # the chord's heading where no gyro covers an interval (see Streams._heading_chord)
        self.heading_hist: tuple[list[float], list[float]] = ([], [])
        self._heading_source: str | None = None
        #: the compass-to-map offset was declared (set_compass_offset), not calibrated from fixes
        self.offset_declared = False
        self._heading_var = np.inf    # its last reading's variance (rad^2)
        self._odom_factor_yaw_var = np.inf   # the last odometry factor's yaw variance (rad^2)
        #: the fused heading against the heading sources it fuses (kept across re-initializations)
        self.heading_check = HeadingConsistency()
        # what the heading sources said since the last solved keyframe: relative sources' summed
        # (increment, variance), absolute ones' latest (reading, variance)
        self._heading_inputs: tuple[dict[str, tuple[float, float]], dict[str, tuple[float, float]]] = ({}, {})
        self._gyro_done: dict[str, float] = {}
        self.chains: dict[str, Chain] = {}
        # per-source health, noise, gyro biases (unless cfg.gyro_bias_in_graph) and latency pairs; the
        # arbiter's long blocks: whether the fixes' heading errors vary slowly (see _fix_weighted_cov)
        self.inputs = InputBook(Arbiter(long_blocks=(4, 16)), self.cfg.adapt_noise, self.cfg.latency,
                                self.cfg.latency_s)
        self._periods: dict[tuple, tuple[list[float], float]] = {}   # _period_of's memory
        self._step_medians: dict[int, StepMedian] = {}   # _period_of's running medians, per stamp list
        self._gains = np.ones(2)
        self._drift = (0.0, 0.0)   # the odometry's sideways creep and turn per metre forward (KeyframeGraph)
        # the fastest speed (m/s) and turn rate (rad/s) the odometry has reported (kept across restarts)
        self._odo_speed_max = 0.0
        self._odo_rate_max = 0.0
        self._odo_lateral_max = 0.0
        self._gap_memo: tuple[tuple, float, float, int] = ((), math.inf, math.nan, -1)   # _odom_gap_s's memory
        self._turned = 0.0
        #: the odometry's stamps cannot be placed against the scans' (set by the localizer: a slow
        #: odometry written in bursts, which its OdometryClock cannot shift): its timing variance is
        #: used as with ``slow_odom_timing`` (see :meth:`_timing_var`)
        self.odom_timing_unknown = False
        # differential orientation sources (readings until their keyframe) and further twist sources
        self.rel_pending: list[tuple[float, float, float, str]] = []
        self._rel_gated: dict[str, int] = {}
        self._rel_innov: dict[str, float] = {}   # each source's last innovation (jumped or crept)
        self.vel: dict[str, tuple[list[float], list[FloatArray], list[FloatArray]]] = {}
        self._vel_done: dict[str, float] = {}
        self._vel_translates: dict[str, bool] = {}
        self._reset_state()

    # ------------------------------------------------------------------ state
    def _reset_state(self) -> None:
        p = gtsam.ISAM2Params()
        # per variable type: the poses and offsets at the configured threshold, the calibration
        # variables at their own scale (a 0.01 s / 0.01 rad/s threshold would never relinearize them)
        th = float(self.cfg.relinearize_threshold)
        tm = gtsam.ISAM2ThresholdMap()
        for sym, v in (("x", [th] * 3), ("o", [th] * 3), ("b", [th * 1e-2]), ("g", [th * 0.1]), ("k", [th * 0.1]),
                       ("l", [th * 1e-2]), ("r", [th]), ("d", [th * 1e-2, th * 1e-2]),
                       ("a", [th * 0.1, th * 0.1]), (BALLAST, [th])):
            tm.insert((sym, np.asarray(v, dtype=float)))
        p.setRelinearizeThreshold(tm)
        p.relinearizeSkip = self.cfg.relinearize_skip
        # every update solves the whole window (back-substitution without the wildfire's 1e-3 cut-off):
        # the variables an update does not re-eliminate (marginalize_every_s) are solved as exactly as
        # those it does
        gn = gtsam.ISAM2GaussNewtonParams()
        gn.setWildfireThreshold(0.0)
        p.setOptimizationParams(gn)
        # new factors go into the slots the marginalized ones left: iSAM2's graph stays the window's
        # size over a session of any length, not a slot per factor ever added (~64 a second at 25 Hz)
        p.findUnusedFactorSlots = True
        self.isam = gtsam.IncrementalFixedLagSmoother(self.cfg.lag_s, p)
        self._ballast: list[int] = []     # inert variables (see _with_ballast)
        self._ballast_t = -np.inf         # when they were last stamped, and how many there were
        self._ballast_n = 0
        self._t_latest = -np.inf          # the newest timestamp given to the smoother
        self.kf_t: list[float] = []          # keyframe times, increasing (window + history)
        self.kf_key: list[int] = []          # keys, same order
        self.kf_pose: dict[int, FloatArray] = {}   # latest estimate per key
        self.window: deque[tuple[float, int]] = deque()
        self.smoothed: dict[int, tuple[float, FloatArray]] = {}
        self.between_idx: dict[tuple[int, int], int] = {}
        self.cur_o: int | None = None
        self.cur_o_t = -np.inf
        self.odo_t: list[float] = []
        self.odo_u: list[tuple[float, float, float]] = []   # (vx, vy, w) per message
        self.odo_c: list[tuple[float, float, float, float, float, float]] = []  # covariances (upper6)
        self.compass_pending: list[tuple[float, float, float, str]] = []  # t, yaw (compass), var, source
        self.t0: float | None = None
        self._rejects = 0
        self._last_cov = np.eye(3) * 1e-2
        #: the last fix the graph took: (stamp, pose, covariance with its floors), the floor of the output's
        #: covariance (see KeyframeGraph._record_online)
        self._fix_floor: tuple[float, FloatArray, FloatArray] | None = None
        self._floor_mark: list[float] = []   # its odometry integration's resumption mark
        self._floor_mark_t0 = -np.inf
        self._output_cov_memo: tuple[float, FloatArray, FloatArray, tuple, FloatArray] | None = None
        self._cov_stale: int | None = None
        self._init_yaw = 0.0
        self.pending_kf: list[tuple[float, PoseFix | None]] = []
        self._pred_cache: tuple | None = None
        self._int_marks: dict[float, list[float]] = {}   # _integrate's resumable states, by start
        self._rate_marks: dict[tuple[str, float], list[float]] = {}   # _gyro_increment's, by (gyro, start)
        self._gyro_memo: dict[tuple, tuple[float | None, float]] = {}   # _gyro_increment's answers (before the bias)
        self._integrate_memo: tuple[tuple, TwistValues] | None = None   # its last answer
        self._acc: tuple | None = None  # factors of keyframes not yet given to iSAM2
        self.heading_check.restart()
        self._heading_inputs = ({}, {})
        for ch in self.chains.values():  # calibration carries over a re-initialization as a prior
            if ch.key is not None and ch.estimate is not None:
                ch.prior_mean = ch.estimate.copy()
            ch.key, ch.t, ch.stamped = None, -np.inf, -np.inf
        for src in self._gyro_done:
            self._gyro_done[src] = -np.inf
        self.rel_pending.clear()
        self._vel_done = dict.fromkeys(self._vel_done, -np.inf)

    @property
    def initialized(self) -> bool:
        return self.t0 is not None

    @property
    def encoder_sigmas(self) -> tuple[float, float, float]:
        return self.cfg.encoder_sigmas

    def set_odometry_timing_unknown(self, unknown: bool) -> None:
        self.odom_timing_unknown = bool(unknown)

    def source_health(self) -> Mapping[str, SourceHealth]:
        return self.inputs.health

    def source_noise(self, name: str) -> SourceNoise | None:
        return self.inputs.source_noise(name)
