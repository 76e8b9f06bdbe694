"""Errors the engine raises for bad input.

Every problem a caller can fix (a bad file, bad points, a bad option) is an :class:`InputError`
whose message quotes the offending value; the CLI prints it as one line and exits with code 2,
the service turns it into an HTTP 4xx or a failed item.
"""

from __future__ import annotations

from typing import Any

__all__ = ["InputError", "PartRefusedError"]


class InputError(ValueError):
    """Input the engine cannot work with; the message says what and quotes the bad value."""


class PartRefusedError(InputError):
    """A zero-click measurement refused over what was found for the part (no part, several, not a
    box, reaching past the board), with that evidence, so that a caller can show it.

    Attributes
    ----------
    photo : ndarray, shape (H, W, 3), uint8, or None
        The photo as the segmentation saw it (undistorted).
    taken : ndarray, shape (H, W), bool, or None
        What was taken for the part (every blob counted, where several were): the pixels to show.
    """

    def __init__(self, message: str, photo: Any = None, taken: Any = None) -> None:
        super().__init__(message)
        self.photo = photo
        self.taken = taken

    def __reduce__(self) -> tuple[type[InputError], tuple[str]]:
        # pickled (a Celery task's failure) as the message alone: the evidence stays where it was made
        return InputError, (str(self),)
