"""The web page's point search on the worker (prism_worker.upload_points), on in-memory fakes:
what it stores for a photo, a file that is no photo, a file gone, a search that gave up, and
that a stored answer is not searched again."""

from __future__ import annotations

import cv2
import numpy as np
from prism_common.upload_keys import points_key

from prism_worker import upload_points
from prismcore.locate.search import find_points
from prismsynth.scenes import empty_scene

from .conftest import Fakes

IMAGE = empty_scene(0, image_size=(320, 256))


def _png(image: np.ndarray) -> bytes:
    ok, data = cv2.imencode(".png", cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
    assert ok
    return data.tobytes()


def _answer(fakes: Fakes, upload_id: str, hint: tuple[int, int] | None = None) -> dict:
    return fakes.objects.get_json(points_key("acme", upload_id, None, hint))


def test_a_photo_gets_the_searchs_own_answer_once(fakes: Fakes) -> None:
    upload_id = fakes.upload(_png(IMAGE), name="empty.png").removeprefix("upload:")
    upload_points.find_upload_points(fakes.ctx, upload_id, None, (100, 90))
    want = upload_points.found_document(find_points(IMAGE, hint=(100, 90)), 320, 256)
    assert _answer(fakes, upload_id, (100, 90)) == want and want["reason"]
    assert want["points"] is None and want["faces"] == []  # refused: nothing to place
    # Stored: a repeat (a redelivery, a second claim) leaves it as it is.
    key = points_key("acme", upload_id, None, (100, 90))
    fakes.objects.put_json(key, {"kept": True})
    upload_points.find_upload_points(fakes.ctx, upload_id, None, (100, 90))
    assert fakes.objects.get_json(key) == {"kept": True}


def test_a_file_that_is_no_photo_or_is_gone_is_an_error_in_words(fakes: Fakes) -> None:
    text = fakes.upload(b"hello, world\n" * 20, name="notes.png").removeprefix("upload:")
    upload_points.find_upload_points(fakes.ctx, text, None, None)
    error = _answer(fakes, text)["error"]
    assert "'notes.png'" in error and "/tmp" not in error, error
    gone = fakes.upload(_png(IMAGE), name="gone.png").removeprefix("upload:")
    fakes.objects.delete_keys([fakes.store.get_upload(gone)["key"]])
    upload_points.find_upload_points(fakes.ctx, gone, None, None)
    assert _answer(fakes, gone) == {"error": "'gone.png' is no longer stored: upload it again"}


def test_a_search_that_gave_up_says_why(fakes: Fakes) -> None:
    upload_id = fakes.upload(_png(IMAGE)).removeprefix("upload:")
    upload_points.search_failed(fakes.ctx, upload_id, None, None, "took longer than the worker's "
                                "time limit of 5 s: the input may be too large")
    assert _answer(fakes, upload_id) == {"error": "the point search took longer than the worker's time "
                                         "limit of 5 s: the input may be too large", "retry": True}
    upload_points.search_failed(fakes.ctx, upload_id, None, (1, 2), "the object store was unreachable")
    assert _answer(fakes, upload_id, (1, 2)) == {
        "error": "the point search failed: the object store was unreachable", "retry": True}


def test_an_expired_upload_leaves_nothing(fakes: Fakes) -> None:
    upload_id = fakes.upload(_png(IMAGE)).removeprefix("upload:")
    fakes.store.delete_upload(upload_id)
    upload_points.find_upload_points(fakes.ctx, upload_id, None, None)
    assert not any(".points/" in k for k in fakes.objects.objects)
