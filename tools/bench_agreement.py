"""What the scan-agreement monitor (fgloc.localization.monitor.MapAgreement) costs per scan.

    python tools/bench_agreement.py [--scenario kidnap] [--scans 1000] [--repeats 5]

The scans of a shipped scenario at their true poses: CPU time of one measurement (``measure``), and of
``check`` called on every scan as the localizer does (a measurement every ``integrity.agreement_period_s``
of log time), per scan; medians and ranges over the repeats.
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def main() -> None:
    from fgloc.config import load_config, scenario_path
    from fgloc.localization.gate import agreement_sigma
    from fgloc.localization.localizer import AGREEMENT_MONITOR_SCALE
    from fgloc.localization.monitor import MapAgreement
    from fgloc.sim import load_scenario, run_scenario

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="kidnap")
    ap.add_argument("--scans", type=int, default=1000)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    sim = run_scenario(load_scenario(scenario_path(args.scenario)), seed=0)
    cfg = load_config().integrity
    scans = [m for t, m in sim.messages if t == "/scan"][: args.scans]
    poses = sim.ground_truth.interpolate(np.array([s.stamp for s in scans]))
    sigma = AGREEMENT_MONITOR_SCALE * agreement_sigma(sim.map, cfg.agreement_sigma_m)
    rate = (len(scans) - 1) / (scans[-1].stamp - scans[0].stamp)
    one, per_scan = [], []
    checks = 0
    for _ in range(args.repeats):
        ag = MapAgreement(cfg, sim.map, sim.laser_mount, sigma)
        t0 = time.process_time()
        for s, p in zip(scans, poses, strict=True):
            ag.measure(s, p)
        one.append((time.process_time() - t0) / len(scans))
        ag = MapAgreement(cfg, sim.map, sim.laser_mount, sigma)
        t0 = time.process_time()
        for s, p in zip(scans, poses, strict=True):
            ag.check(float(s.stamp), s, p, True)
        per_scan.append((time.process_time() - t0) / len(scans))
        checks = ag.checks

    def fmt(v: list[float]) -> str:
        us = np.array(v) * 1e6
        return f"{np.median(us):.1f} us [{us.min():.1f}-{us.max():.1f}]"

    print(f"{len(scans)} scans of {args.scenario} ({len(scans[0].ranges)} beams, {rate:.0f} Hz), "
          f"{args.repeats} repeats, CPU time:")
    print(f"  one measurement: {fmt(one)}")
    print(f"  per scan (a measurement every {cfg.agreement_period_s} s: {checks} in {len(scans)} scans): "
          f"{fmt(per_scan)}")


if __name__ == "__main__":
    main()
