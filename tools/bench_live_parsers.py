#!/usr/bin/env python
"""Live parsers: speed and robustness of the CoLa-A (SICK) and STM32 serial parsers.

    python tools/bench_live_parsers.py                       # this checkout
    python tools/bench_live_parsers.py --compare-rev 88417dc # side by side with fgloc/live/sick.py at a revision

Prints, per parser version: the median time to parse one 541-beam LMDscandata telegram and
one second of 4-wheel serial frames (50 Hz), and how many of N randomly mutated telegrams
(tokens prefixed/replaced with signs, 0x, _, 20-digit numbers, deleted, or replaced by
random 8..80-bit numbers) raise anything but ``TelegramError`` (each such exception killed
the laser client thread before the fix), how many are accepted, and how many of the accepted
ones have a different token count (would be a silently wrong scan).
"""

from __future__ import annotations

import argparse
import importlib.util
import math
import random
import statistics
import subprocess
import sys
import tempfile
import timeit
from pathlib import Path
from types import ModuleType

import numpy as np

from fgloc.live import sick as sick_now
from fgloc.live.serial_protocol import FrameParser, encode_sensor_frame
from fgloc.types import LaserScan

JUNK = [b"-", b"+", b"0x", b"_", b"FFFFFFFFFFFFFFFFFFFF", b"-1", b"G", b"00000000000000000000001"]


def _module_at(rev: str) -> ModuleType:
    repo = Path(__file__).resolve().parents[1]
    src = subprocess.run(["git", "-C", str(repo), "show", f"{rev}:fgloc/live/sick.py"], check=True,
                         capture_output=True, text=True).stdout
    path = Path(tempfile.mkdtemp()) / f"sick_{rev}.py"
    path.write_text(src)
    spec = importlib.util.spec_from_file_location(f"sick_{rev}", path)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


def _mutate(good: bytes, rng: random.Random) -> bytes:
    tok = good.split(b" ")
    for _ in range(rng.randint(1, 3)):
        i = rng.randrange(2, len(tok))
        k = rng.random()
        if k < 0.4:
            tok[i] = rng.choice(JUNK) + tok[i]
        elif k < 0.7:
            tok[i] = rng.choice(JUNK)
        elif k < 0.85:
            del tok[i]
        else:
            tok[i] = format(rng.getrandbits(rng.choice([8, 16, 32, 40, 80])), "X").encode()
    return b" ".join(tok)


def _median_ms(fn, number: int, repeat: int) -> float:
    return statistics.median(timeit.repeat(fn, number=number, repeat=repeat)) / number * 1e3


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--compare-rev", default=None, help="also measure fgloc/live/sick.py at this git revision")
    p.add_argument("--mutations", type=int, default=20000)
    p.add_argument("--repeat", type=int, default=7)
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)

    r = np.random.default_rng(args.seed).uniform(0.5, 30, 541).astype(np.float32)
    scan = LaserScan(0.0, math.radians(-135), math.radians(0.5), 0.05, 50.0, r, scan_time=0.04,
                     time_increment=1 / 18000)
    good = sick_now.encode_lmdscandata(scan, 1, 1, 1000, 2000)
    rng = random.Random(args.seed)
    muts = [_mutate(good, rng) for _ in range(args.mutations)]
    n0 = len(good.split(b" "))

    versions = [("this checkout", sick_now)] + ([(args.compare_rev, _module_at(args.compare_rev))]
                                                 if args.compare_rev else [])
    print(f"{'CoLa-A parser':<16} {'541 beams ms':>12} {'raised':>8} {'accepted':>9} {'wrong len':>9}  exceptions")
    for name, mod in versions:
        raised, accepted, wrong_len = 0, 0, 0
        kinds: dict[str, int] = {}
        for m in muts:
            try:
                mod.parse_lmdscandata(m)
                accepted += 1
                wrong_len += len(m.split(b" ")) != n0
            except mod.TelegramError:
                pass
            except Exception as e:  # noqa: BLE001 - counting exactly these
                raised += 1
                kinds[type(e).__name__] = kinds.get(type(e).__name__, 0) + 1
        ms = _median_ms(lambda mod=mod: mod.parse_lmdscandata(good), 200, args.repeat)
        print(f"{name:<16} {ms:12.3f} {raised:8d} {accepted:9d} {wrong_len:9d}  {kinds or '-'}")

    frames = b"".join(encode_sensor_frame(k, k * 20_000, [k, 2 * k, 3 * k, 4 * k], k % 3600, k) for k in range(50))
    ms = _median_ms(lambda: FrameParser().feed(frames), 20, args.repeat)
    print(f"serial parser: 1 s of 4-wheel frames at 50 Hz ({len(frames)} B) in {ms:.3f} ms (median of {args.repeat})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
