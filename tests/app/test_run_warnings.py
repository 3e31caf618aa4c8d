"""fgloc run's summary warns when the wheels and the scan fixes disagree about distance by more than
half (the speed scale hw2.bag showed with no laser mount: 2.188), naming the missing mount."""

from __future__ import annotations

from fgloc.app.run import SPEED_SCALE_PLAUSIBLE, scale_warnings
from fgloc.localization.sources.report import SourceReport
from fgloc.localization.stats import RunStats


def _stats(**sources: dict) -> RunStats:
    return RunStats(sources={name: SourceReport(kind="odometry", **kw) for name, kw in sources.items()})


def test_an_implausible_speed_scale_is_a_warning_naming_the_mount():
    stats = _stats(odom={"speed_scale": 2.188, "yaw_rate_scale": 2.478}, imu={"gyro_bias_radps": 0.0})
    (line,) = scale_warnings(stats, mount_assumed=True)
    assert line.startswith("odom: the wheels report 2.19x the distance the scan fixes moved: the log has no "
                           "transform to the laser")
    assert "--static-transform PARENT CHILD X Y Z ROLL PITCH YAW" in line
    (line,) = scale_warnings(_stats(wheels={"speed_scale": 0.6}), mount_assumed=False)
    assert line == ("wheels: the wheels report 0.60x the distance the scan fixes moved: check the laser mount "
                    "and the odometry's units")


def test_plausible_scales_and_yaw_rate_scales_are_not_warned_about():
    lo, hi = SPEED_SCALE_PLAUSIBLE
    assert (lo, hi) == (1 / 1.5, 1.5)
    for sc in (lo, 0.9, 1.0, 1.2, hi):
        assert scale_warnings(_stats(odom={"speed_scale": sc}), mount_assumed=True) == []
    # a skid steer's yaw-rate scale of 2.5 is its wheels slipping, not a wrong mount
    assert scale_warnings(_stats(odom={"yaw_rate_scale": 2.5}), mount_assumed=True) == []
    assert scale_warnings(RunStats(), mount_assumed=True) == []
