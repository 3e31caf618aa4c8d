"""`fgloc live --record FILE` never replaces a file (a map image, the previous session's
recording) without --force; a clean stop publishes the recording under its name, a kill leaves
it as FILE.partial (never a truncated file under the final name)."""

from __future__ import annotations

import time
from pathlib import Path

from fgloc.testing.cli import run_cli as cli

from .conftest import LONGER, error_line


class LiveFeed:
    """The STM32 and SICK emulators (fgloc.testing) replaying a simulated drive over TCP, for a
    ``fgloc live`` in this process or a child: ``args`` are its --serial / --laser options."""

    def __init__(self, tmp_path: Path, seconds: float = 12.0, lead_s: float = 0.5, scenario: dict | None = None):
        self.tmp_path = tmp_path
        self.seconds = seconds
        self.lead_s = lead_s
        self.scenario = scenario or LONGER

    def __enter__(self) -> LiveFeed:
        from fgloc.config import load_config
        from fgloc.sim import run_scenario
        from fgloc.testing.emulators import EmulatorPair

        sim = run_scenario(self.scenario, seed=0)
        robot = load_config().robot  # the live default on both sides: the counts decode to the same twist
        self.pair = EmulatorPair.create(sim.messages, robot, mode="tcp", speed=1.0, duration=self.seconds,
                                        lead_s=self.lead_s)
        self.pair.start()
        self.args = ["--serial", self.pair.stm32.url, "--laser", self.pair.sick.address, "--backend", "ekf"]
        return self

    def __exit__(self, *exc: object) -> None:
        self.pair.stop()


def test_record_onto_an_existing_file_is_refused(tmp_path):
    """Issue 32 item 3: `--record map.pgm` replaced the map image; a restart with the same name
    erased the previous recording.  Both are refused (exit 2, one line, the file unchanged)."""
    image = tmp_path / "map.pgm"
    image.write_bytes(b"P5 2 2 255\n" + bytes(4))
    rc, _, err = cli("live", "--serial", "loop://", "--backend", "ekf", "--duration", "0.2", "--quiet",
                     "--record", image)
    assert rc == 2 and error_line(err) == f"fgloc: error: {image}: exists; pass --force to overwrite it"
    assert image.read_bytes() == b"P5 2 2 255\n" + bytes(4)
    # a session's recording, then a restart with the same name
    rec = tmp_path / "rec.mcap"
    with LiveFeed(tmp_path, seconds=3.0) as feed:
        rc, _, err = cli("live", *feed.args, "--duration", "2", "--quiet", "--record", rec)
    assert rc == 0, err
    first = rec.read_bytes()
    from fgloc.io import open_log

    counts = {t: v["count"] for t, v in open_log(rec).summary()["topics"].items()}
    assert counts.get("/odom", 0) > 20 and counts.get("/scan", 0) > 5, counts
    rc, _, err = cli("live", "--serial", "loop://", "--backend", "ekf", "--duration", "0.2", "--quiet",
                     "--record", rec)
    assert rc == 2 and "rec.mcap: exists; pass --force" in error_line(err)
    assert rec.read_bytes() == first and not (tmp_path / "rec.mcap.partial").exists()
    with LiveFeed(tmp_path, seconds=2.0) as feed:
        rc, _, err = cli("live", *feed.args, "--duration", "1", "--quiet", "--record", rec, "--force")
    assert rc == 0, err
    assert rec.read_bytes() != first


def test_out_files_are_checked_before_the_session(tmp_path):
    """`--out` onto an existing file is refused at once, not after a day of running."""
    tum = tmp_path / "traj.tum"
    tum.write_text("# someone's trajectory\n")
    t0 = time.monotonic()
    rc, _, err = cli("live", "--serial", "loop://", "--backend", "ekf", "--duration", "30", "--quiet", "-o", tum)
    assert rc == 2 and time.monotonic() - t0 < 20
    assert error_line(err) == f"fgloc: error: {tum}: exists; pass --force to overwrite it"
    assert tum.read_text() == "# someone's trajectory\n"
