"""Errors the engine raises for bad input.

Every problem a caller can fix (a bad file, bad points, a bad option) is an :class:`InputError`
whose message quotes the offending value; the CLI prints it as one line and exits with code 2,
the service turns it into an HTTP 4xx or a failed item.
"""

__all__ = ["InputError"]


class InputError(ValueError):
    """Input the engine cannot work with; the message says what and quotes the bad value."""
