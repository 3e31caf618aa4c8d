"""IMU sources (``sensor_msgs/Imu``, or the yaw-only :class:`~fgloc.types.CompassHeading`).

An IMU is rotated into the robot's base frame through its mount (the transform chain from the base,
``sources.base_frame`` or the odometry's ``child_frame_id`` or ``base_link``, to ``header.frame_id``
in ``/tf_static``, ``/tf`` or ``sources.static_transforms``: :class:`~fgloc.frames.mounts.MountTable`;
the maths in :mod:`fgloc.frames.imu`): any 3-D mount when the message is a whole
:class:`~fgloc.types.Imu` (every log reader gives one) and the transform a
:class:`~fgloc.types.Transform3D`; with a planar transform or a yaw-only reading (fgloc's serial
link, the paper simulator), the yaw mount is undone.  A frame that no chain connects to the base is used unmounted
(identity: most IMUs without a published mount are mounted level and aligned, and a heading source
is not dropped on a guess), counted, and said once per source: a warning once
:data:`~fgloc.frames.mounts.MOUNT_WAIT_S` of its stamps passed without one, and the source's health
line names the base, the frame and what its links reach (a mount that arrives is applied from then
on, and the summary says after how many).

The first IMU gives the heading (and its rate) to the localizer; a second one only its yaw rate
(its heading is in another world frame).  ``use: [..., roll, pitch]``: its attitude levels the
odometry and its yaw rate is the heading's rate ``(sin(roll) w_y + cos(roll) w_z) / cos(pitch)``
(the default layout's IMU does so unless ``sources.level_by_imu`` is off); a reading whose roll /
pitch variance says they are not estimated (:func:`tilt_usable`) does neither, counted; so is a
yaw whose variance says it is not estimated (:func:`yaw_usable`): not a heading, absolute or differential.
``differential``: orientation increments, as a heading with the source's own offset for a
back-end that takes them (``add_relative_yaw``), else as a yaw rate.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from fgloc.backends.contract import Capability
from fgloc.frames.imu import imu_in_base
from fgloc.frames.mounts import MOUNT_WAIT_S, OWN_FRAMES
from fgloc.geometry import wrap_angle, wrap_scalar
from fgloc.io.topics import IMU
from fgloc.localization.sources.handler import SourceContext, SourceHandler
from fgloc.localization.sources.odometry import MAX_TILT_RAD
from fgloc.localization.sources.spec import COMPONENTS, OUT_OF_ORDER, TILT, SourceSpec, SourceType
from fgloc.types import CompassHeading, Imu

if TYPE_CHECKING:
    from fgloc.localization.sources.report import SourceReport


def needed(spec: SourceSpec, msg: Imu) -> Imu:
    """``msg`` without the fields ``spec`` does not use (their faults are none of its business):
    the orientation serves yaw, roll / pitch and orientation increments, the angular velocity
    vyaw (and a levelling IMU's heading rate)."""
    orient = spec.uses("yaw") or spec.uses("roll")
    rates = spec.uses("vyaw")
    if orient and rates:
        return msg
    return replace(msg, orientation_xyzw=msg.orientation_xyzw if orient else None,
                   orientation_cov=msg.orientation_cov if orient else None,
                   angular_velocity_radps=msg.angular_velocity_radps if rates else None,
                   angular_velocity_cov=msg.angular_velocity_cov if rates else None)


def tilt_usable(roll_pitch_var: tuple[float, float] | None) -> bool:
    """Whether the base's roll and pitch variances (:attr:`~fgloc.frames.imu.BaseImu.roll_pitch_var`;
    None: no covariance given) let them level the odometry: both at most :data:`MAX_TILT_RAD` squared.
    Larger is a driver's "not estimated" placeholder (1e6, 99999): a sigma that allows any tilt a
    ground robot has.  Zero (REP 145's "unknown") is taken, as robot_localization takes it; a NaN or
    negative diagonal has already dropped the orientation (:func:`~fgloc.frames.imu.imu_in_base`)."""
    if roll_pitch_var is None:
        return True
    bound = MAX_TILT_RAD * MAX_TILT_RAD
    return roll_pitch_var[0] <= bound and roll_pitch_var[1] <= bound  # (NaN: not)


#: rad: a yaw sigma of a quarter turn or more allows any heading (a driver's "not estimated"; an xsens
#: claiming 10 rad^2 while its yaw ran against the turn): such a yaw is no heading.  Taken as one,
#: its readings' errors (one drift, not independent) add up over a hundred readings a second to a
#: heading the filter trusts
MAX_YAW_SIGMA_RAD = math.pi / 2


def yaw_usable(yaw_var: float) -> bool:
    """Whether a yaw's variance (after the source's covariance policy; NaN: none claimed, the
    back-end's default) lets it be a heading: at most :data:`MAX_YAW_SIGMA_RAD` squared."""
    return not yaw_var > MAX_YAW_SIGMA_RAD * MAX_YAW_SIGMA_RAD


class ImuHandler(SourceHandler):
    """An IMU source's messages into the localizer (see the module docstring)."""

    accepts = (Imu, CompassHeading)
    group = "heading"  # the first IMU gives the heading; a second one its yaw rate

    def __init__(self, spec: SourceSpec, ctx: SourceContext, fused: bool = True, second: bool = False) -> None:
        super().__init__(spec, ctx, fused, second)
        # what the source uses, asked once (every message reads them)
        self.uses_yaw, self.uses_vyaw, self.uses_roll = spec.uses("yaw"), spec.uses("vyaw"), spec.uses("roll")
        self.whole = (self.uses_yaw or self.uses_roll) and self.uses_vyaw  # needed() keeps the message as it is
        self.message_variances = spec.covariance == "message"  # spec.variance of a used component is the message's

    def handle(self, msg: Imu | CompassHeading) -> None:
        spec, st, ctx, mounts = self.spec, self.state, self.ctx, self.ctx.mounts
        h = st.health
        if isinstance(msg, Imu):
            mount = mounts.mount(msg.frame_id)
            if mount is None and msg.frame_id not in OWN_FRAMES and not mounts.is_base(msg.frame_id):
                self.unmounted(msg.frame_id, float(msg.stamp))
            elif mount is not None:
                self.mounted()
            Rv = mounts.rotation_values(mount)
            base, problems = imu_in_base(msg if self.whole else needed(spec, msg), Rv)
            for p in problems:
                self.skip(p)
            yaw, yaw_var, rate, rate_var = base.yaw_rad, base.yaw_var, base.yaw_rate_radps, base.yaw_rate_var
            if self.uses_roll and base.roll_pitch_rad is not None:
                if not tilt_usable(base.roll_pitch_var):
                    st.extra["tilt_unusable"] = st.extra.get("tilt_unusable", 0) + 1
                else:
                    if ctx.tilt_source in (None, spec.name):  # the first levelling IMU levels
                        ctx.tilt_source = spec.name
                        ctx.tilt = (float(msg.stamp), *base.roll_pitch_rad)
                    # the heading's rate on a slope; a tilt no ground robot drives on (an upside-down or
                    # left-handed mount, as _levelled refuses it) keeps the base's own z rate
                    if base.heading_rate_radps is not None and max(map(abs, base.roll_pitch_rad)) <= MAX_TILT_RAD:
                        rate = base.heading_rate_radps
        else:
            yaw, rate = msg.yaw_rad, msg.yaw_rate_radps
            yaw_var, rate_var = float(msg.yaw_var), float(msg.yaw_rate_var)
            if yaw is not None and (yaw_var < 0 or math.isinf(yaw_var)):
                self.skip("imu: orientation covariance with a NaN or negative diagonal")
                yaw = None
            if rate is not None and (rate_var < 0 or math.isinf(rate_var)):
                self.skip("imu: angular velocity covariance with a NaN or negative diagonal")
                rate = None
            # a yaw-only reading: an unknown yaw mount is absorbed by the heading offset estimate
            mount = mounts.mount(msg.frame_id)
            if mount is not None:
                R = mounts.rotation(mount)
                if yaw is not None:  # the reader gave the sensor frame's yaw: undo the mount's
                    yaw = float(wrap_angle(yaw - math.atan2(R[1, 0], R[0, 0])))
                if rate is not None:
                    if abs(R[2, 2]) < 0.9:
                        # the sensor's z axis is not the base's: its z rate is not the yaw rate, and
                        # a reader that gives only z cannot say what is (a skip only if it is used)
                        if spec.uses("vyaw"):
                            self.skip("imu: yaw rate of a tilted mount not in the message (needs the whole Imu)")
                        rate = None
                    else:
                        rate = rate * float(np.sign(R[2, 2]))
        t = float(msg.stamp)
        be = self.loc.backend
        if yaw is not None and self.uses_yaw and not yaw_usable(spec.variance("yaw", yaw_var)):
            st.extra["yaw_unusable"] = st.extra.get("yaw_unusable", 0) + 1
            yaw = None
        if spec.differential and yaw is not None and self.uses_yaw and not self.uses_vyaw \
                and Capability.RELATIVE_YAW in be.capabilities:
            # orientation increments as a heading with the source's own offset (a back-end that
            # takes them: the EKF), not as a rate d_yaw / d_t, which stamp jitter turns into spikes
            if st.prev_yaw is not None and not t > st.prev_yaw[0]:
                self.skip(f"imu: {OUT_OF_ORDER}")
                return
            st.prev_yaw = (t, yaw)
            be.add_relative_yaw(t, float(yaw), spec.variance("yaw", yaw_var),
                                "imu" if not st.extra.get("second") else spec.name)
            if self.loc.dead_reckoning is not None and not st.extra.get("second"):
                self.loc.dead_reckoning.relative_yaw(t, float(yaw))
            h.accepted += 1
            return
        if spec.differential and yaw is not None:
            # orientation increments as a yaw rate (robot_localization's imuN_differential)
            var = yaw_var if math.isfinite(yaw_var) else 1e-4
            if st.prev_yaw is not None and not t > st.prev_yaw[0]:
                self.skip(f"imu: {OUT_OF_ORDER}")
                return
            prev, st.prev_yaw = st.prev_yaw, (t, yaw)
            prev_var, st.extra["prev_yaw_var"] = st.extra.get("prev_yaw_var", var), var
            if prev is not None and t > prev[0] and self.uses_yaw:
                d_rate = wrap_scalar(yaw - prev[1]) / (t - prev[0])
                if rate is None or not self.uses_vyaw:  # r_l's variance (differential_cov)
                    rate, rate_var = d_rate, (var + prev_var) * (t - prev[0])
            yaw = None
        if yaw is not None and self.uses_yaw:
            if not self.message_variances:
                yaw_var = spec.variance("yaw", yaw_var)
        else:
            yaw = None
        if rate is not None and self.uses_vyaw:
            if not self.message_variances:
                rate_var = spec.variance("vyaw", rate_var)
        elif not (spec.differential and rate is not None):
            rate = None
        if yaw is None and rate is None:
            if not h.skipped:  # an empty reading: the localizer counts it as it always did
                self.loc.on_compass(CompassHeading(t, None, None))
            return
        if st.extra.get("second"):
            yaw = None  # a second IMU's heading is in another world frame: only its rate is fused
            if rate is None:
                return
            if Capability.GYRO in be.capabilities and be.initialized:
                be.add_gyro(t, rate, rate_var, spec.name)
            h.accepted += 1
            return
        h.accepted += 1
        self.loc.compass_values(t, yaw, yaw_var if yaw is not None else math.nan, rate,
                                rate_var if rate is not None else math.nan)

    def unmounted(self, frame: str, t: float) -> None:
        """An IMU message of ``frame`` without a mount (yet): taken as identity, counted; warned about
        once :data:`MOUNT_WAIT_S` of its stamps have passed without one (or at :meth:`finish`)."""
        f, st = frame.lstrip("/"), self.state
        st.extra["no_transform"] = st.extra.get("no_transform", 0) + 1
        st.extra["no_transform_frame"] = f
        since = st.extra.setdefault("no_transform_since", t)
        if t - since >= MOUNT_WAIT_S:
            self.ctx.mounts.warn_missing(f)

    def mounted(self) -> None:
        """The mount arrived after messages taken as identity (a /tf_static logged late)."""
        st = self.state
        if st.extra.get("no_transform"):
            st.extra["mount_late"] = st.extra.get("mount_late", 0) + int(st.extra.pop("no_transform"))
            st.extra.pop("no_transform_since", None)


    def finish(self) -> None:
        st = self.state
        if st.extra.get("no_transform"):  # the log ended before MOUNT_WAIT_S without a mount
            self.ctx.mounts.warn_missing(str(st.extra.get("no_transform_frame", "")))


    # ------------------------------------------------------------------ report
    def backend_streams(self) -> list[str]:
        name = self.spec.name if self.state.extra.get("second") else "imu"
        return [f"{name}.yaw", f"{name}.gyro"]

    def report_estimates(self, r: SourceReport) -> None:
        be = self.loc.backend
        if self.state.messages and Capability.GYRO_BIAS in be.capabilities:
            b = be.gyro_bias(self.spec.name if self.state.extra.get("second") else "imu")
            r.gyro_bias_radps = round(float(b), 7)


SOURCE = SourceType("imu", IMU, "/imu", ("yaw", "vyaw"), COMPONENTS + TILT, ImuHandler)
