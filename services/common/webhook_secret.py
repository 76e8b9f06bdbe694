"""The key webhooks are signed with, from `PRISM_WEBHOOK_SECRET` (Standard Webhooks, HMAC-SHA256).

The standard's form is ``whsec_`` followed by the key in base64; receivers' libraries take that
string as it is. Any other string is accepted too, and its key is its UTF-8 bytes: the same key
as ``"whsec_" + base64(secret.encode())``, so a receiver can use either form. (A key derived by
hashing would work as well, but then a receiver could not pass the plain secret to a library.)
"""

from __future__ import annotations

import base64
import binascii

__all__ = ["PREFIX", "signing_key"]

PREFIX = "whsec_"


def signing_key(secret: str) -> bytes:
    """The HMAC key of `secret`: base64-decoded after ``whsec_``, else the string's UTF-8 bytes.

    Raises
    ------
    ValueError
        The secret is empty, or starts with ``whsec_`` and the rest is not base64 of at least
        one byte. The message never quotes the secret.
    """
    if not secret:
        raise ValueError("the webhook secret is empty")
    if not secret.startswith(PREFIX):
        return secret.encode()
    encoded = secret.removeprefix(PREFIX)
    try:
        # Padding may be left off, as the reference libraries allow; anything outside the
        # base64 alphabet is an error here (they would skip it silently and sign with another key).
        key = base64.b64decode(encoded + "=" * (-len(encoded) % 4), validate=True)
    except binascii.Error:
        raise ValueError(f"the webhook secret starts with {PREFIX!r} but the rest, "
                         f"{len(encoded)} characters, is not base64") from None
    if not key:
        raise ValueError(f"the webhook secret {PREFIX!r} holds no key after its prefix")
    return key

