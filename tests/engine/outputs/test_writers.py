"""Point-cloud writers: files read back by independent readers (numpy, plyfile, Open3D)."""

from __future__ import annotations

import importlib.util
import io
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from plyfile import PlyData

from prismcore.errors import InputError
from prismcore.outputs import writers
from prismcore.outputs.writers import write_csv, write_ply


def make_cloud(n: int, dtype=np.float32, seed: int = 7, scale: float = 250.0):
    rng = np.random.default_rng(seed)
    points = (rng.standard_normal((n, 3)) * scale).astype(dtype)
    colors = rng.integers(0, 256, (n, 3), dtype=np.uint8)
    return points, colors


def reference_text(values: np.ndarray, decimals: int) -> list[str]:
    """Python's correctly rounded fixed-point text (the oracle), '-0.000' written '0.000'."""
    out = []
    for v in np.asarray(values, dtype=np.float64).ravel().tolist():
        s = f"{v:.{decimals}f}"
        if s.startswith("-") and not s.strip("-0."):
            s = s[1:]
        out.append(s)
    return out


def csv_fields(data: bytes) -> list[str]:
    return [f for line in data.decode("ascii").splitlines() for f in line.split(",")]


def written(fn, *args, **kwargs) -> bytes:
    buf = io.BytesIO()
    n = fn(buf, *args, **kwargs)
    data = buf.getvalue()
    assert n == len(data)
    return data


# ------------------------------------------------------------------------------------------ CSV


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("header", [False, True])
@pytest.mark.parametrize("with_colors", [False, True])
@pytest.mark.parametrize("decimals", [0, 1, 3, 6])
def test_csv_round_trip_loadtxt(tmp_path, dtype, header, with_colors, decimals):
    points, colors = make_cloud(3000, dtype)
    colors = colors if with_colors else None
    path = tmp_path / "cloud.csv"
    n = write_csv(path, points, colors, header=header, decimals=decimals)
    data = path.read_bytes()
    assert n == len(data)
    assert data.endswith(b"\n") and b"\r" not in data
    lines = data.decode("ascii").splitlines()
    if header:
        assert lines[0] == ("x,y,z,r,g,b" if with_colors else "x,y,z")
    else:
        assert lines[0].split(",")[0] == reference_text(points[0, 0], decimals)[0]
    assert len(lines) == len(points) + header

    table = np.loadtxt(path, delimiter=",", skiprows=int(header), ndmin=2)
    assert table.shape == (len(points), 6 if with_colors else 3)
    want = points.astype(np.float64)
    # Every value is the point rounded to `decimals` places.
    np.testing.assert_allclose(table[:, :3], want, rtol=0, atol=0.5 * 10.0**-decimals * 1.000001)
    np.testing.assert_array_equal(table[:, :3], np.round(table[:, :3], decimals))
    if with_colors:
        np.testing.assert_array_equal(table[:, 3:], colors)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("decimals", [0, 2, 3, 5])
def test_csv_text_matches_correct_rounding(dtype, decimals):
    points, _ = make_cloud(4000, dtype, seed=decimals, scale=50.0)
    fields = csv_fields(written(write_csv, points, decimals=decimals))
    assert fields == reference_text(points, decimals)


def test_csv_default_is_the_papers_bare_xyz():
    points = np.array([[12.5, 0.25, -3.0], [1.0, 2.0, 3.0]], dtype=np.float32)
    colors = np.array([[1, 2, 3], [255, 0, 128]], dtype=np.uint8)
    assert written(write_csv, points) == b"12.500,0.250,-3.000\n1.000,2.000,3.000\n"
    assert written(write_csv, points, colors, header=True) == (
        b"x,y,z,r,g,b\n12.500,0.250,-3.000,1,2,3\n1.000,2.000,3.000,255,0,128\n"
    )


TRICKY64 = [
    0.0005, -0.0005, 1.0005, 8.0005, 2.675, -2.675, 0.1235, 0.1245, -0.1235, 0.0625, -0.0625,
    1.0625, 0.5, -0.5, 1.5, 2.5, -0.0, 0.0, -0.0004999, -1e-9, 1e-300, -1e-300, 5e-324,
    123456789.0125, 999.9995, -999.9995, 0.9995, 1e11, -1e11 + 0.0005,
]


