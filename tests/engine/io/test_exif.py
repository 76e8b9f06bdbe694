"""Focal length from EXIF: reading the fields from real image files, and the conversion to pixels.

Oracles are independent of the code's formulas:

* the focal length in pixels of a sensor of known pixel pitch is ``f_mm / pitch_mm`` (the
  definition of the pinhole projection in pixels), whatever unit the focal plane resolution is
  written in;
* a 35 mm-equivalent focal length gives the same *diagonal angle of view* as the photo:
  ``2 atan(43.27 / 2 / f35) == 2 atan(diag_px / 2 / f_px)``;
* the iPhone-like camera (4032 x 3024 px, 1.4 um pixels, a 4.25 mm lens, 26 mm equivalent) has
  its two routes agree to the rounding of the 35 mm value (0.3 %).

EXIF blocks are written both by Pillow (``Image.Exif``, as cameras' files are read) and by the
minimal TIFF writer below (struct only), which can also write what Pillow would not: zero
denominators, wrong types, pointers past the end, truncated blocks.
"""

from __future__ import annotations

import dataclasses
import gzip
import io
import math
import struct
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PIL import Image, TiffImagePlugin
from PIL.TiffImagePlugin import IFDRational

from prismcore.errors import InputError
from prismcore.io.exif import (
    CameraExif,
    ExifFocal,
    NoExifFocal,
    camera_key,
    explain_exif_focal,
    focal_px_from_exif,
    read_camera_exif,
)
from prismcore.io.images import load_image

# The iPhone-like camera: 4032 x 3024 px of 1.4 um, a 4.25 mm lens sold as "26 mm".
PITCH_MM = 0.0014
F_MM = 4.25
F35 = 26
FULL = (4032, 3024)
F_PX_PLANE = F_MM / PITCH_MM  # 3035.714 px: the pinhole focal length in pixels of the sensor
# 4032 x 3024 is a 3-4-5 triangle: diagonal 5040 px exactly; the 36 x 24 mm frame's is 43.2667 mm.
F_PX_35 = 5040 / 2 / math.tan(math.atan(43.26661530556787 / 2 / F35))  # same diagonal angle of view

# ExifIFD tags
MAKE, MODEL, ORIENTATION, EXIF_IFD = 0x010F, 0x0110, 0x0112, 0x8769
FOCAL, PIX_X, PIX_Y, F35_TAG, LENS = 0x920A, 0xA002, 0xA003, 0xA405, 0xA434
FP_X, FP_Y, FP_UNIT = 0xA20E, 0xA20F, 0xA210

ASCII, SHORT, LONG, RATIONAL, UNDEFINED, SRATIONAL = 2, 3, 4, 5, 7, 10

OPENCV_EXAMPLES = Path("/usr/share/doc/opencv-doc/examples")


# --------------------------------------------------------------------------------------------
# writing EXIF


def pillow_exif(
    *,
    make: str | None = "Apple",
    model: str | None = "iPhone 13",
    orientation: int | None = None,
    size: tuple[int, int] | None = FULL,
    f35: int | None = F35,
    f_mm: float | None = F_MM,
    plane_unit: int | None = 3,
    lens: str | None = None,
) -> Image.Exif:
    """An EXIF block written by Pillow, the iPhone-like camera by default."""
    exif = Image.Exif()
    for tag, value in ((MAKE, make), (MODEL, model), (ORIENTATION, orientation)):
        if value is not None:
            exif[tag] = value
    sub = exif.get_ifd(EXIF_IFD)
    if size is not None:
        sub[PIX_X], sub[PIX_Y] = size
    if f35 is not None:
        sub[F35_TAG] = f35
    if f_mm is not None:
        sub[FOCAL] = IFDRational(round(f_mm * 100), 100)
    if plane_unit is not None:
        # unit length / 1.4 um, as an exact fraction: 254000/14 per inch ... 10/14 per um
        per_unit = {2: 254_000, 3: 100_000, 4: 10_000, 5: 10}[plane_unit]
        sub[FP_X] = sub[FP_Y] = IFDRational(per_unit, 14)
        sub[FP_UNIT] = plane_unit
    if lens is not None:
        sub[LENS] = lens
    return exif


