"""A zero-click refusal carries what was taken for the part to its caller, and crosses a process
(a Celery task's failure) as its words alone; its picture shows the pixels and the reason."""

from __future__ import annotations

import pickle

import numpy as np

from prismcore.errors import InputError, PartRefusedError
from prismcore.outputs import refusal_overlay


def test_a_refusal_is_an_input_error_and_pickles_as_its_words() -> None:
    photo = np.zeros((40, 60, 3), np.uint8)
    taken = np.zeros((40, 60), bool)
    exc = PartRefusedError("2 parts found: one part per photo", photo, taken)
    assert isinstance(exc, InputError) and exc.photo is photo and exc.taken is taken
    back = pickle.loads(pickle.dumps(exc))
    assert type(back) is InputError and str(back) == str(exc)


def test_the_picture_tints_what_was_taken_and_writes_the_reason_on_a_band() -> None:
    photo = np.full((400, 600, 3), 120, np.uint8)
    taken = np.zeros((400, 600), bool)
    taken[250:330, 100:200] = True
    out = refusal_overlay(photo, taken, "2 parts found: one part per photo")
    assert out.shape == photo.shape and out.dtype == np.uint8
    inner = out[260:320, 110:190].astype(int)
    assert (inner[..., 0] - inner[..., 1] > 60).all()  # tinted red
    np.testing.assert_array_equal(out[350:, 300:], photo[350:, 300:])  # elsewhere the photo
    band = out[:20].astype(int)
    assert band.max() == 255 and np.median(band) < 60  # white words on a dark band
    assert refusal_overlay(photo, None, "no part found").shape == photo.shape
