"""``fgloc simulate``'s summary line names the heading source's offset only when the scenario has one."""

from __future__ import annotations

import pytest

from fgloc.cli import main


@pytest.mark.parametrize(("extra", "said", "not_said"), [
    ("", "compass offset", "IMU yaw offset"),
    ("compass: null\n", None, "offset"),
    ("imu: {offset_deg: 12.0}\n", "IMU yaw offset 12.00 deg", "compass offset"),
])
def test_the_offset_is_said_for_the_source_simulated(tmp_path, capsys, extra, said, not_said):
    scen = tmp_path / "short.yaml"
    scen.write_text("route: [[3.0, 3.0], [5.0, 3.0]]\n" + extra)
    assert main(["simulate", "scenario", str(scen), "-o", str(tmp_path / "out"), "--seed", "2"]) == 0
    line = capsys.readouterr().out.strip().splitlines()[-1].split(": ", 1)[1]  # not the folder name
    assert said is None or said in line, line
    assert not_said not in line, line