@pytest.mark.parametrize("decimals", [0, 1, 2, 3, 4, 6, 9, 12, 17])
def test_csv_ties_signed_zeros_and_tiny_values(decimals):
    values = np.array(TRICKY64 + [0.0] * (-len(TRICKY64) % 3), dtype=np.float64)
    points = values.reshape(-1, 3)
    fields = csv_fields(written(write_csv, points, decimals=decimals))
    assert fields == reference_text(points, decimals)
    assert not any(f.startswith("-") and not f.strip("-0.") for f in fields)


@pytest.mark.parametrize("decimals", [3, 4])
def test_csv_float64_decimal_ties_in_bulk(decimals):
    # Values with one digit more than printed: the float product x * 10**d often lands on an
    # exact half-integer that the true product is not; the writer must still round correctly.
    rng = np.random.default_rng(decimals)
    k = rng.integers(-10**9, 10**9, (5000, 3))
    points = k / 10.0 ** (decimals + 1)
    fields = csv_fields(written(write_csv, points, decimals=decimals))
    assert fields == reference_text(points, decimals)


@pytest.mark.parametrize("decimals", [0, 3, 6])
def test_csv_float32_binary_ties(decimals):
    rng = np.random.default_rng(11)
    k = rng.integers(-10**6, 10**6, (3000, 3))
    points = (k / 2.0 ** rng.integers(1, 14, (3000, 3))).astype(np.float32)
    fields = csv_fields(written(write_csv, points, decimals=decimals))
    assert fields == reference_text(points, decimals)


@pytest.mark.parametrize(
    "values",
    [
        [3.4e38, -3.4e38, 1.0],
        [1e15, -1e15, -0.0001],
        [1e12, -1e20, 0.25],
        [-0.0, -0.0004, 123.4565],
        [1e20, -0.5, -0.0005],  # one huge value: the float-formatter route, signed zeros there
        [3e38, -0.0004999, -1.5],
    ],
)
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_csv_huge_values_fixed_notation(values, dtype):
    points = np.array([values, values[::-1]], dtype=dtype)
    for decimals in (0, 3):
        data = written(write_csv, points, decimals=decimals)
        assert b"e" not in data.lower()
        assert csv_fields(data) == reference_text(points, decimals)


@settings(max_examples=60, deadline=None, database=None)
@given(
    points=hnp.arrays(
        st.sampled_from([np.float32, np.float64]),
        hnp.array_shapes(min_dims=2, max_dims=2, min_side=0, max_side=40).map(lambda s: (s[0], 3)),
        elements={"allow_nan": False, "allow_infinity": False},
    ),
    decimals=st.integers(0, 8),
)
def test_csv_any_finite_floats(points, decimals):
    data = written(write_csv, points, decimals=decimals)
    fields = csv_fields(data)
    assert fields == reference_text(points, decimals)
    pattern = re.compile(rf"-?\d+\.\d{{{decimals}}}" if decimals else r"-?\d+")
    assert all(pattern.fullmatch(f) for f in fields)


def test_csv_chunks_join_seamlessly(monkeypatch):
    points, colors = make_cloud(2500, np.float64)
    whole = written(write_csv, points, colors, header=True)
    monkeypatch.setattr(writers, "CHUNK_ROWS", 97)
    assert written(write_csv, points, colors, header=True) == whole


# ------------------------------------------------------------------------------------------ PLY


