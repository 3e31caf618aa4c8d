#!/usr/bin/env python
"""STM32 emulator: replay a run's /odom and /imu as fgloc serial frames (docs/serial-protocol.md).

    python tools/emu_stm32.py --log run/log.mcap --pty            # prints the pty path
    python tools/emu_stm32.py --sim --tcp 5555 --speed 2          # socket://127.0.0.1:5555
    fgloc live --serial /dev/pts/7 ...                              # in another terminal

Loopback only.  --corrupt / --garbage inject bit flips and noise bytes.
"""

from __future__ import annotations

import argparse
import signal
import sys
import time

from _emu_common import add_common, load_messages, make_clock

from fgloc.config import load_config
from fgloc.testing.emulators import Stm32Emulator


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_common(p)
    out = p.add_mutually_exclusive_group()
    out.add_argument("--pty", action="store_true", help="create a pseudo-terminal (default)")
    out.add_argument("--tcp", type=int, metavar="PORT", help="serve on 127.0.0.1:PORT (0 = any free port)")
    p.add_argument("--config", default=None, help="live config YAML (robot geometry); default config/live.yaml")
    p.add_argument("--corrupt", type=float, default=0.0, help="probability of a bit flip per frame")
    p.add_argument("--garbage", type=float, default=0.0, help="probability of noise bytes before a frame")
    p.add_argument("--drift-ppm", type=float, default=40.0, help="MCU clock rate error")
    args = p.parse_args(argv)
    msgs = load_messages(args)
    clock = make_clock(args, msgs)
    robot = load_config(args.config).robot
    emu = Stm32Emulator(msgs, robot, mode="tcp" if args.tcp is not None else "pty", port=args.tcp or 0,
                        speed=args.speed, t_start=clock.s0, duration=args.duration, clock=clock,
                        drift_ppm=args.drift_ppm, corrupt_prob=args.corrupt, garbage_prob=args.garbage)
    print(emu.url, flush=True)
    print(f"emu_stm32: {len(emu.msgs)} frames, replay starts at {clock.start_host:.3f} "
          f"({max(0.0, clock.start_host - time.time()):.1f} s from now), speed {args.speed}", file=sys.stderr)
    signal.signal(signal.SIGTERM, lambda *a: emu._stop.set())
    emu.start()
    try:
        while not emu.done.wait(0.2):
            pass
    except KeyboardInterrupt:
        pass
    emu.stop()
    s = emu.stats
    print(f"emu_stm32: sent {s.frames} frames, corrupted {s.corrupted}, garbage {s.garbage_bytes} B",
          file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
