"""The fused / fix JSON channels formatted directly: the same bytes as the dict and the json module."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

pytest.importorskip("foxglove")

from fgloc.types import PoseFix  # noqa: E402
from fgloc.view import encode  # noqa: E402
from fgloc.view.feed import json_ready  # noqa: E402


def _dumped(obj: dict) -> str:
    """What the recorder writes for a dict: compact JSON, NaN / numpy values through json_ready."""
    try:
        return json.dumps(obj, separators=(",", ":"), allow_nan=False)
    except (TypeError, ValueError):
        return json.dumps(json_ready(obj), separators=(",", ":"))


def _fixes() -> list[PoseFix]:
    rng = np.random.default_rng(7)
    out = []
    for k in range(200):
        a = rng.normal(size=(3, 3)) * 10.0 ** rng.integers(-6, 2)
        cov = a @ a.T
        if k % 7 == 0:
            cov[0, 2] = cov[2, 0] = 0.0
            cov[1, 2], cov[2, 1] = 0.0, -0.0  # equal numbers, different reprs
        if k % 11 == 0:
            cov[0, 0] = -1e-9  # not a variance: sigma null
        if k % 13 == 0:
            cov[2, 2] = math.nan
        pose = rng.normal(size=3) * np.array([50.0, 50.0, 3.0])
        if k % 17 == 0:
            pose[2] = -0.0
        if k % 19 == 0:
            pose[0] = math.inf
        stamp = float(rng.uniform(0, 1e5)) if k % 23 else np.float64(12.5)
        out.append(PoseFix(stamp, pose, cov, quality=float(rng.uniform()) if k % 29 else math.nan,
                           source="native" if k % 3 else "smoother\u00e9", frame_id="map" if k % 5 else 'm"ap\\'))
    return out


def test_fused_json_text_is_the_dumped_dict() -> None:
    direct = 0
    for fused in _fixes():
        text = encode.fused_json_text(fused)
        if text is not None:
            direct += 1
            assert text == _dumped(encode.fused_json(fused))
    assert direct > 150  # the fallback (None) is only for non-finite values


def test_fix_json_text_is_the_dumped_dict() -> None:
    fixes = _fixes()
    direct = 0
    for i, fix in enumerate(fixes):
        fused = fixes[i - 1] if i % 4 else None
        for f in (fix, None):
            args = (float(fix.stamp) + 0.25, "accepted" if i % 2 else "no_fix", "" if i % 3 else "global: \u00fc", f,
                    fused)
            try:
                want = _dumped(encode.fix_json(*args))
            except ValueError:  # an infinite yaw offset: the dict fails the same way
                with pytest.raises(ValueError):
                    encode.fix_json_text(*args)
                continue
            text = encode.fix_json_text(*args)
            if text is not None:
                direct += 1
                assert text == want
    assert direct > 300