def read_ply(data: bytes) -> PlyData:
    return PlyData.read(io.BytesIO(data))


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("with_colors", [False, True])
@pytest.mark.parametrize("ascii", [False, True])
def test_ply_round_trip_plyfile(dtype, with_colors, ascii):
    points, colors = make_cloud(3000, dtype)
    points[:5] = [[0.1, 1e-7, -3e38],
                  [-0.0, 1 / 3, 16777217.0], [1e-45, 5e-39, 2.0**-149],
                  [123456.7, -0.5, 7.0], [3.4028235e38, -1.17549435e-38, 0.0]]
    colors = colors if with_colors else None
    data = written(write_ply, points, colors, ascii=ascii, comment="prismcloud test")
    ply = read_ply(data)
    assert ply.text == ascii
    assert ply.byte_order == ("=" if ascii else "<")
    assert "prismcloud test" in ply.comments
    vertex = ply["vertex"]
    assert vertex.count == len(points)
    names = [p.name for p in vertex.properties]
    types = [p.val_dtype for p in vertex.properties]
    if with_colors:
        assert names == ["x", "y", "z", "red", "green", "blue"]
        assert types == ["f4"] * 3 + ["u1"] * 3
    else:
        assert names == ["x", "y", "z"]
        assert types == ["f4"] * 3
    got = np.stack([vertex["x"], vertex["y"], vertex["z"]], axis=1)
    assert got.dtype == np.float32
    np.testing.assert_array_equal(got, points.astype(np.float32))  # exact, ascii too
    if with_colors:
        rgb = np.stack([vertex["red"], vertex["green"], vertex["blue"]], axis=1)
        assert rgb.dtype == np.uint8
        np.testing.assert_array_equal(rgb, colors)


def test_ply_header_layout():
    points, colors = make_cloud(2)
    data = written(write_ply, points, colors, comment="made by prism")
    head, _, body = data.partition(b"end_header\n")
    assert head.decode("ascii").splitlines() == [
        "ply", "format binary_little_endian 1.0", "comment made by prism", "element vertex 2",
        "property float x", "property float y", "property float z", "property uchar red",
        "property uchar green", "property uchar blue",
    ]
    assert len(body) == 2 * 15
    ascii_body = written(write_ply, points, ascii=True).partition(b"end_header\n")[2]
    assert len(ascii_body.decode("ascii").splitlines()) == 2
    assert b"-0.0" not in written(write_ply, -np.zeros((1, 3), np.float32), ascii=True)


def test_ply_chunks_join_seamlessly(monkeypatch):
    points, colors = make_cloud(2500)
    whole = [written(write_ply, points, colors, ascii=a) for a in (False, True)]
    monkeypatch.setattr(writers, "CHUNK_ROWS", 97)
    assert [written(write_ply, points, colors, ascii=a) for a in (False, True)] == whole


@pytest.mark.parametrize("with_colors", [False, True])
@pytest.mark.parametrize("ascii", [False, True])
def test_ply_round_trip_open3d(tmp_path, with_colors, ascii):
    o3d = pytest.importorskip("open3d", exc_type=ImportError)  # installed but unloadable: skip
    points, colors = make_cloud(5000, seed=3)
    path = tmp_path / "cloud.ply"
    write_ply(path, points, colors if with_colors else None, ascii=ascii)
    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
        cloud = o3d.io.read_point_cloud(str(path), format="ply")
    got = np.asarray(cloud.points)
    assert got.shape == points.shape
    np.testing.assert_array_equal(got.astype(np.float32), points)
    assert cloud.has_colors() == with_colors
    if with_colors:
        np.testing.assert_array_equal(np.rint(np.asarray(cloud.colors) * 255), colors)


# ------------------------------------------------------------------------- destinations, sizes

WRITERS = [
    pytest.param(write_csv, {}, id="csv"),
    pytest.param(write_csv, {"header": True}, id="csv-header"),
    pytest.param(write_ply, {}, id="ply"),
    pytest.param(write_ply, {"ascii": True}, id="ply-ascii"),
]


class WriteOnly:
    """A bare stream (like an upload body) that takes at most 1000 bytes per call."""

    def __init__(self):
        self.parts: list[bytes] = []

    def write(self, data) -> int:
        chunk = bytes(memoryview(data)[:1000])
        self.parts.append(chunk)
        return len(chunk)


class ReturnsNone:
    def __init__(self):
        self.parts: list[bytes] = []

    def write(self, data) -> None:
        self.parts.append(bytes(data))