Entries = dict[int, tuple[int, Any]]


def _pack(bo: str, typ: int, values: Any) -> tuple[bytes, int]:
    if typ == ASCII:
        raw = values.encode("latin-1") + b"\x00"
        return raw, len(raw)
    if typ == UNDEFINED:
        return values, len(values)
    if typ in (SHORT, LONG):
        fmt = "H" if typ == SHORT else "I"
        return struct.pack(bo + fmt * len(values), *values), len(values)
    flat = [v for pair in values for v in pair]  # (numerator, denominator) pairs
    fmt = "I" if typ == RATIONAL else "i"
    return struct.pack(bo + fmt * len(flat), *flat), len(values)


def tiff_block(
    ifd0: Entries, exif: Entries | None = None, *, bo: str = "<", exif_at: int | None = None
) -> bytes:
    """An APP1 EXIF payload ("Exif\\0\\0" + TIFF structure) written with struct only.

    Entries are tag -> (field type, values); ``exif_at`` overrides the Exif IFD pointer.
    """
    ifd0 = dict(ifd0)
    if exif is not None:
        ifd0[EXIF_IFD] = (LONG, [0])
    start1 = 8 + 2 + 12 * len(ifd0) + 4
    data_at = start1 + (2 + 12 * len(exif) + 4 if exif is not None else 0)
    if exif is not None:
        ifd0[EXIF_IFD] = (LONG, [start1 if exif_at is None else exif_at])
    data = bytearray()

    def ifd(entries: Entries) -> bytes:
        out = struct.pack(bo + "H", len(entries))
        for tag in sorted(entries):
            typ, values = entries[tag]
            raw, count = _pack(bo, typ, values)
            if len(raw) <= 4:
                field = raw.ljust(4, b"\x00")
            else:
                field = struct.pack(bo + "I", data_at + len(data))
                data.extend(raw + b"\x00" * (len(raw) & 1))
            out += struct.pack(bo + "HHI", tag, typ, count) + field
        return out + struct.pack(bo + "I", 0)

    body = ifd(ifd0) + (ifd(exif) if exif is not None else b"")
    head = (b"II" if bo == "<" else b"MM") + struct.pack(bo + "HI", 42, 8)
    return b"Exif\x00\x00" + head + body + bytes(data)


def iphone_entries() -> tuple[Entries, Entries]:
    """IFD0 and Exif IFD of the iPhone-like camera, for the struct writer."""
    ifd0 = {MAKE: (ASCII, "Apple"), MODEL: (ASCII, "iPhone 13")}
    sub = {
        PIX_X: (LONG, [FULL[0]]), PIX_Y: (LONG, [FULL[1]]), F35_TAG: (SHORT, [F35]),
        FOCAL: (RATIONAL, [(425, 100)]),
        FP_X: (RATIONAL, [(10_000_000, 1400)]), FP_Y: (RATIONAL, [(10_000_000, 1400)]), FP_UNIT: (SHORT, [3]),
    }  # fmt: skip
    return ifd0, sub


def photo(exif: Image.Exif | bytes | None, size: tuple[int, int] = (64, 48), fmt: str = "JPEG") -> bytes:
    """A small image file (stored size ``size``) carrying ``exif``."""
    x = np.linspace(0, 255, size[0], dtype=np.uint8)
    im = Image.fromarray(np.broadcast_to(x[None, :, None], (size[1], size[0], 3)).copy())
    buf = io.BytesIO()
    if fmt == "TIFF" and isinstance(exif, Image.Exif):
        # Pillow's TIFF writer keeps the Exif IFD only when it is given as a nested directory.
        info = TiffImagePlugin.ImageFileDirectory_v2()
        for tag, value in exif.items():
            info[tag] = value
        info[EXIF_IFD] = exif.get_ifd(EXIF_IFD)
        im.save(buf, fmt, tiffinfo=info)
    else:
        im.save(buf, fmt, **({} if exif is None else {"exif": exif}))
    return buf.getvalue()


