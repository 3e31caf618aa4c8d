"""`fgloc live` in-process: exit status when a sensor thread dies, strict JSON summary."""

from __future__ import annotations

import json
import re
import time

import pytest

from fgloc.cli import main
from fgloc.live.sick import SickClient


def _strict_json(text: str):
    def no_constant(name: str):
        raise ValueError(f"not JSON: {name}")

    return json.loads(text, parse_constant=no_constant)


def test_dead_laser_thread_is_reported_and_exit_is_nonzero(monkeypatch, capsys):
    """Issue 12 item 8: a worker thread that dies (here: a forced bug in the client loop)
    stops `fgloc live` at once with a one-line report and a non-zero exit status."""

    def broken_serve(self):
        raise RuntimeError("forced failure")

    monkeypatch.setattr(SickClient, "serve", broken_serve)
    t0 = time.monotonic()
    code = main(["live", "--laser", "127.0.0.1:9", "--backend", "ekf", "--duration", "20", "--quiet", "--json"])
    elapsed = time.monotonic() - t0
    out, err = capsys.readouterr()
    assert code == 1
    assert elapsed < 10.0  # stopped when the thread died, not after --duration
    assert "laser thread died (RuntimeError: forced failure)" in err
    report = _strict_json(out)
    assert report["failed_threads"] == ["laser thread died (RuntimeError: forced failure)"]
    assert report["counters"]["laser"]["thread_failure"] == "RuntimeError: forced failure"


@pytest.mark.parametrize("flag", ["--serial", "--laser"])
def test_summary_is_strict_json_with_an_absent_sensor(flag, capsys):
    """Issue 12 item 7: no messages at all -> latency percentiles are unknown: null, not NaN; a sensor
    that delivered nothing the whole session is a one-line error, exit 1."""
    target = "loop://" if flag == "--serial" else "127.0.0.1:9"  # port 9: nothing listens
    code = main(["live", flag, target, "--backend", "ekf", "--duration", "0.5", "--quiet", "--json"])
    out, err = capsys.readouterr()
    assert code == 1
    what = "serial loop://: no frame received" if flag == "--serial" else \
        "laser 127.0.0.1:9: no scan received (never connected)"
    last = err.strip().splitlines()[-1]
    # the session's length: 0.5 s asked, more on a loaded host (1.1 s seen at load 13)
    assert re.fullmatch(rf"fgloc live: error: {re.escape(what)} in \d+\.\d+ s", last), last
    report = _strict_json(out)
    assert report["poses"] == 0
    assert report["latency_ms"] == {"p50": None, "p99": None}
    assert report["failed_threads"] == []


def test_a_missing_serial_port_is_one_line_and_exit_2(tmp_path, capsys):
    """A serial device path that does not exist: one line before anything starts, exit 2; the default
    output is one summary line, not the JSON counters."""
    code = main(["live", "--serial", str(tmp_path / "ttyUSB9"), "--duration", "0.5", "--quiet"])
    out, err = capsys.readouterr()
    assert code == 2 and out == ""
    assert err.strip() == (f"fgloc: error: {tmp_path / 'ttyUSB9'}: no such serial port (is the adapter plugged in? "
                           "see ls /dev/ttyUSB* /dev/ttyACM*; a pyserial URL such as socket://HOST:PORT works too)")
    code = main(["live", "--serial", "loop://", "--duration", "0.3", "--quiet"])
    out, err = capsys.readouterr()
    assert code == 1 and out.count("\n") == 1 and out.startswith("fgloc live: 0.")


def test_help_shows_no_nan_defaults():
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-m", "fgloc.cli", "live", "--help"], capture_output=True, text=True,
                         timeout=120, env={"COLUMNS": "200", "PATH": ""}).stdout
    flat = " ".join(out.split())
    assert "nan" not in flat and "--initial-pose" in flat and "global localization" in flat
