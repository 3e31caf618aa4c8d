import numpy as np
import pytest

from fgloc.errors import LogError
from fgloc.io.tum import read_tum, write_tum
from fgloc.types import Trajectory


def test_tum_roundtrip_exact(tmp_path):
    rng = np.random.default_rng(3)
    stamps = 1.7e9 + np.cumsum(rng.uniform(0.01, 0.1, 200))
    poses = np.column_stack([rng.normal(0, 30, 200), rng.normal(0, 30, 200), rng.uniform(-np.pi, np.pi, 200)])
    t = Trajectory(stamps, poses)
    back = read_tum(write_tum(tmp_path / "t.tum", t))
    assert np.allclose(back.stamps, t.stamps, rtol=0, atol=1e-9)
    assert np.array_equal(back.poses[:, :2], t.poses[:, :2])
    assert np.allclose(back.poses[:, 2], t.poses[:, 2], atol=1e-12)


def test_tum_format_is_evo_compatible(tmp_path):
    p = write_tum(tmp_path / "t.tum", Trajectory([0.0, 1.0], [[1.0, 2.0, np.pi / 2], [0, 0, 0]]))
    row = [float(v) for v in p.read_text().splitlines()[1].split()]
    assert len(row) == 8
    assert row[:4] == [0.0, 1.0, 2.0, 0.0]
    assert row[4:] == pytest.approx([0, 0, np.sqrt(0.5), np.sqrt(0.5)])


@pytest.mark.parametrize("text,needle", [
    ("", "no poses"),
    ("0 1 2 3\n", "expected 8 numbers"),
    ("0 1 2 0 0 0 x 1\n", "not a number"),
    ("1 0 0 0 0 0 0 1\n0 0 0 0 0 0 0 1\n", "not strictly increasing"),
])
def test_tum_bad_input(tmp_path, text, needle):
    p = tmp_path / "bad.tum"
    p.write_text(text)
    with pytest.raises(LogError, match=needle):
        read_tum(p)