def decoded_size(data: bytes) -> tuple[int, int]:
    """(width, height) of the image load_image returns for ``data``."""
    h, w = load_image(data).shape[:2]
    return w, h


def iphone(**changes: Any) -> CameraExif:
    base = CameraExif(make="Apple", model="iPhone 13", pixel_width=FULL[0], pixel_height=FULL[1],
                      focal_35mm=float(F35), focal_mm=F_MM, focal_plane_x_res=10 / PITCH_MM,
                      focal_plane_y_res=10 / PITCH_MM, focal_plane_unit=3)  # fmt: skip
    return dataclasses.replace(base, **changes)


# --------------------------------------------------------------------------------------------
# the oracles themselves


def test_the_two_oracles_agree_for_the_iphone_like_camera():
    # 26 mm is the 35 mm value rounded to the mm: 4.25 mm x crop factor 43.27 / (5040 x 1.4 um).
    assert abs(F_MM * 43.26661530556787 / (5040 * PITCH_MM) - F35) < 0.5
    assert abs(F_PX_35 / F_PX_PLANE - 1) < 0.003
    assert abs(F_PX_35 - 3028.66) < 0.01  # 131040 / 43.2666


# --------------------------------------------------------------------------------------------
# reading


@pytest.mark.parametrize("fmt", ["JPEG", "PNG", "WEBP", "TIFF"])
def test_reads_the_camera_fields_from_every_format(fmt):
    data = photo(pillow_exif(orientation=6, lens="iPhone 13 back camera 4.25mm f/1.6"), fmt=fmt)
    exif = read_camera_exif(data)
    assert exif == CameraExif(
        make="Apple", model="iPhone 13", lens_model="iPhone 13 back camera 4.25mm f/1.6", orientation=6,
        pixel_width=4032, pixel_height=3024, focal_35mm=26.0, focal_mm=4.25,
        focal_plane_x_res=pytest.approx(10 / PITCH_MM, rel=1e-6),
        focal_plane_y_res=pytest.approx(10 / PITCH_MM, rel=1e-6), focal_plane_unit=3,
    )  # fmt: skip
    assert exif.turned


@pytest.mark.parametrize("bo", ["<", ">"])
def test_struct_written_block_reads_as_pillow_written_one(bo):
    ifd0, sub = iphone_entries()
    from_struct = read_camera_exif(photo(tiff_block(ifd0, sub, bo=bo)))
    from_pillow = read_camera_exif(photo(pillow_exif()))
    assert from_struct == from_pillow
    assert from_struct is not None and from_struct.orientation == 1


def test_a_bare_exif_block_is_read_with_its_own_orientation():
    exif = read_camera_exif(pillow_exif(orientation=8).tobytes())
    assert exif is not None and exif.orientation == 8 and exif.focal_35mm == 26.0


@pytest.mark.parametrize("data", [photo(None), photo(None, fmt="PNG"), b"", b"not an image", b"Exif\x00\x00"])
def test_no_exif_reads_as_none(data):
    assert read_camera_exif(data) is None


@pytest.mark.parametrize("bad", ["photo.jpg", None, 12])
def test_a_source_that_is_not_bytes_is_an_input_error(bad):
    with pytest.raises(InputError, match=type(bad).__name__):
        read_camera_exif(bad)


@pytest.mark.parametrize("orientation, read", [(1, 1), (3, 3), (6, 6), (8, 8), (0, 1), (9, 1), (400, 1)])
def test_orientation_is_what_load_image_applies(orientation, read):
    data = photo(pillow_exif(orientation=orientation))
    exif = read_camera_exif(data)
    assert exif is not None and exif.orientation == read
    w, h = decoded_size(data)
    assert (w, h) == ((48, 64) if read >= 5 else (64, 48))


