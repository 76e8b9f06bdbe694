"""Image decoding: every format and pixel layout against a known array, and every bad input.

The oracle is the array each file was written from. Files are written by OpenCV, by Pillow, and
by the minimal PNG and TIFF writers below (struct + zlib, independent of both libraries), and
compared exactly for lossless formats, within a tolerance for JPEG and lossy WebP.
"""

from __future__ import annotations

import io
import struct
import time
import tracemalloc
import zlib
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest
from PIL import Image, ImageFile, ImageOps

from prismcore.errors import InputError
from prismcore.io import images
from prismcore.io.images import DEFAULT_MAX_PIXELS, ImageInfo, load_image, probe_image

H, W = 48, 64


# --------------------------------------------------------------------------------------------
# known arrays


def smooth_rgb(h: int = H, w: int = W) -> np.ndarray:
    """Smooth gradients with distinct channels (small JPEG error, any channel swap shows)."""
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    r = 30 + 190 * x / (w - 1)
    g = 20 + 200 * y / (h - 1)
    b = 128 + 100 * np.sin(x / 9.0) * np.cos(y / 7.0)
    return np.rint(np.dstack([r, g, b])).astype(np.uint8)


def noise(shape: tuple[int, ...], dtype=np.uint8, seed: int = 3) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, np.iinfo(dtype).max, shape, dtype=dtype, endpoint=True)


