#!/usr/bin/env python
"""SICK LMS1xx emulator: a CoLa-A TCP server on 127.0.0.1 streaming a run's /scan.

    python tools/emu_sick.py --log run/log.mcap --port 2111
    fgloc live --laser 127.0.0.1:2111 ...

Streams `sSN LMDscandata` telegrams after `sEN LMDscandata 1`.  --drop-every S closes the
connection every S seconds (and refuses new ones for --refuse seconds) to exercise the
client's reconnect; --malformed P sends a truncated telegram before a valid one.
"""

from __future__ import annotations

import argparse
import signal
import sys
import time

from _emu_common import add_common, load_messages, make_clock

from fgloc.testing.emulators import SickEmulator


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_common(p)
    p.add_argument("--port", type=int, default=2111, help="TCP port on 127.0.0.1 (0 = any free port)")
    p.add_argument("--malformed", type=float, default=0.0, help="probability of a malformed telegram")
    p.add_argument("--drop-every", type=float, default=None, help="drop the connection every S seconds")
    p.add_argument("--refuse", type=float, default=1.0, help="after a drop, refuse connections this long")
    args = p.parse_args(argv)
    msgs = load_messages(args)
    clock = make_clock(args, msgs)
    emu = SickEmulator(msgs, port=args.port, speed=args.speed, t_start=clock.s0, duration=args.duration,
                       clock=clock, malformed_prob=args.malformed)
    print(emu.address, flush=True)
    print(f"emu_sick: {len(emu.scans)} scans, replay starts at {clock.start_host:.3f}, speed {args.speed}",
          file=sys.stderr)
    signal.signal(signal.SIGTERM, lambda *a: emu._stop.set())
    emu.start()
    next_drop = time.time() + args.drop_every if args.drop_every else float("inf")
    try:
        while not emu.done.wait(0.1):
            if time.time() >= next_drop:
                emu.drop_connection(args.refuse)
                print(f"emu_sick: dropped the connection (refusing for {args.refuse} s)", file=sys.stderr)
                next_drop += args.drop_every
    except KeyboardInterrupt:
        pass
    emu.stop()
    print(f"emu_sick: sent {emu.sent_scans} of {len(emu.scans)} scans, malformed {emu.stats.malformed}, "
          f"drops {emu.stats.dropped_connections}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