def test_orientation_load_image_ignores_is_ignored_here_too():
    # Written as a RATIONAL 6/1 (TIFF says SHORT): Pillow reads 6, load_image does not turn.
    ifd0, sub = iphone_entries()
    ifd0[ORIENTATION] = (RATIONAL, [(6, 1)])
    data = photo(tiff_block(ifd0, sub))
    assert decoded_size(data) == (64, 48)
    exif = read_camera_exif(data)
    assert exif is not None and exif.orientation == 1
    assert focal_px_from_exif(exif, 64, 48).focal_px == pytest.approx(F_PX_35 / 63)


def test_strings_are_cleaned_and_absent_fields_are_none():
    block = tiff_block({MAKE: (ASCII, "  Canon\x00\x00  "), MODEL: (UNDEFINED, b"EOS\x01 5D\x00")})
    assert read_camera_exif(photo(block)) == CameraExif(make="Canon", model="EOS 5D")


@pytest.mark.parametrize(
    "field, entry",
    [
        ("focal_mm", (FOCAL, (RATIONAL, [(425, 0)]))),  # zero denominator
        ("focal_mm", (FOCAL, (RATIONAL, [(0, 0)]))),
        ("focal_mm", (FOCAL, (RATIONAL, [(0, 1)]))),  # 0: unknown
        ("focal_mm", (FOCAL, (SRATIONAL, [(-425, 100)]))),
        ("focal_mm", (FOCAL, (ASCII, "4.25mm"))),
        ("focal_plane_x_res", (FP_X, (RATIONAL, [(7142, 0)]))),
        ("focal_35mm", (F35_TAG, (SHORT, [0]))),
        ("focal_35mm", (F35_TAG, (ASCII, "26"))),
        ("pixel_width", (PIX_X, (RATIONAL, [(1, 3)]))),  # not an integer
        ("pixel_width", (PIX_X, (LONG, []))),  # no value at all
    ],
)
def test_a_broken_value_reads_as_missing_and_leaves_the_others(field, entry):
    ifd0, sub = iphone_entries()
    sub[entry[0]] = entry[1]
    exif = read_camera_exif(photo(tiff_block(ifd0, sub)))
    assert exif is not None
    assert getattr(exif, field) is None
    assert dataclasses.replace(exif, **{field: getattr(iphone(), field)}) == iphone()


def test_a_tag_with_two_values_reads_its_first():
    ifd0, sub = iphone_entries()
    sub[PIX_X] = (LONG, [4032, 17])
    exif = read_camera_exif(photo(tiff_block(ifd0, sub)))
    assert exif is not None and exif.pixel_width == 4032


@pytest.mark.parametrize("exif_at", [10**6, 3, 0xFFFFFFFF])
def test_an_exif_pointer_past_the_end_keeps_make_and_model(exif_at):
    ifd0, sub = iphone_entries()
    exif = read_camera_exif(photo(tiff_block(ifd0, sub, exif_at=exif_at)))
    assert exif is not None and (exif.make, exif.model) == ("Apple", "iPhone 13")
    assert exif.focal_35mm is None or exif.focal_35mm == 26.0  # pointer 3 lands in the header


def test_every_truncation_of_the_block_reads_without_error_and_never_a_wrong_focal():
    block = pillow_exif().tobytes()
    outcomes = set()
    for n in range(len(block) + 1):
        exif = read_camera_exif(photo(block[:n]))
        found = None if exif is None else focal_px_from_exif(exif, *FULL)
        if found is not None:  # what survived the cut must be the true value
            assert found.focal_px in (pytest.approx(F_PX_35), pytest.approx(F_PX_PLANE))
        outcomes.add("none" if exif is None else "focal" if found else "fields")
    assert outcomes == {"none", "fields", "focal"}


