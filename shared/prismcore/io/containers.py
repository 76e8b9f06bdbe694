"""Tell a video file from a photo by its first bytes, not by its name.

Pure bytes in, a name out: no numpy or OpenCV, so the service's API can sniff uploads too.
"""

from __future__ import annotations

__all__ = ["HEAD_BYTES", "video_container"]

HEAD_BYTES = 16
"""How many leading bytes :func:`video_container` needs."""

# ISO base media ("ftyp") brands that are still images or audio; every other brand is a movie
# (MP4, QuickTime, 3GP, ...), which is the safer guess: FFmpeg then says whether it decodes.
_NOT_VIDEO_BRANDS = frozenset({
    b"heic", b"heix", b"heim", b"heis", b"hevc", b"hevx", b"hevm", b"hevs", b"mif1", b"msf1",
    b"avif", b"avis", b"avio", b"jxl ", b"crx ", b"jp2 ", b"jpx ", b"jpm ",
    b"M4A ", b"M4B ", b"M4P ", b"F4A ", b"F4B ",
})
# QuickTime files written before the "ftyp" atom existed start with one of these atoms.
_QUICKTIME_ATOMS = frozenset({b"moov", b"mdat", b"wide", b"free", b"skip", b"pnot"})


def video_container(head: bytes | bytearray | memoryview) -> str | None:
    """The container a file's first bytes announce, if it is a video.

    Parameters
    ----------
    head : bytes-like
        The file's first :data:`HEAD_BYTES` bytes (more are ignored, fewer may not tell).

    Returns
    -------
    str or None
        ``"avi"`` (RIFF AVI), ``"mp4"`` (ISO media: MP4, M4V, 3GP), ``"mov"`` (QuickTime),
        ``"mkv"`` (Matroska or WebM); None for anything else, photos included. Only the header
        is read: whether the streams inside decode is for the decoder to say.
    """
    head = bytes(head[:HEAD_BYTES])
    if head[:4] == b"RIFF" and head[8:12] == b"AVI ":
        return "avi"
    if head[:4] == b"\x1a\x45\xdf\xa3":  # EBML magic
        return "mkv"
    box = head[4:8]
    if box == b"ftyp" and len(head) >= 12:
        brand = head[8:12]
        if brand in _NOT_VIDEO_BRANDS:
            return None
        return "mov" if brand == b"qt  " else "mp4"
    size = int.from_bytes(head[:4], "big")
    # Those atoms are small (only "mdat" holds the media), so a text that happens to read "free"
    # at offset 4 is not taken for a movie.
    if box in _QUICKTIME_ATOMS and (size == 1 or 8 <= size < (1 << 24) or box == b"mdat"):
        return "mov"
    return None
