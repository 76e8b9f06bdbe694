"""The same content uploaded again by a tenant is answered with the upload it already has (one
stored copy, its lifetime renewed); another tenant, or other content, gets an upload of its own;
once the first upload is gone, the content is stored afresh."""

# ruff: noqa: F811 - fixtures imported from test_api are used as such
from __future__ import annotations

import hashlib

from .test_api import ACME, client, fresh_tenant, make_client, photo  # noqa: F401 (fixtures)


def post(client, data: bytes, name: str, headers=ACME):
    return client.post("/v1/uploads", files={"file": (name, data)}, headers=headers)


def test_same_content_is_answered_with_the_stored_upload(client, store, objects):
    data = photo(size=5000, width=300)
    first = post(client, data, "a.png")
    again = post(client, data, "a.png")
    assert first.status_code == 201 and again.status_code == 200, (first.text, again.text)
    assert again.json()["id"] == first.json()["id"]
    # Another name is another upload: errors about an upload quote the name it was given.
    renamed = post(client, data, "renamed.png")
    assert renamed.status_code == 201 and renamed.json()["name"] == "renamed.png"
    assert first.json()["sha256"] == again.json()["sha256"] == hashlib.sha256(data).hexdigest()
    # One copy stored: the second upload's object was removed.
    record = store.get_upload(first.json()["id"])
    prefix = record["key"].rsplit("/", 1)[0] + "/"
    assert record["key"] in objects.list_keys(prefix)
    assert len(objects.list_keys(prefix)) == 2  # a.png once, renamed.png


def test_an_upload_whose_object_is_gone_is_not_handed_out(client, store, objects):
    data = photo(size=5100, width=300)
    first = post(client, data, "a.png").json()["id"]
    objects.delete_keys([store.get_upload(first)["key"]])
    again = post(client, data, "a.png")
    assert again.status_code == 201 and again.json()["id"] != first


def test_other_content_and_other_tenants_get_their_own(make_client, settings, client):
    data = photo(size=6000, width=310)
    mine = post(client, data, "a.png").json()["id"]
    assert post(client, photo(size=6001, width=310), "a.png").json()["id"] != mine
    other, headers = fresh_tenant(make_client, settings)
    theirs = post(other, data, "a.png", headers=headers)
    assert theirs.status_code == 201 and theirs.json()["id"] != mine


def test_a_deleted_upload_is_not_handed_out_again(client, store):
    data = photo(size=7000, width=320)
    first = post(client, data, "a.png").json()["id"]
    store.delete_upload(first)  # as the expiry sweep does
    again = post(client, data, "a.png")
    assert again.status_code == 201 and again.json()["id"] != first