def test_random_damage_to_the_block_never_raises():
    block = bytearray(pillow_exif(orientation=6).tobytes())
    rng = np.random.default_rng(7)
    read = 0
    for _ in range(300):
        damaged = bytearray(block)
        at = rng.integers(6, len(block), size=rng.integers(1, 6))
        for i in at:
            damaged[i] = int(rng.integers(0, 256))
        exif = read_camera_exif(photo(bytes(damaged)))
        if exif is not None:
            read += 1
            found = focal_px_from_exif(exif, 48, 64)
            assert found is None or 0.2 * 80 <= found.focal_px <= 10 * 80
    assert read > 100  # most one-byte damage leaves a readable block


# --------------------------------------------------------------------------------------------
# the conversion to pixels


def test_35mm_equivalent_matches_the_diagonal_angle_of_view():
    found = focal_px_from_exif(iphone(focal_mm=None), *FULL)
    assert found == ExifFocal(pytest.approx(F_PX_35, rel=1e-9), "FocalLengthIn35mmFilm 26 mm")
    fov_35mm = 2 * math.atan(math.hypot(36, 24) / 2 / F35)
    assert 2 * math.atan(5040 / 2 / found.focal_px) == pytest.approx(fov_35mm, rel=1e-12)


@pytest.mark.parametrize("unit, per_unit_mm, name", [(2, 25.4, "in"), (3, 10.0, "cm"), (4, 1.0, "mm"),
                                                     (5, 0.001, "um")])  # fmt: skip
def test_focal_plane_resolution_gives_focal_over_pixel_pitch_in_any_unit(unit, per_unit_mm, name):
    exif = read_camera_exif(photo(pillow_exif(f35=None, plane_unit=unit)))
    assert exif is not None and exif.focal_35mm is None
    found = focal_px_from_exif(exif, *FULL)
    assert found is not None
    assert found.focal_px == pytest.approx(F_PX_PLANE, rel=1e-6)
    resolution = per_unit_mm / PITCH_MM
    assert found.basis.startswith(f"FocalLength 4.25 mm at {resolution:.6g} px/{name} focal plane")


def test_the_focal_plane_unit_defaults_to_inches():
    ifd0, sub = iphone_entries()
    del sub[F35_TAG], sub[FP_UNIT]
    sub[FP_X] = sub[FP_Y] = (RATIONAL, [(254_000, 14)])  # 25.4 mm / 1.4 um, per inch
    exif = read_camera_exif(photo(tiff_block(ifd0, sub)))
    assert exif is not None and exif.focal_plane_unit == 2
    assert focal_px_from_exif(exif, *FULL).focal_px == pytest.approx(F_PX_PLANE, rel=1e-9)


def test_tiff_ep_focal_plane_tags_in_ifd0():
    # TIFF/EP (raw files) numbers them 0x920E/0x920F/0x9210 and keeps them in IFD0; unit 4 = mm.
    ifd0 = {MAKE: (ASCII, "Nikon"), FOCAL: (RATIONAL, [(425, 100)]),
            0x920E: (RATIONAL, [(10_000, 14)]), 0x920F: (RATIONAL, [(10_000, 14)]), 0x9210: (SHORT, [4])}
    exif = read_camera_exif(photo(tiff_block(ifd0)))
    assert exif is not None and exif.focal_plane_unit == 4 and exif.pixel_width is None
    found = focal_px_from_exif(exif, *FULL)
    assert found.focal_px == pytest.approx(F_PX_PLANE, rel=1e-9) and "px/mm" in found.basis


def test_numpy_integer_sizes_are_accepted():
    assert focal_px_from_exif(iphone(), np.int64(4032), np.int32(3024)).focal_px == pytest.approx(F_PX_35)


