import os

import numpy as np
import pytest

from fgloc.cli import main
from fgloc.errors import MapError
from fgloc.maps import FREE, OCCUPIED, UNKNOWN, OccupancyMap, load_map

# fuzz examples are derandomized (CI must be reproducible); FGLOC_FUZZ_RANDOM=1 hunts with fresh ones
FUZZ_RANDOM = bool(os.environ.get("FGLOC_FUZZ_RANDOM"))


@pytest.fixture(scope="module")
def willow(shared_data):
    return load_map(shared_data / "maps" / "willow-2010-02-18-0.10.yaml")


def box_map(res=0.05, size=4.0, origin=(0.0, 0.0, 0.0)):
    n = int(round(size / res))
    data = np.zeros((n, n), dtype=np.int16)
    data[: n // 4, -n // 4 :] = UNKNOWN
    data[0, :] = data[-1, :] = data[:, 0] = data[:, -1] = OCCUPIED
    return OccupancyMap(data, res, np.array(origin))


def test_willow_loads_with_map_server_semantics(willow, shared_data):
    from PIL import Image

    pix = np.asarray(Image.open(shared_data / "maps" / "willow-2010-02-18-0.10.pgm"))
    assert willow.data.shape == pix.shape == (608, 566)
    assert willow.resolution == pytest.approx(0.1)
    occ = (255 - pix.astype(float)) / 255 > 0.65
    free = (255 - pix.astype(float)) / 255 < 0.196
    # image row 0 is the top of the map: grid row 0 is the image's last row
    assert np.array_equal(willow.occupied, np.flipud(occ))
    assert np.array_equal(willow.free, np.flipud(free))
    assert willow.occupied.sum() == occ.sum() > 0


def test_save_load_roundtrip(willow, tmp_path):
    for fmt in ("pgm", "png"):
        m2 = load_map(willow.save(tmp_path / f"w_{fmt}.yaml", image_format=fmt))
        assert m2.equals(willow)
    rot = OccupancyMap(willow.data, 0.1, np.array([-3.5, 2.25, 0.3]))
    assert load_map(rot.save(tmp_path / "rot.yaml")).equals(rot)


def test_negate_and_scale_modes(tmp_path):
    from PIL import Image

    pix = np.array([[0, 100, 254], [205, 40, 255]], dtype=np.uint8)
    Image.fromarray(pix).save(tmp_path / "m.pgm")
    (tmp_path / "neg.yaml").write_text(
        "image: m.pgm\nresolution: 1.0\norigin: [0, 0, 0]\nnegate: 1\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")
    m = load_map(tmp_path / "neg.yaml")
    # negate: p = v/255; 254, 255 occupied, 0 free
    assert np.flipud(m.data).tolist() == [[FREE, UNKNOWN, OCCUPIED], [OCCUPIED, FREE, OCCUPIED]]
    (tmp_path / "scale.yaml").write_text(
        "image: m.pgm\nresolution: 1.0\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\n"
        "free_thresh: 0.196\nmode: scale\n")
    s = np.flipud(load_map(tmp_path / "scale.yaml").data)
    assert s[0, 0] == OCCUPIED and s[0, 2] == FREE and 0 < s[0, 1] < 100


def test_world_grid_transforms_with_origin_yaw():
    m = box_map(origin=(1.0, -2.0, np.pi / 2))
    rc = np.array([[3, 7], [10, 2]])
    w = m.grid_to_world(rc[:, 0], rc[:, 1])
    assert np.array_equal(m.world_to_grid(w), rc)
    # with yaw 90 deg, grid +col points along map +y
    assert np.allclose(m.grid_to_world([0], [0])[0], [1.0 - 0.025, -2.0 + 0.025])


def test_raycast_exact_distances():
    m = box_map(res=0.05, size=4.0)  # inner walls at x = 0.05 and x = 3.95
    ang = np.array([0.0, np.pi, np.pi / 2, -np.pi / 2])
    r = m.raycast(np.array([1.0, 1.0]), ang, 10.0)
    assert np.allclose(r, [2.95, 0.95, 2.95, 0.95], atol=1e-9)
    assert np.isinf(m.raycast(np.array([1.0, 1.0]), np.array([0.0]), 1.0)[0])  # beyond max range
    assert m.raycast(np.array([0.01, 1.0]), np.array([0.0]), 5.0)[0] == 0.0  # starts inside a wall
    # through unknown: not blocked by default, blocked on request
    p = np.array([3.5, 0.5])
    assert m.raycast(p, np.array([0.0]), 5.0)[0] == pytest.approx(0.45)
    assert m.raycast(p - [0.6, 0.0], np.array([0.0]), 5.0, unknown_is_obstacle=True)[0] == pytest.approx(0.1)


def test_distance_field_and_bilinear():
    m = box_map(res=0.05, size=4.0)
    d = m.distance_at(np.array([[1.025, 2.025], [0.075, 2.025], [-5.0, 0.0]]))
    assert d[0] == pytest.approx(1.0)  # cell centre x=1.025 to the wall cell centre x=0.025
    assert d[1] == pytest.approx(0.05)
    assert np.isinf(d[2])
    # bilinear: halfway between two centres
    assert m.distance_at(np.array([[1.05, 2.025]]))[0] == pytest.approx(1.025)


@pytest.mark.parametrize(
    "yaml_text,needle",
    [
        ("image: m.pgm\nresolution: [oops\n", "does not parse"),
        ("image: m.pgm\norigin: [0, 0, 0]\n", "lacks required key 'resolution'"),
        ("image: m.pgm\nresolution: -1\norigin: [0, 0, 0]\n", "resolution must be a positive"),
        ("image: m.pgm\nresolution: abc\norigin: [0, 0, 0]\n", "bad value"),
        ("image: missing.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n", "map image not found"),
        ("image: bad.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n", "cannot read map image"),
        ("just a string", "must be a mapping"),
    ],
)
def test_bad_maps_give_one_line_errors(tmp_path, capsys, yaml_text, needle):
    (tmp_path / "bad.pgm").write_bytes(b"P5\n10 10\n255\n\x00\x01")  # truncated pixel data
    y = tmp_path / "map.yaml"
    y.write_text(yaml_text)
    with pytest.raises(MapError, match=needle):
        load_map(y)
    assert main(["map-info", str(y)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and str(y.name) in err or "pgm" in err
    assert err.startswith("fgloc: error:") and "Traceback" not in err


def test_map_info_cli(capsys, shared_data):
    assert main(["map-info", str(shared_data / "maps" / "willow-2010-02-18-0.10.yaml")]) == 0
    out = capsys.readouterr().out
    assert "566 x 608 cells" in out and "occupied 544" in out


def _png_header_only(w: int, h: int) -> bytes:
    """A PNG whose IHDR claims ``w x h`` grey pixels, followed by a tiny IDAT (a 'decompression bomb' header)."""
    import struct
    import zlib

    def chunk(t: bytes, d: bytes) -> bytes:
        return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xFFFFFFFF)

    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(b"\0" * 100)) + chunk(b"IEND", b""))