@pytest.mark.parametrize(("fn", "options"), WRITERS)
def test_path_and_streams_give_identical_bytes(tmp_path, fn, options):
    points, colors = make_cloud(1234)
    path = tmp_path / "out"
    n_path = fn(path, points, colors, **options)
    n_str = fn(str(tmp_path / "out2"), points, colors, **options)
    data = path.read_bytes()
    assert n_path == n_str == len(data) == path.stat().st_size
    assert (tmp_path / "out2").read_bytes() == data

    assert written(fn, points, colors, **options) == data
    with open(tmp_path / "opened", "wb") as fh:
        fh.write(b"PREFIX")  # written at the stream's position, stream left open
        assert fn(fh, points, colors, **options) == len(data)
        assert not fh.closed
    assert (tmp_path / "opened").read_bytes() == b"PREFIX" + data
    for sink in (WriteOnly(), ReturnsNone()):
        assert fn(sink, points, colors, **options) == len(data)
        assert b"".join(sink.parts) == data


@pytest.mark.parametrize(("fn", "options"), WRITERS)
@pytest.mark.parametrize("with_colors", [False, True])
def test_empty_cloud(fn, options, with_colors):
    points = np.empty((0, 3), np.float32)
    colors = np.empty((0, 3), np.uint8) if with_colors else None
    data = written(fn, points, colors, **options)
    if fn is write_csv:
        expected = b""
        if options.get("header"):
            expected = b"x,y,z,r,g,b\n" if with_colors else b"x,y,z\n"
        assert data == expected
    else:
        ply = read_ply(data)
        assert ply["vertex"].count == 0
        assert len(ply["vertex"].properties) == (6 if with_colors else 3)


def test_inputs_not_modified_and_views_accepted():
    points, colors = make_cloud(600, np.float64)
    points[0] = [-0.0, -0.0001, 0.1235]
    points.setflags(write=False)
    colors.setflags(write=False)
    before = points.copy(), colors.copy()
    outputs = [written(fn, points, colors, **opt) for fn, opt in
               [(write_csv, {}), (write_ply, {}), (write_ply, {"ascii": True})]]
    np.testing.assert_array_equal(points, before[0])
    assert np.signbit(points[0, 0])
    np.testing.assert_array_equal(colors, before[1])
    # Strided and Fortran-ordered views write what their contiguous copies write.
    fortran = np.asfortranarray(points)
    assert written(write_csv, fortran, colors) == outputs[0]
    assert written(write_ply, fortran, np.asfortranarray(colors)) == outputs[1]
    assert written(write_csv, points[::2], colors[::2]) == written(
        write_csv, np.ascontiguousarray(points[::2]), np.ascontiguousarray(colors[::2]))


def test_large_cloud_quick_check(tmp_path):
    points, colors = make_cloud(200_000, seed=5)
    csv_path, ply_path = tmp_path / "big.csv", tmp_path / "big.ply"
    assert write_csv(csv_path, points) == csv_path.stat().st_size
    table = np.loadtxt(csv_path, delimiter=",")
    np.testing.assert_allclose(table, points, rtol=0, atol=0.0005 + 1e-9)
    assert write_ply(ply_path, points, colors) == ply_path.stat().st_size
    vertex = PlyData.read(str(ply_path))["vertex"]
    np.testing.assert_array_equal(np.stack([vertex["x"], vertex["y"], vertex["z"]], 1), points)
    np.testing.assert_array_equal(vertex["blue"], colors[:, 2])


# ------------------------------------------------------------------------------------ bad input

GOOD_POINTS = np.zeros((4, 3), np.float32)