def test_both_present_prefers_the_35mm_value_even_under_digital_zoom():
    # A 2x digital zoom: the lens is still 4.25 mm, the centre crop is upsampled to 4032 x 3024,
    # so the angle of view halves and only the 35 mm value (52 mm) knows it.
    found = focal_px_from_exif(iphone(focal_35mm=52.0), *FULL)
    assert found is not None and found.basis == "FocalLengthIn35mmFilm 52 mm"
    assert found.focal_px == pytest.approx(2 * F_PX_35, rel=1e-9)


@pytest.mark.parametrize("orientation", [1, 2, 3, 4, 5, 6, 7, 8])
@pytest.mark.parametrize("route", ["35mm", "plane"])
def test_turned_and_resized_photos_from_real_files(orientation, route):
    """A 4032 x 3024 photo stored at 64 x 48 (resized by 1/63), upright or turned by EXIF."""
    exif_tags = pillow_exif(orientation=orientation, f35=F35 if route == "35mm" else None)
    data = photo(exif_tags)
    exif = read_camera_exif(data)
    w, h = decoded_size(data)
    found = focal_px_from_exif(exif, w, h)
    assert found is not None
    expected = (F_PX_35 if route == "35mm" else F_PX_PLANE) / 63
    assert found.focal_px == pytest.approx(expected, rel=1e-6)
    if route == "plane":
        assert "resized 4032x3024 -> 64x48 px" in found.basis
        assert ("turned by EXIF orientation" in found.basis) == (orientation >= 5)
    # The size before orientation is not the decoded one for a turned photo: refused as a crop.
    if orientation >= 5:
        refused = explain_exif_focal(exif, h, w)
        assert isinstance(refused, NoExifFocal) and "cropped" in refused.reason


@pytest.mark.parametrize("decoded, factor", [((1008, 756), 0.25), ((1000, 750), 1000 / 4032),
                                             ((8064, 6048), 2.0), ((101, 76), 101 / 4032)])  # fmt: skip
def test_resized_photo_scales_the_focal_length(decoded, factor):
    plane = focal_px_from_exif(iphone(focal_35mm=None), *decoded)
    assert plane is not None and plane.focal_px == pytest.approx(F_PX_PLANE * factor, rel=0.006)
    f35 = focal_px_from_exif(iphone(), *decoded)
    assert f35 is not None and f35.focal_px == pytest.approx(F_PX_35 * factor, rel=0.006)


@pytest.mark.parametrize("decoded, accepted", [((4032, 3000), True), ((4032, 2990), False),
                                               ((3024, 3024), False), ((3024, 4032), False),
                                               ((1920, 1080), False)])  # fmt: skip
def test_a_cropped_photo_is_refused_with_the_sizes_in_the_reason(decoded, accepted):
    for exif in (iphone(), iphone(focal_35mm=None)):
        found = explain_exif_focal(exif, *decoded)
        assert isinstance(found, ExifFocal) == accepted
        if not accepted:
            assert "4032x3024" in found.reason and f"{decoded[0]}x{decoded[1]}" in found.reason
            assert "cropped" in found.reason
            assert focal_px_from_exif(exif, *decoded) is None


def test_without_the_original_size_the_decoded_size_is_assumed():
    exif = iphone(pixel_width=None, pixel_height=None)
    found = focal_px_from_exif(exif, *FULL)
    assert found.focal_px == pytest.approx(F_PX_35) and "original size not recorded" in found.basis
    plane = focal_px_from_exif(dataclasses.replace(exif, focal_35mm=None), *FULL)
    assert plane.focal_px == pytest.approx(F_PX_PLANE) and "original size not recorded" in plane.basis


@pytest.mark.parametrize("f35, accepted", [(8, False), (9, True), (432, True), (433, False), (65535, False)])
def test_implausible_35mm_values_are_refused(f35, accepted):
    # plausible: 0.2 .. 10 diagonals, i.e. 8.65 .. 432.7 mm in 35 mm terms
    found = explain_exif_focal(iphone(focal_35mm=float(f35), focal_mm=None), *FULL)
    assert isinstance(found, ExifFocal) == accepted
    if not accepted:
        assert f"FocalLengthIn35mmFilm {f35} mm" in found.reason and "plausible" in found.reason


