"""Shared command-line plumbing of tools/emu_stm32.py and tools/emu_sick.py."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fgloc.testing.emulators import ReplayClock  # noqa: E402


def add_common(p: argparse.ArgumentParser) -> None:
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--log", type=Path, help="MCAP log to replay (e.g. written by `fgloc sim`)")
    src.add_argument("--sim", action="store_true", help="simulate the paper run in memory and replay it")
    p.add_argument("--seed", type=int, default=0, help="simulation seed (with --sim)")
    p.add_argument("--speed", type=float, default=1.0, help="replay speed factor (1 = real time)")
    p.add_argument("--t-start", type=float, default=0.0, help="skip this many seconds of the run")
    p.add_argument("--duration", type=float, default=None, help="replay only this many seconds")
    p.add_argument("--start-at", type=float, default=None,
                   help="host Unix time at which the replay starts (give both emulators the same)")


def load_messages(args: argparse.Namespace) -> list[tuple[str, object]]:
    if args.sim:
        from fgloc.sim import simulate_paper

        return list(simulate_paper(seed=args.seed).messages)
    from fgloc.io import open_log

    return list(open_log(args.log).messages())


def make_clock(args: argparse.Namespace, msgs: list[tuple[str, object]]) -> ReplayClock:
    stamps = [float(m.stamp) for _, m in msgs if hasattr(m, "stamp")]  # type: ignore[attr-defined]
    s0 = min(stamps) + args.t_start
    start = args.start_at if args.start_at is not None else time.time() + 1.0
    return ReplayClock(s0, start, args.speed)
