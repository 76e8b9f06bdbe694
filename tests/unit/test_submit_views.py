"""`prism submit`: an item's views name local photos, uploaded (each once) and replaced by their
references before the job is sent; references and the caller's document are left as they are."""

from __future__ import annotations

from pathlib import Path

import pytest

from prism_cli.client_commands import _upload_local
from prismcore import InputError


class FakeClient:
    def __init__(self) -> None:
        self.sent: list[str] = []

    def upload(self, path: Path) -> str:
        self.sent.append(path.name)
        return f"upload:{path.stem}"


def test_views_photos_are_uploaded_once_each(tmp_path: Path) -> None:
    for name in ("a.jpg", "b.jpg"):
        (tmp_path / name).write_bytes(b"x")
    views = [{"image": "a.jpg", "points": []}, {"image": "b.jpg"}, {"image": "upload:kept"}]
    item = {"image": "a.jpg", "views": views}
    client = FakeClient()
    sent = _upload_local(client, dict(item), tmp_path)  # type: ignore[arg-type]
    assert [v["image"] for v in sent["views"]] == ["upload:a", "upload:b", "upload:kept"]
    assert sent["image"] == "upload:a" and client.sent == ["a.jpg", "b.jpg"]
    assert views[0]["image"] == "a.jpg"  # the document as read is not changed


def test_a_missing_view_photo_is_named(tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"views\[1\]\.image 'gone\.jpg': no such file"):
        _upload_local(FakeClient(), {"views": [{"image": "upload:x"}, {"image": "gone.jpg"}]},  # type: ignore[arg-type]
                      tmp_path)