def test_an_implausible_35mm_value_falls_back_to_the_focal_plane_and_says_so():
    found = focal_px_from_exif(iphone(focal_35mm=65535.0), *FULL)
    assert found is not None and found.focal_px == pytest.approx(F_PX_PLANE)
    assert found.basis.startswith("FocalLength 4.25 mm") and "FocalLengthIn35mmFilm 65535 mm" in found.basis


@pytest.mark.parametrize(
    "changes, words",
    [
        ({"focal_35mm": None, "focal_mm": 1e6}, "plausible"),
        ({"focal_35mm": None, "focal_plane_x_res": 1.0, "focal_plane_y_res": 1.0}, "plausible"),
        ({"focal_35mm": None, "focal_plane_unit": 1}, "FocalPlaneResolutionUnit 1"),
        ({"focal_35mm": None, "focal_plane_unit": 7}, "FocalPlaneResolutionUnit 7"),
        ({"focal_35mm": None, "focal_plane_y_res": 2 * 10 / PITCH_MM}, "non-square"),
        ({"focal_35mm": None, "focal_mm": None}, "no usable FocalLengthIn35mmFilm, nor FocalLength"),
        ({"focal_35mm": None, "focal_plane_x_res": None}, "nor FocalPlaneXResolution"),
        ({"focal_35mm": 2.0, "focal_plane_x_res": None}, "FocalLengthIn35mmFilm 2 mm"),
        ({"pixel_width": 2, "pixel_height": 2}, "cropped"),
    ],
)
def test_no_focal_length_and_the_reason(changes, words):
    exif = iphone(**changes)
    found = explain_exif_focal(exif, *FULL)
    assert isinstance(found, NoExifFocal) and words in found.reason
    assert focal_px_from_exif(exif, *FULL) is None


def test_tiny_original_size_with_the_right_aspect_is_refused_as_implausible():
    # 4 x 3 "original" px: the resize factor 1008 makes the focal plane result absurd
    found = explain_exif_focal(iphone(focal_35mm=None, pixel_width=4, pixel_height=3), *FULL)
    assert isinstance(found, NoExifFocal) and "plausible" in found.reason


@pytest.mark.parametrize("size, quoted", [((0, 3024), "decoded_width .* got 0"),
                                          ((4032, -1), "decoded_height .* got -1"),
                                          ((4032.0, 3024), "decoded_width .* got 4032.0"),
                                          ((True, 3024), "decoded_width .* got True"),
                                          (("4032", 3024), "decoded_width .* got '4032'")])  # fmt: skip
def test_a_bad_decoded_size_is_an_input_error(size, quoted):
    with pytest.raises(InputError, match=quoted):
        explain_exif_focal(iphone(), *size)


# --------------------------------------------------------------------------------------------
# pooling key


def test_camera_key_is_shared_by_upright_and_turned_photos_of_one_camera():
    keys = {camera_key(read_camera_exif(photo(pillow_exif(orientation=o)))) for o in (1, 6, 8)}
    assert keys == {"Apple|iPhone 13|4032x3024|f=4.25mm|f35=26mm"}


@pytest.mark.parametrize(
    "changes",
    [
        {"model": "iPhone 14"},
        {"pixel_width": 3024, "pixel_height": 3024},
        {"focal_mm": 1.54, "focal_35mm": 13.0},  # the ultra-wide camera of the same phone
        {"focal_35mm": 52.0},  # digital zoom
        {"lens_model": "iPhone 13 back camera 4.25mm f/1.6"},
    ],
)
def test_camera_key_separates_other_cameras_and_lens_settings(changes):
    assert camera_key(iphone(**changes)) not in (None, camera_key(iphone()))