def quadrants(h: int = H, w: int = W) -> np.ndarray:
    """Four flat, very different quadrants plus a marker: any flip or turn changes it grossly."""
    a = np.zeros((h, w, 3), np.uint8)
    a[: h // 2, : w // 2] = (230, 20, 20)
    a[: h // 2, w // 2 :] = (20, 230, 20)
    a[h // 2 :, : w // 2] = (20, 20, 230)
    a[h // 2 :, w // 2 :] = (230, 230, 20)
    a[2:10, 2:18] = (255, 255, 255)
    return a


def gray3(g: np.ndarray) -> np.ndarray:
    return np.repeat(g[..., None], 3, axis=2)


def as16(a: np.ndarray) -> np.ndarray:
    """The float32 0..255 scale load_image promises for 16-bit samples."""
    return a.astype(np.float64) / 257.0


# --------------------------------------------------------------------------------------------
# independent writers


def png_chunk(tag: bytes, payload: bytes) -> bytes:
    return struct.pack(">I", len(payload)) + tag + payload + struct.pack(">I", zlib.crc32(tag + payload))


def png_bytes(
    arr: np.ndarray,
    color_type: int,
    *,
    palette: np.ndarray | None = None,
    trns: bytes | None = None,
    exif: bytes | None = None,
    size: tuple[int, int] | None = None,
) -> bytes:
    """A PNG with filter 0 rows: colour type 0 gray, 2 RGB, 3 palette, 4 gray+alpha, 6 RGBA."""
    h, w = arr.shape[:2]
    depth = 16 if arr.dtype == np.uint16 else 8
    width, height = size or (w, h)
    rows = arr.astype(">u2") if depth == 16 else arr
    raw = b"".join(b"\x00" + row.tobytes() for row in rows.reshape(h, -1))
    out = b"\x89PNG\r\n\x1a\n" + png_chunk(
        b"IHDR", struct.pack(">IIBBBBB", width, height, depth, color_type, 0, 0, 0)
    )
    if palette is not None:
        out += png_chunk(b"PLTE", palette.astype(np.uint8).tobytes())
    if trns is not None:
        out += png_chunk(b"tRNS", trns)
    if exif is not None:
        out += png_chunk(b"eXIf", exif)
    return out + png_chunk(b"IDAT", zlib.compress(raw)) + png_chunk(b"IEND", b"")


def tiff_bytes(
    arr: np.ndarray,
    *,
    order: str = "<",
    orientation: int | None = None,
    size: tuple[int, int] | None = None,
) -> bytes:
    """An uncompressed single-strip TIFF of uint8/uint16 samples, 1, 3 or 4 (RGBA) channels."""
    h, w = arr.shape[:2]
    spp = 1 if arr.ndim == 2 else arr.shape[2]
    bits = arr.dtype.itemsize * 8
    width, height = size or (w, h)
    pixels = arr.astype(arr.dtype.newbyteorder(order)).tobytes()
    entries: list[tuple[int, int, list[int]]] = [  # (tag, type, values); 3 SHORT, 4 LONG
        (256, 4, [width]),
        (257, 4, [height]),
        (258, 3, [bits] * spp),
        (259, 3, [1]),
        (262, 3, [1 if spp == 1 else 2]),
        (273, 4, [0]),  # patched below
        (277, 3, [spp]),
        (278, 4, [height]),
        (279, 4, [len(pixels)]),
        (284, 3, [1]),
    ]
    if orientation is not None:
        entries.append((274, 3, [orientation]))
    if spp == 4:
        entries.append((338, 3, [2]))  # unassociated alpha
    entries.sort()
    ifd_size = 2 + 12 * len(entries) + 4
    extra = b""
    packed = []
    for tag, typ, values in entries:
        fmt = order + ("H" if typ == 3 else "I") * len(values)
        payload = struct.pack(fmt, *values)
        if len(payload) <= 4:
            packed.append((tag, typ, len(values), payload.ljust(4, b"\x00")))
        else:
            packed.append((tag, typ, len(values), struct.pack(order + "I", 8 + ifd_size + len(extra))))
            extra += payload
    data_at = 8 + ifd_size + len(extra)
    ifd = struct.pack(order + "H", len(packed))
    for tag, typ, count, value in packed:
        if tag == 273:
            value = struct.pack(order + "I", data_at)
        ifd += struct.pack(order + "HHI", tag, typ, count) + value
    ifd += struct.pack(order + "I", 0)
    head = (b"II" if order == "<" else b"MM") + struct.pack(order + "HI", 42, 8)
    return head + ifd + extra + pixels


def cv2_bytes(ext: str, arr: np.ndarray, *params: int) -> bytes:
    """Encode an RGB(A) or gray array with OpenCV, which wants BGR(A)."""
    if arr.ndim == 3:
        arr = cv2.cvtColor(arr, cv2.COLOR_RGBA2BGRA if arr.shape[2] == 4 else cv2.COLOR_RGB2BGR)
    ok, buf = cv2.imencode(ext, arr, list(params))
    assert ok
    return buf.tobytes()


def pil_bytes(arr: np.ndarray | Image.Image, fmt: str, mode: str | None = None, **kw) -> bytes:
    im = arr if isinstance(arr, Image.Image) else Image.fromarray(arr)
    if mode:
        im = im.convert(mode)
    buf = io.BytesIO()
    im.save(buf, fmt, **kw)
    return buf.getvalue()


# --------------------------------------------------------------------------------------------
# the format x layout matrix: (file bytes, expected RGB array, tolerance) built lazily


def _palette_case() -> tuple[bytes, np.ndarray]:
    palette = noise((16, 3), seed=11)
    idx = noise((H, W), seed=12) % 16
    return png_bytes(idx.astype(np.uint8), 3, palette=palette, trns=bytes(range(0, 256, 16))), palette[idx]


def _pil_palette(fmt: str) -> tuple[bytes, np.ndarray]:
    im = Image.fromarray(smooth_rgb()).quantize(32)
    return pil_bytes(im, fmt), np.asarray(im.convert("RGB"))


def _cmyk_jpeg() -> tuple[bytes, np.ndarray]:
    cmy = 255 - smooth_rgb()
    cmyk = np.dstack([cmy, np.zeros((H, W), np.uint8)])
    return pil_bytes(Image.fromarray(cmyk, "CMYK"), "JPEG", quality=95), smooth_rgb()


def _bilevel(fmt: str) -> tuple[bytes, np.ndarray]:
    bits = noise((H, W), seed=21) > 127
    return pil_bytes(Image.fromarray(bits), fmt), gray3(bits.astype(np.uint8) * 255)


RGB, GRAY, RGBA = smooth_rgb(), noise((H, W), seed=5), noise((H, W, 4), seed=6)
RGB16, GRAY16, RGBA16 = (
    noise((H, W, 3), np.uint16, 7),
    noise((H, W), np.uint16, 8),
    noise((H, W, 4), np.uint16, 9),
)
LA8, LA16 = noise((H, W, 2), seed=10), noise((H, W, 2), np.uint16, 13)
SMOOTH_GRAY = smooth_rgb()[..., 1]

# id -> () -> (data, expected, tolerance); tolerance 0 means exact (and same dtype)
CASES: dict[str, Callable[[], tuple[bytes, np.ndarray, float]]] = {
    # PNG
    "png-rgb-cv2": lambda: (cv2_bytes(".png", RGB), RGB, 0),
    "png-rgb-own": lambda: (png_bytes(RGB, 2), RGB, 0),
    "png-gray-cv2": lambda: (cv2_bytes(".png", GRAY), gray3(GRAY), 0),
    "png-gray-own": lambda: (png_bytes(GRAY, 0), gray3(GRAY), 0),
    "png-rgba-cv2": lambda: (cv2_bytes(".png", RGBA), RGBA[..., :3], 0),
    "png-rgba-own": lambda: (png_bytes(RGBA, 6), RGBA[..., :3], 0),
    "png-gray-alpha": lambda: (png_bytes(LA8, 4), gray3(LA8[..., 0]), 0),
    "png-palette-trns": lambda: (*_palette_case(), 0),
    "png-palette-pil": lambda: (*_pil_palette("PNG"), 0),
    "png-bilevel": lambda: (*_bilevel("PNG"), 0),
    "png-gray16-cv2": lambda: (cv2_bytes(".png", GRAY16), gray3(as16(GRAY16)), 0),
    "png-gray16-own": lambda: (png_bytes(GRAY16, 0), gray3(as16(GRAY16)), 0),
    "png-rgb16-cv2": lambda: (cv2_bytes(".png", RGB16), as16(RGB16), 0),
    "png-rgb16-own": lambda: (png_bytes(RGB16, 2), as16(RGB16), 0),
    "png-rgba16-cv2": lambda: (cv2_bytes(".png", RGBA16), as16(RGBA16[..., :3]), 0),
    "png-rgba16-own": lambda: (png_bytes(RGBA16, 6), as16(RGBA16[..., :3]), 0),
    "png-gray-alpha16": lambda: (png_bytes(LA16, 4), gray3(as16(LA16[..., 0])), 0),
    # TIFF
    "tiff-rgb-pil": lambda: (pil_bytes(RGB, "TIFF"), RGB, 0),
    "tiff-rgb-lzw": lambda: (pil_bytes(RGB, "TIFF", compression="tiff_lzw"), RGB, 0),
    "tiff-rgb-deflate": lambda: (pil_bytes(RGB, "TIFF", compression="tiff_adobe_deflate"), RGB, 0),
    "tiff-rgb-cv2": lambda: (cv2_bytes(".tiff", RGB), RGB, 0),
    "tiff-rgb-own": lambda: (tiff_bytes(RGB), RGB, 0),
    "tiff-gray-pil": lambda: (pil_bytes(GRAY, "TIFF"), gray3(GRAY), 0),
    "tiff-gray-own-big-endian": lambda: (tiff_bytes(GRAY, order=">"), gray3(GRAY), 0),
    "tiff-rgba-pil": lambda: (pil_bytes(RGBA, "TIFF"), RGBA[..., :3], 0),
    "tiff-rgba-own": lambda: (tiff_bytes(RGBA), RGBA[..., :3], 0),
    "tiff-palette": lambda: (*_pil_palette("TIFF"), 0),
    "tiff-bilevel": lambda: (*_bilevel("TIFF"), 0),
    "tiff-gray16-pil": lambda: (pil_bytes(GRAY16, "TIFF"), gray3(as16(GRAY16)), 0),
    "tiff-gray16-cv2": lambda: (cv2_bytes(".tiff", GRAY16), gray3(as16(GRAY16)), 0),
    "tiff-gray16-own": lambda: (tiff_bytes(GRAY16), gray3(as16(GRAY16)), 0),
    "tiff-gray16-own-big-endian": lambda: (tiff_bytes(GRAY16, order=">"), gray3(as16(GRAY16)), 0),
    "tiff-rgb16-cv2": lambda: (cv2_bytes(".tiff", RGB16), as16(RGB16), 0),
    "tiff-rgb16-own": lambda: (tiff_bytes(RGB16), as16(RGB16), 0),
    "tiff-rgb16-own-big-endian": lambda: (tiff_bytes(RGB16, order=">"), as16(RGB16), 0),
    "tiff-rgba16-own": lambda: (tiff_bytes(RGBA16), as16(RGBA16[..., :3]), 0),
    # BMP
    "bmp-rgb-cv2": lambda: (cv2_bytes(".bmp", RGB), RGB, 0),
    "bmp-rgb-pil": lambda: (pil_bytes(RGB, "BMP"), RGB, 0),
    "bmp-gray-cv2": lambda: (cv2_bytes(".bmp", GRAY), gray3(GRAY), 0),
    "bmp-gray-pil": lambda: (pil_bytes(GRAY, "BMP"), gray3(GRAY), 0),
    "bmp-rgba-pil": lambda: (pil_bytes(RGBA, "BMP"), RGBA[..., :3], 0),
    "bmp-palette": lambda: (*_pil_palette("BMP"), 0),
    "bmp-bilevel": lambda: (*_bilevel("BMP"), 0),
    # JPEG (lossy: smooth content, mean error bound)
    "jpeg-rgb-cv2": lambda: (cv2_bytes(".jpg", RGB, cv2.IMWRITE_JPEG_QUALITY, 95), RGB, 3),
    "jpeg-rgb-pil": lambda: (pil_bytes(RGB, "JPEG", quality=95), RGB, 3),
    "jpeg-rgb-progressive": lambda: (pil_bytes(RGB, "JPEG", quality=95, progressive=True), RGB, 3),
    "jpeg-gray-cv2": lambda: (
        cv2_bytes(".jpg", SMOOTH_GRAY, cv2.IMWRITE_JPEG_QUALITY, 95),
        gray3(SMOOTH_GRAY),
        2,
    ),
    "jpeg-gray-pil": lambda: (pil_bytes(SMOOTH_GRAY, "JPEG", quality=95), gray3(SMOOTH_GRAY), 2),
    "jpeg-cmyk": lambda: (*_cmyk_jpeg(), 3),
    # WebP
    "webp-rgb-lossless": lambda: (pil_bytes(RGB, "WEBP", lossless=True), RGB, 0),
    "webp-rgb-lossy": lambda: (pil_bytes(RGB, "WEBP", quality=95), RGB, 3),
    "webp-rgb-cv2-lossless": lambda: (cv2_bytes(".webp", RGB, cv2.IMWRITE_WEBP_QUALITY, 101), RGB, 0),
    "webp-gray-lossless": lambda: (pil_bytes(GRAY, "WEBP", lossless=True), gray3(GRAY), 0),
    "webp-rgba-lossless": lambda: (pil_bytes(RGBA, "WEBP", lossless=True, exact=True), RGBA[..., :3], 0),
    "webp-rgba-lossy": lambda: (pil_bytes(np.dstack([RGB, GRAY]), "WEBP", quality=95), RGB, 3),
}

FORMAT_OF = {"png": "PNG", "tiff": "TIFF", "bmp": "BMP", "jpeg": "JPEG", "webp": "WEBP"}


def check_image(out: np.ndarray, expected: np.ndarray, tolerance: float) -> None:
    assert out.shape == (*expected.shape[:2], 3)
    assert out.flags.c_contiguous and out.flags.writeable and out.flags.owndata
    if tolerance == 0:
        if expected.dtype == np.uint8:
            assert out.dtype == np.uint8
            np.testing.assert_array_equal(out, expected)
        else:  # 16-bit: float32 value / 257, the float64 oracle rounded once
            assert out.dtype == np.float32
            np.testing.assert_allclose(out, expected, rtol=2e-7, atol=0)
    else:
        assert out.dtype == np.uint8
        err = np.abs(out.astype(np.float64) - expected)
        assert err.mean() < tolerance, err.mean()
        assert np.abs(out.astype(np.float64).mean(axis=(0, 1)) - expected.mean(axis=(0, 1))).max() < tolerance


@pytest.mark.parametrize("case", sorted(CASES))
def test_formats_and_layouts_from_path(case: str, tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    data, expected, tolerance = CASES[case]()
    path = tmp_path / f"image.{case.split('-')[0]}"
    path.write_bytes(data)
    out = load_image(path)
    check_image(out, expected, tolerance)

    info = probe_image(path)
    assert info.format == FORMAT_OF[case.split("-")[0]]
    assert (info.width, info.height) == (W, H)
    assert info.shape == out.shape and info.dtype == out.dtype
    assert info.bit_depth == (16 if "16" in case else 8)
    assert capfd.readouterr().err == ""


@pytest.mark.parametrize(
    "case", ["png-rgb-own", "tiff-rgb16-own", "jpeg-rgb-pil", "webp-rgba-lossy", "bmp-gray-cv2"]
)
def test_bytes_and_path_inputs_agree(case: str, tmp_path: Path) -> None:
    data, _, _ = CASES[case]()
    path = tmp_path / "x.img"
    path.write_bytes(data)
    from_path = load_image(path)
    for source in (data, bytearray(data), memoryview(data), str(path)):
        out = load_image(source)
        assert out.dtype == from_path.dtype
        np.testing.assert_array_equal(out, from_path)
    assert probe_image(data) == probe_image(path) == probe_image(str(path))


def test_sixteen_bit_precision_is_kept() -> None:
    ramp = np.arange(0, 65536, 1, dtype=np.uint16).reshape(256, 256)
    for data in (png_bytes(ramp, 0), tiff_bytes(ramp), cv2_bytes(".png", np.dstack([ramp] * 3))):
        out = load_image(data)
        assert out.dtype == np.float32
        assert len(np.unique(out[..., 0])) == 65536  # no two 16-bit levels collapse
        assert out[0, 0, 0] == 0.0 and out[-1, -1, 0] == 255.0
        assert out[1, 1, 0] == np.float32(257 / 257)  # 257 * k -> exactly k


# --------------------------------------------------------------------------------------------
# channel order


RED = np.zeros((8, 12, 3), np.uint8)
RED[..., 0] = 255


@pytest.mark.parametrize(
    "data",
    [
        pytest.param(lambda: cv2_bytes(".png", RED), id="png-cv2"),
        pytest.param(lambda: cv2_bytes(".bmp", RED), id="bmp-cv2"),
        pytest.param(lambda: cv2_bytes(".tiff", RED), id="tiff-cv2"),
        pytest.param(lambda: cv2_bytes(".webp", RED, cv2.IMWRITE_WEBP_QUALITY, 101), id="webp-cv2"),
        pytest.param(lambda: cv2_bytes(".jpg", RED, cv2.IMWRITE_JPEG_QUALITY, 100), id="jpeg-cv2"),
        pytest.param(lambda: pil_bytes(RED, "JPEG", quality=100), id="jpeg-pil"),
        pytest.param(lambda: pil_bytes(RED, "WEBP", quality=100), id="webp-lossy-pil"),
        pytest.param(lambda: png_bytes(RED, 2), id="png-own"),
        pytest.param(lambda: png_bytes(np.dstack([RED, RED[..., :1]]), 6), id="png-rgba-own"),
        pytest.param(lambda: tiff_bytes(RED), id="tiff-own"),
    ],
)
def test_pure_red_comes_back_red(data: Callable[[], bytes]) -> None:
    out = load_image(data())
    assert out.dtype == np.uint8
    np.testing.assert_allclose(out.reshape(-1, 3).mean(axis=0), [255, 0, 0], atol=3)


@pytest.mark.parametrize(
    "data",
    [
        pytest.param(lambda: cv2_bytes(".png", RED.astype(np.uint16) * 257), id="png16-cv2"),
        pytest.param(lambda: cv2_bytes(".tiff", RED.astype(np.uint16) * 257), id="tiff16-cv2"),
        pytest.param(lambda: png_bytes(RED.astype(np.uint16) * 257, 2), id="png16-own"),
        pytest.param(lambda: tiff_bytes(RED.astype(np.uint16) * 257), id="tiff16-own"),
    ],
)
def test_pure_red_16bit_comes_back_red(data: Callable[[], bytes]) -> None:
    out = load_image(data())
    assert out.dtype == np.float32
    np.testing.assert_array_equal(out.reshape(-1, 3), np.tile([255.0, 0.0, 0.0], (8 * 12, 1)))


# --------------------------------------------------------------------------------------------
# EXIF orientation


def exif_block(orientation: int) -> bytes:
    exif = Image.Exif()
    exif[0x0112] = orientation
    return exif.tobytes()


def upright(a: np.ndarray, orientation: int) -> np.ndarray:
    """What a viewer shows for a stored array, per the EXIF definitions of the 8 values."""
    return {
        1: lambda: a,
        2: lambda: np.fliplr(a),
        3: lambda: np.rot90(a, 2),
        4: lambda: np.flipud(a),
        5: lambda: np.rot90(np.fliplr(a), 1),
        6: lambda: np.rot90(a, -1),
        7: lambda: np.rot90(np.fliplr(a), -1),
        8: lambda: np.rot90(a, 1),
    }[orientation]()


ORIENTED_WRITERS: dict[str, tuple[Callable[[np.ndarray, int], bytes], float]] = {
    "jpeg": (lambda a, o: pil_bytes(a, "JPEG", quality=95, exif=exif_block(o)), 4),
    "png": (lambda a, o: pil_bytes(a, "PNG", exif=exif_block(o)), 0),
    "png-own": (lambda a, o: png_bytes(a, 2, exif=exif_block(o)[6:]), 0),
    "webp": (lambda a, o: pil_bytes(a, "WEBP", lossless=True, exif=exif_block(o)), 0),
    "tiff-own": (lambda a, o: tiff_bytes(a, orientation=o), 0),
}


@pytest.mark.parametrize("orientation", range(1, 9))
@pytest.mark.parametrize("writer", sorted(ORIENTED_WRITERS))
def test_exif_orientation_is_applied(writer: str, orientation: int) -> None:
    write, tolerance = ORIENTED_WRITERS[writer]
    stored = quadrants()
    data = write(stored, orientation)
    out = load_image(data)
    expected = upright(stored, orientation)
    assert out.shape == expected.shape
    check_image(out, expected, tolerance)
    assert probe_image(data).orientation == orientation
    assert probe_image(data).shape == out.shape
    # Pillow's own implementation (an independent oracle) agrees
    with Image.open(io.BytesIO(data)) as im:
        shown = np.asarray(ImageOps.exif_transpose(im).convert("RGB"))
    assert shown.shape == out.shape
    if tolerance == 0:
        np.testing.assert_array_equal(out, shown)


@pytest.mark.parametrize(
    "exif", [b"Exif\x00\x00garbage", b"Exif\x00\x00II*\x00\xff\xff\xff\x7f", b"\x00" * 40]
)
def test_broken_exif_is_ignored(exif: bytes) -> None:
    data = png_bytes(RGB, 2, exif=exif)
    np.testing.assert_array_equal(load_image(data), RGB)
    assert probe_image(data).orientation == 1


# An EXIF block whose XResolution points far past its end: Pillow's own EXIF reader warns
# ("Truncated File Read") on it, an error in this suite, so load_image must not let Pillow parse it.
BAD_EXIF = (
    b"Exif\x00\x00II*\x00\x08\x00\x00\x00\x02\x00"
    + (struct.pack("<HHII", 0x011A, 5, 1, 0xFFFF) + struct.pack("<HHIHH", 0x0112, 3, 1, 6, 0))
    + b"\x00\x00\x00\x00"
)


def test_jpeg_with_malformed_exif_loads_without_warnings() -> None:
    data = pil_bytes(quadrants(), "JPEG", quality=95, exif=BAD_EXIF)
    with pytest.warns(UserWarning), Image.open(io.BytesIO(data)) as im:
        im.getexif().get(0x011A)  # the premise: Pillow itself complains about this block
    out = load_image(data)  # warnings are errors in this suite
    check_image(out, upright(quadrants(), 6), 4)  # orientation is read all the same
    assert probe_image(data).orientation == 6


def test_tiff_with_exif_pointer_past_the_end_is_corrupt() -> None:
    data = bytearray(tiff_bytes(RGB, orientation=1))
    # turn the Orientation entry into an EXIF-directory pointer to beyond the file
    entry = data.index(struct.pack("<HHI", 274, 3, 1))
    struct.pack_into("<HHII", data, entry, 34665, 4, 1, len(data) + 1000)
    with pytest.raises(InputError, match=r"'exif\.tif' is truncated or corrupt \(TIFF: directory at byte"):
        load_image(bytes(data), name="exif.tif")


def test_out_of_range_orientation_is_ignored() -> None:
    data = tiff_bytes(RGB, orientation=9)
    np.testing.assert_array_equal(load_image(data), RGB)


# --------------------------------------------------------------------------------------------
# truncated and corrupt files


TRUNCATABLE = {
    "png": lambda: png_bytes(noise((H, W, 3)), 2),
    "png-cv2": lambda: cv2_bytes(".png", RGB),
    "png16": lambda: cv2_bytes(".png", RGB16),
    "jpeg": lambda: pil_bytes(RGB, "JPEG", quality=95),
    "jpeg-progressive": lambda: pil_bytes(RGB, "JPEG", quality=95, progressive=True),
    "jpeg-exif": lambda: pil_bytes(RGB, "JPEG", quality=95, exif=exif_block(6)),
    "tiff-pil": lambda: pil_bytes(RGB, "TIFF"),
    "tiff-lzw": lambda: pil_bytes(RGB, "TIFF", compression="tiff_lzw"),
    "tiff-cv2": lambda: cv2_bytes(".tiff", RGB),  # directory at the end of the file
    "tiff16-own": lambda: tiff_bytes(RGB16),
    "webp-lossy": lambda: pil_bytes(RGB, "WEBP", quality=90),
    "webp-lossless": lambda: pil_bytes(RGB, "WEBP", lossless=True),
    "bmp": lambda: cv2_bytes(".bmp", RGB),
    "bmp-gray": lambda: cv2_bytes(".bmp", GRAY),
}


@pytest.mark.parametrize("keep", [0.1, 0.5, 0.9, -1, -2])
@pytest.mark.parametrize("kind", sorted(TRUNCATABLE))
def test_truncated_files_are_refused_quietly(
    kind: str, keep: float, tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    data = TRUNCATABLE[kind]()
    cut = data[: int(len(data) * keep)] if keep > 0 else data[: len(data) + int(keep)]
    path = tmp_path / f"cut.{kind}"
    path.write_bytes(cut)
    with pytest.raises(InputError, match=r"'.*cut\..*' is (truncated or corrupt|not a)") as err:
        load_image(path)
    assert "\n" not in str(err.value)
    out, errout = capfd.readouterr()
    assert out == "" and errout == ""  # no libjpeg / libpng / libtiff chatter


@pytest.mark.parametrize("kind", ["png", "png16", "tiff-lzw", "webp-lossy", "webp-lossless"])
def test_corrupt_middle_is_refused(kind: str, capfd: pytest.CaptureFixture[str]) -> None:
    data = bytearray(TRUNCATABLE[kind]())
    mid = len(data) // 2
    data[mid : mid + 64] = bytes(np.random.default_rng(0).integers(0, 256, 64, dtype=np.uint8))
    with pytest.raises(InputError, match=r"'broken\.img' is truncated or corrupt"):
        load_image(bytes(data), name="broken.img")
    if not kind.startswith("tiff"):
        # Known exception: libtiff reports bad compressed data through its process-wide error
        # handler, which Pillow leaves at "print to stderr" (the file is still refused).
        assert capfd.readouterr().err == ""


def test_corrupt_jpeg_data_does_not_print(capfd: pytest.CaptureFixture[str]) -> None:
    # Damaged entropy-coded data in a complete JPEG is undetectable without libjpeg's warning
    # count (OpenCV prints "Corrupt JPEG data" and decodes); it must at least stay quiet.
    data = bytearray(pil_bytes(noise((H, W, 3)), "JPEG", quality=90))
    data[len(data) // 2 : len(data) // 2 + 40] = b"\x55" * 40
    try:
        out = load_image(bytes(data))
        assert out.shape == (H, W, 3)
    except InputError:
        pass
    assert capfd.readouterr().err == ""


@pytest.mark.parametrize("seed", range(4))
def test_mutated_files_give_an_image_or_input_error(seed: int) -> None:
    """Random damage anywhere (header included) ends in a valid RGB array or an InputError:
    never another exception, never a warning (warnings are errors here)."""
    rng = np.random.default_rng(seed)
    seeds = [make()[0] for make in CASES.values()] + [make() for make in TRUNCATABLE.values()]
    for _ in range(150):
        data = bytearray(seeds[rng.integers(len(seeds))])
        where = int(rng.integers(min(len(data), 300))) if rng.random() < 0.5 else int(rng.integers(len(data)))
        data[where : where + int(rng.integers(1, 4))] = rng.integers(0, 256, 3, dtype=np.uint8).tobytes()
        for fn in (probe_image, load_image):
            try:
                out = fn(bytes(data))
            except InputError as err:
                assert "\n" not in str(err)
                continue
            if fn is load_image:
                assert out.ndim == 3 and out.shape[2] == 3 and out.dtype in (np.uint8, np.float32)


def test_random_bytes_are_not_an_image() -> None:
    junk = bytes(np.random.default_rng(1).integers(0, 256, 5000, dtype=np.uint8))
    assert not junk.startswith((b"BM", b"\x89P", b"\xff\xd8", b"II", b"MM", b"RIFF"))
    with pytest.raises(InputError, match=r"'junk\.png' is not a BMP, PNG, JPEG, TIFF or WebP image"):
        load_image(junk, name="junk.png")
    with pytest.raises(InputError, match="not a BMP"):
        probe_image(junk)


@pytest.mark.parametrize("magic", [b"\x89PNG\r\n\x1a\n", b"\xff\xd8\xff\xe0", b"II*\x00", b"MM\x00*", b"BM"])
def test_random_bytes_after_a_signature_are_corrupt(magic: bytes) -> None:
    junk = magic + bytes(np.random.default_rng(2).integers(0, 256, 3000, dtype=np.uint8))
    with pytest.raises(InputError, match=r"'fake\.img' is truncated or corrupt"):
        load_image(junk, name="fake.img")


def test_webp_signature_with_junk_is_corrupt() -> None:
    junk = b"RIFF" + struct.pack("<I", 3000) + b"WEBPVP8 " + bytes(3000)
    with pytest.raises(InputError, match="truncated or corrupt"):
        load_image(junk)


@pytest.mark.parametrize(
    ("data", "kind"),
    [
        (lambda: pil_bytes(RGB, "GIF"), "GIF"),
        (lambda: b"\x00\x00\x00\x18ftypheic" + bytes(100), "HEIF"),
        (lambda: b"%PDF-1.7\n" + bytes(100), "PDF"),
    ],
)
def test_other_formats_are_named(data: Callable[[], bytes], kind: str) -> None:
    with pytest.raises(
        InputError, match=rf"'photo' is a {kind}.*supported formats are BMP, PNG, JPEG, TIFF, WebP"
    ):
        load_image(data(), name="photo")


def test_empty_file_and_bytes(tmp_path: Path) -> None:
    path = tmp_path / "empty.jpg"
    path.write_bytes(b"")
    with pytest.raises(InputError, match=r"'.*empty\.jpg' is empty \(0 bytes\)"):
        load_image(path)
    with pytest.raises(InputError, match="is empty"):
        probe_image(path)
    with pytest.raises(InputError, match=r"'upload\.png' is empty"):
        load_image(b"", name="upload.png")


def test_missing_path_and_directory(tmp_path: Path) -> None:
    missing = tmp_path / "nope.png"
    with pytest.raises(InputError, match=r"image file '.*nope\.png' does not exist"):
        load_image(missing)
    with pytest.raises(InputError, match="does not exist"):
        probe_image(str(missing))
    with pytest.raises(InputError, match="is a directory"):
        load_image(tmp_path)
    with pytest.raises(InputError, match="is a directory"):
        probe_image(tmp_path)
    with pytest.raises(InputError, match="not a valid path"):
        load_image("bad\x00name.png")


@pytest.mark.parametrize("source", [None, 42, 3.5, ["a.png"]])
def test_wrong_source_type(source: object) -> None:
    with pytest.raises(InputError, match="must be a path or bytes"):
        load_image(source)  # type: ignore[arg-type]


@pytest.mark.parametrize("limit", [0, -5, 2.5, True, "100", None])
def test_bad_max_pixels(limit: object) -> None:
    with pytest.raises(InputError, match="max_pixels"):
        load_image(png_bytes(RGB, 2), max_pixels=limit)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("real", "suffix"),
    [("png", ".jpg"), ("jpeg", ".png"), ("webp", ".bmp"), ("tiff", ".webp"), ("bmp", ".tif"), ("png", "")],
)
def test_mislabelled_extension_loads_by_content(real: str, suffix: str, tmp_path: Path) -> None:
    writers = {
        "png": lambda: cv2_bytes(".png", RGB),
        "jpeg": lambda: cv2_bytes(".jpg", RGB, cv2.IMWRITE_JPEG_QUALITY, 95),
        "webp": lambda: pil_bytes(RGB, "WEBP", lossless=True),
        "tiff": lambda: pil_bytes(RGB, "TIFF"),
        "bmp": lambda: cv2_bytes(".bmp", RGB),
    }
    path = tmp_path / f"photo{suffix}"
    path.write_bytes(writers[real]())
    check_image(load_image(path), RGB, 3 if real == "jpeg" else 0)
    assert probe_image(path).format == FORMAT_OF[real]


# --------------------------------------------------------------------------------------------
# decompression bombs and the pixel limit


def bomb_png(width: int = 100_000, height: int = 100_000) -> bytes:
    """A valid 100-odd-byte PNG header declaring width x height RGB, with a token IDAT."""
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    idat = zlib.compress(b"\x00" * 1000, 9)
    return (
        b"\x89PNG\r\n\x1a\n" + png_chunk(b"IHDR", ihdr) + png_chunk(b"IDAT", idat) + png_chunk(b"IEND", b"")
    )


def bomb_jpeg(width: int = 60_000, height: int = 60_000) -> bytes:
    """A real small JPEG whose SOF0 frame header is rewritten to declare a huge size."""
    data = bytearray(pil_bytes(RGB, "JPEG"))
    sof = data.index(b"\xff\xc0")
    struct.pack_into(">HH", data, sof + 5, height, width)
    return bytes(data)


def bomb_bmp(width: int = 30_000, height: int = 30_000) -> bytes:
    data = bytearray(pil_bytes(RGB, "BMP"))
    struct.pack_into("<ii", data, 18, width, height)
    return bytes(data)


def bomb_webp(width: int = 16_000, height: int = 16_000) -> bytes:
    """A lossless WebP whose VP8X canvas is declared huge (Pillow would allocate it on open)."""
    payload = pil_bytes(RGB, "WEBP", lossless=True)[12:]  # the VP8L chunk
    vp8x = b"VP8X" + struct.pack("<I", 10) + b"\x00" * 4
    vp8x += (width - 1).to_bytes(3, "little") + (height - 1).to_bytes(3, "little")
    body = b"WEBP" + vp8x + payload
    return b"RIFF" + struct.pack("<I", len(body)) + body


BOMBS = {
    "png": (bomb_png, (100_000, 100_000)),
    "jpeg": (bomb_jpeg, (60_000, 60_000)),
    "bmp": (bomb_bmp, (30_000, 30_000)),
    "webp": (bomb_webp, (16_000, 16_000)),
    "tiff": (lambda: tiff_bytes(RGB, size=(90_000, 90_000)), (90_000, 90_000)),
}


@pytest.mark.parametrize("kind", sorted(BOMBS))
def test_decompression_bombs_are_refused_fast(kind: str, tmp_path: Path) -> None:
    make, (w, h) = BOMBS[kind]
    data = make()
    assert len(data) < 20_000
    path = tmp_path / "bomb.img"
    path.write_bytes(data)
    before = Image.MAX_IMAGE_PIXELS
    tracemalloc.start()
    try:
        # CPU time, not the wall clock: decoding the declared pixels would cost seconds of it,
        # while other processes on a loaded machine cost this one none.
        t0 = time.process_time()
        with pytest.raises(InputError) as err:
            load_image(path)
        elapsed = time.process_time() - t0
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    msg = str(err.value)
    assert f"{w}x{h}" in msg and str(w * h) in msg and str(DEFAULT_MAX_PIXELS) in msg, msg
    assert "bomb.img" in msg
    assert elapsed < 0.5
    assert peak < 5_000_000  # nothing of the declared size was allocated
    assert before == Image.MAX_IMAGE_PIXELS  # Pillow's global limit untouched
    # probing only reads the header and reports the declared size
    info = probe_image(path)
    assert (info.width, info.height, info.pixels) == (w, h, w * h)


@pytest.mark.parametrize(
    "case", ["png-rgb-own", "jpeg-rgb-pil", "webp-rgb-lossless", "tiff-rgb16-own", "bmp-rgb-cv2"]
)
def test_pixel_limit_boundary(case: str) -> None:
    data, expected, tolerance = CASES[case]()
    check_image(load_image(data, max_pixels=H * W), expected, tolerance)
    with pytest.raises(
        InputError, match=rf"'small\.img' is {W}x{H} = {W * H} pixels, over the limit of {W * H - 1} pixels"
    ):
        load_image(data, max_pixels=H * W - 1, name="small.img")


@pytest.mark.parametrize("case", ["tiff-rgb-pil", "webp-rgb-lossless", "png-rgb-own"])
def test_limit_above_pillows_own(case: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """A caller may allow more than Pillow's global limit; Pillow's own checks must then neither
    warn (warnings are errors here) nor escape as anything but InputError."""
    data, expected, tolerance = CASES[case]()
    monkeypatch.setattr(Image, "MAX_IMAGE_PIXELS", H * W // 3 * 2)  # between 1x and 2x: warns
    check_image(load_image(data, max_pixels=10**9), expected, tolerance)
    monkeypatch.setattr(Image, "MAX_IMAGE_PIXELS", H * W // 4)  # beyond 2x: Pillow refuses
    if case == "png-rgb-own":  # Pillow re-checks only TIFF and WebP while decoding
        check_image(load_image(data, max_pixels=10**9), expected, tolerance)
    else:
        with pytest.raises(InputError, match="decompression-bomb limit"):
            load_image(data, max_pixels=10**9)


# --------------------------------------------------------------------------------------------
# probe, purity, speed path


def test_probe_reports_header_fields() -> None:
    assert probe_image(cv2_bytes(".png", RGB16)) == ImageInfo(W, H, "PNG", "RGB", 16, 1)
    assert probe_image(pil_bytes(GRAY16, "TIFF")) == ImageInfo(W, H, "TIFF", "I;16", 16, 1)
    assert probe_image(pil_bytes(RGBA, "WEBP", lossless=True)) == ImageInfo(W, H, "WEBP", "RGBA", 8, 1)
    assert probe_image(pil_bytes(RGB, "WEBP", quality=80)).mode == "RGB"
    jpeg = probe_image(pil_bytes(RGB, "JPEG", exif=exif_block(6)), name="a.jpg")
    assert jpeg == ImageInfo(W, H, "JPEG", "RGB", 8, 6, "4:2:0")  # Pillow's default sampling
    assert jpeg.shape == (W, H, 3) and jpeg.dtype == np.uint8 and jpeg.pixels == W * H
    assert probe_image(_palette_case()[0]).mode == "P"


@pytest.mark.parametrize(("sampling", "chroma"), [(cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444, "4:4:4"),
                                                  (cv2.IMWRITE_JPEG_SAMPLING_FACTOR_422, "4:2:2"),
                                                  (cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420, "4:2:0")])
def test_probe_reads_a_jpegs_colour_sampling(sampling: int, chroma: str) -> None:
    data = cv2_bytes(".jpg", RGB, cv2.IMWRITE_JPEG_SAMPLING_FACTOR, sampling)
    assert probe_image(data).chroma == chroma
    assert probe_image(cv2_bytes(".jpg", RGB[..., 0])).chroma is None  # grey: no colour to sample
    assert probe_image(cv2_bytes(".png", RGB)).chroma is None


def test_thirty_two_bit_tiff_is_refused() -> None:
    data = pil_bytes(Image.fromarray(np.ones((H, W), np.float32)), "TIFF")
    assert probe_image(data).bit_depth == 32
    with pytest.raises(InputError, match=r"'f\.tif' has 32-bit samples in mode 'F'"):
        load_image(data, name="f.tif")


def test_pillow_globals_are_left_alone() -> None:
    before = (Image.MAX_IMAGE_PIXELS, ImageFile.LOAD_TRUNCATED_IMAGES)
    load_image(pil_bytes(RGB, "TIFF"))
    with pytest.raises(InputError):
        load_image(bomb_png())
    with pytest.raises(InputError):
        load_image(pil_bytes(RGB, "PNG")[:-100])
    assert before == (Image.MAX_IMAGE_PIXELS, ImageFile.LOAD_TRUNCATED_IMAGES)


def test_eight_bit_images_are_decoded_once_without_opencv(monkeypatch: pytest.MonkeyPatch) -> None:
    def refuse(*args: object, **kwargs: object) -> None:
        raise AssertionError("OpenCV decode on the 8-bit path")

    monkeypatch.setattr(images.cv2, "imdecode", refuse)
    for case in (
        "jpeg-rgb-pil",
        "png-rgb-own",
        "webp-rgb-lossy",
        "tiff-rgb-lzw",
        "bmp-gray-cv2",
        "png-gray16-own",
    ):
        data, expected, tolerance = CASES[case]()
        check_image(load_image(data), expected, tolerance)


def test_result_is_the_callers_to_modify() -> None:
    data = pil_bytes(RGB, "PNG")
    a = load_image(data)
    a[...] = 0
    np.testing.assert_array_equal(load_image(data), RGB)