@pytest.mark.parametrize("fn", [write_csv, write_ply])
@pytest.mark.parametrize(
    ("points", "colors", "message"),
    [
        (np.zeros((5, 2), np.float32), None, r"shape \(N, 3\), got \(5, 2\)"),
        (np.zeros(3, np.float32), None, r"got \(3,\)"),
        (np.zeros((2, 3, 1), np.float32), None, r"got \(2, 3, 1\)"),
        (np.zeros((0,), np.float32), None, r"got \(0,\)"),
        (np.zeros((4, 3), np.int64), None, "float32 or float64, got int64"),
        (np.zeros((4, 3), np.float16), None, "float32 or float64, got float16"),
        ([[0.0, 0.0, 0.0]], None, "numpy array, got list"),
        (GOOD_POINTS, np.zeros((4, 4), np.uint8), r"colors must have shape \(N, 3\), got \(4, 4\)"),
        (GOOD_POINTS, np.zeros((4, 3), np.float32), "colors must be uint8, got float32"),
        (GOOD_POINTS, np.zeros((5, 3), np.uint8), r"\(5, 3\) but points has shape \(4, 3\)"),
        (GOOD_POINTS, [[1, 2, 3]] * 4, "colors must be a numpy array"),
    ],
)
def test_bad_shapes_and_types(tmp_path, fn, points, colors, message):
    path = tmp_path / "never"
    with pytest.raises(InputError, match=message):
        fn(path, points, colors)
    assert not path.exists()  # refused before the file is opened


@pytest.mark.parametrize("fn", [write_csv, write_ply])
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_non_finite_points(tmp_path, fn, bad, dtype):
    points = np.ones((6, 3), dtype)
    points[4, 1] = bad
    with pytest.raises(InputError, match=r"1 non-finite .* row 4"):
        fn(tmp_path / "never", points)
    assert not (tmp_path / "never").exists()


def test_ply_float64_beyond_float32_range():
    points = np.zeros((2, 3))
    points[1, 2] = -1e39
    with pytest.raises(InputError, match="too large"):
        write_ply(io.BytesIO(), points)
    points[1, 2] = -3.4028235e38  # rounds to -FLT_MAX: fine
    assert read_ply(written(write_ply, points))["vertex"]["z"][1] == -np.finfo(np.float32).max


@pytest.mark.parametrize("decimals", [-1, 18, 2.0, True, "3", None])
def test_bad_decimals(decimals):
    with pytest.raises(InputError, match="decimals"):
        write_csv(io.BytesIO(), GOOD_POINTS, decimals=decimals)


@pytest.mark.parametrize("comment", ["two\nlines", "cr\r", "caf\u00e9", 42])
def test_bad_comment(comment):
    with pytest.raises(InputError, match="comment"):
        write_ply(io.BytesIO(), GOOD_POINTS, comment=comment)


@pytest.mark.parametrize("fn", [write_csv, write_ply])
@pytest.mark.parametrize("dest", [io.StringIO(), 3, None, b"bytes-path"])
def test_bad_destinations(fn, dest):
    with pytest.raises(InputError, match="dest must be"):
        fn(dest, GOOD_POINTS)


def test_text_file_opened_w_is_refused(tmp_path):
    with open(tmp_path / "t.csv", "w") as fh, pytest.raises(InputError, match="text stream"):
        write_csv(fh, GOOD_POINTS)
    assert Path(tmp_path / "t.csv").read_bytes() == b""


# ------------------------------------------------------------------------------------ benchmark


def test_benchmark_run_is_quiet_and_complete(capfd):
    path = Path(__file__).resolve().parents[3] / "benchmarks" / "writers_bench.py"
    spec = importlib.util.spec_from_file_location("writers_bench", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    rows = bench.run(2000)
    out, err = capfd.readouterr()
    assert out == "" and err == ""
    names = [row["name"] for row in rows]
    assert names[:4] == ["prismcore.write_csv", "prismcore.write_ply (binary)",
                         "prismcore.write_ply (ascii)", bench.SAVETXT]
    assert set(names[4:]) <= {bench.OPEN3D}
    by_name = {row["name"]: row for row in rows}
    csv = by_name["prismcore.write_csv"]
    assert csv["baseline"] == bench.SAVETXT and csv["bytes"] == by_name[bench.SAVETXT]["bytes"]
    assert csv["ratio_vs_baseline"] == pytest.approx(by_name[bench.SAVETXT]["seconds"]
                                                     / csv["seconds"])
    for row in rows:
        assert row["seconds"] > 0 and row["points"] == 2000
        if row["name"].startswith("prismcore"):
            assert row["peak_traced_mb"] >= 0