@pytest.mark.parametrize(
    "changes", [{"make": None, "model": None}, {"pixel_width": None}, {"pixel_height": None}]
)
def test_camera_key_is_none_when_the_camera_is_not_known(changes):
    assert camera_key(iphone(**changes)) is None


def test_camera_key_fields_cannot_run_into_each_other():
    assert camera_key(iphone(make="a|b", model="c")) != camera_key(iphone(make="a", model="b|c"))


# --------------------------------------------------------------------------------------------
# real photos (OpenCV's sample data, from Debian's opencv-doc package)


def opencv_photo(name: str) -> bytes:
    for path in (OPENCV_EXAMPLES / name, OPENCV_EXAMPLES / f"{name}.gz"):
        if path.is_file():
            return gzip.decompress(path.read_bytes()) if path.suffix == ".gz" else path.read_bytes()
    pytest.fail(f"{OPENCV_EXAMPLES / name} is missing: install Debian's opencv-doc package "
                "(scripts/setup does)")


def test_real_iphone_photo_resized_after_it_was_taken():
    """leuvenA.jpg: an iPhone 6 photo (3264 x 2448, 1.5 um pixels, 4.15 mm lens, "29 mm") saved at
    751 x 563. Its lens over its pixel pitch, scaled to the saved width, is 636.6 px; the 35 mm
    value, rounded to the mm by the phone (29.35 mm unrounded), gives 1.2 % less."""
    data = opencv_photo("data/leuvenA.jpg")
    exif = read_camera_exif(data)
    assert exif is not None and (exif.pixel_width, exif.pixel_height, exif.focal_35mm) == (3264, 2448, 29.0)
    found = focal_px_from_exif(exif, *decoded_size(data))
    assert found == ExifFocal(pytest.approx(629.11, abs=0.01), "FocalLengthIn35mmFilm 29 mm")
    assert found.focal_px == pytest.approx(4.15 / 0.0015 * 751 / 3264, rel=0.015)
    assert camera_key(exif) == (
        "Apple|iPhone 6|3264x2448|lens=iPhone 6 back camera 4.15mm f/2.2|f=4.15mm|f35=29mm"
    )


def test_real_canon_photo_uses_the_focal_plane_resolution_in_inches():
    """scenetext_segmented_word05.jpg: a Canon PowerShot S20 at 640 x 480, 13 mm, no 35 mm value,
    2302.16 px per inch on the sensor (X and Y differ by 0.24 %, within the square-pixel tolerance)."""
    data = opencv_photo("text/scenetext_segmented_word05.jpg")
    exif = read_camera_exif(data)
    assert exif is not None and exif.focal_35mm is None and exif.focal_plane_unit == 2
    found = focal_px_from_exif(exif, *decoded_size(data))
    assert found is not None and found.focal_px == pytest.approx(13 * 2302.158 / 25.4, rel=1e-5)
    assert found.basis == "FocalLength 13 mm at 2302.16 px/in focal plane"


@pytest.mark.parametrize("name, taken", [("data/text_defocus.jpg", "4320x3240"),
                                         ("data/licenseplate_motion.jpg", "600x968")])  # fmt: skip
def test_real_cropped_photos_are_refused(name, taken):
    data = opencv_photo(name)
    exif = read_camera_exif(data)
    w, h = decoded_size(data)
    found = explain_exif_focal(exif, w, h)
    assert isinstance(found, NoExifFocal)
    assert f"the photo is {w}x{h} px but its EXIF says it was taken at {taken} px" in found.reason


def test_real_photo_with_a_focal_length_and_nothing_to_convert_it():
    exif = read_camera_exif(opencv_photo("data/board.jpg"))  # Olympus C2000Z: FocalLength 13.9 mm only
    found = explain_exif_focal(exif, 640, 480)
    assert isinstance(found, NoExifFocal) and "nor FocalPlaneXResolution" in found.reason
    assert camera_key(exif) == "OLYMPUS OPTICAL CO.,LTD|C2000Z|640x480|f=13.9mm"