@pytest.mark.parametrize("name,content", [
    ("huge.pgm", b"P5\n100000 100000\n255\n" + b"\0" * 1000),   # PIL: DecompressionBombError
    ("huge.png", _png_header_only(100000, 100000)),
    ("big.pgm", b"P5\n11000 11000\n255\n" + b"\0" * 1000),      # under PIL's limit, over ours
])
def test_image_claiming_too_many_pixels_is_one_line(tmp_path, capsys, name, content):
    (tmp_path / name).write_bytes(content)
    y = tmp_path / "map.yaml"
    y.write_text(f"image: {name}\nresolution: 0.05\norigin: [0, 0, 0]\n")
    with pytest.raises(MapError, match="claims .* pixels, more than the 100,000,000 cells"):
        load_map(y)
    assert main(["map-info", str(y)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("fgloc: error:") and "\n" not in err and "Traceback" not in err


def test_fuzz_map_yaml_and_image_headers(tmp_path):
    """Random map YAML values and PGM/PNG headers (with truncated or random pixel data): load_map
    returns a map or raises MapError, nothing else escapes (bounded to ~5 s)."""
    import io
    import warnings

    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st
    from PIL import Image

    scalars = st.one_of(st.none(), st.booleans(), st.integers(-10**30, 10**30), st.text(max_size=12),
                        st.floats(allow_nan=True, allow_infinity=True),
                        st.sampled_from(["1e400", "-.inf", ".nan", "0x1F", "[", "{a: 1}", "~", "'", "&a *a"]))
    values = st.one_of(scalars, st.lists(scalars, max_size=4), st.dictionaries(st.text(max_size=4), scalars,
                                                                               max_size=2))
    dims = st.one_of(st.integers(0, 40), st.sampled_from([2**31, 2**32 + 5, 10**6, 65536, -1]))

    @st.composite
    def image_bytes(draw):
        kind = draw(st.sampled_from(["pgm", "png", "pgm_ascii", "junk", "valid"]))
        w, h = draw(dims), draw(dims)
        tail = draw(st.binary(max_size=64))
        if kind == "pgm":
            maxval = draw(st.sampled_from([1, 255, 256, 65535, 65536, 0, -3]))
            return f"P5\n{w} {h}\n{maxval}\n".encode() + tail
        if kind == "pgm_ascii":
            return f"P2\n{w} {h}\n255\n".encode() + b" ".join(str(b).encode() for b in tail)
        if kind == "png":
            data = _png_header_only(min(max(w, 0), 2**31 - 1), min(max(h, 0), 2**31 - 1))
            cut = draw(st.integers(8, len(data)))
            return data[:cut] + tail
        if kind == "valid":
            buf = io.BytesIO()
            mode = draw(st.sampled_from(["L", "RGB", "RGBA", "1", "I", "F", "P", "LA"]))
            Image.new(mode, (max(min(w, 40), 1), max(min(h, 40), 1))).save(
                buf, format="TIFF" if mode in ("I", "F") else "PNG")
            return buf.getvalue()
        return tail

    @st.composite
    def map_yaml(draw):
        meta = {"image": "m.img", "resolution": 0.05, "origin": [0.0, 0.0, 0.0]}
        for key in draw(st.lists(st.sampled_from(["image", "resolution", "origin", "negate", "occupied_thresh",
                                                  "free_thresh", "mode"]), max_size=3)):
            meta[key] = draw(values)
        for key in draw(st.lists(st.sampled_from(["image", "resolution", "origin"]), max_size=1)):
            meta.pop(key, None)
        return meta

    counter = iter(range(10**9))

    @settings(max_examples=250, deadline=None, suppress_health_check=list(HealthCheck), derandomize=not FUZZ_RANDOM)
    @given(meta=map_yaml(), img=image_bytes(), raw_text=st.one_of(st.none(), st.text(max_size=60)))
    def check(meta, img, raw_text):
        d = tmp_path / f"case{next(counter)}"
        d.mkdir()
        (d / "m.img").write_bytes(img)
        text = raw_text if raw_text is not None else yaml.safe_dump(meta)
        (d / "map.yaml").write_text(text)
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # no stray warnings either
            try:
                m = load_map(d / "map.yaml")
            except MapError as e:
                assert "\n" not in str(e)
                return
        assert isinstance(m, OccupancyMap) and m.data.ndim == 2 and m.data.size > 0

    import yaml

    check()


def test_accuracy_is_read_written_and_checked(tmp_path):
    """``accuracy_m`` (fgloc's extension to the map YAML): absent = None, written only when declared,
    read back as declared; a negative or non-numeric value is a one-line MapError."""
    m = box_map()
    y = m.save(tmp_path / "plain.yaml")
    assert "accuracy_m" not in y.read_text() and load_map(y).accuracy_m is None
    m.accuracy_m = 0.02
    assert load_map(m.save(tmp_path / "acc.yaml")).accuracy_m == pytest.approx(0.02)
    for bad in ("-0.01", "abc", ".nan"):
        (tmp_path / "bad.yaml").write_text(
            (tmp_path / "acc.yaml").read_text().replace("accuracy_m: 0.02", f"accuracy_m: {bad}"))
        with pytest.raises(MapError, match="accuracy_m"):
            load_map(tmp_path / "bad.yaml")
    with pytest.raises(MapError, match="accuracy_m"):
        OccupancyMap(m.data, 0.05, accuracy_m=-1.0)
