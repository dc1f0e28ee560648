"""Errors raised by the bag writer and reader.

Every message is one line that says what was expected, what was found and, where it helps,
what the user can do about it. Low-level failures (``OSError``, ``struct.error``, decompressor
errors, ...) are translated at the module boundary with ``raise BagReadError(msg) from err``.
"""

from __future__ import annotations

__all__ = ['BagError', 'BagReadError', 'BagTruncatedWarning', 'BagWriteError']


class BagError(Exception):
    """Base class of all bag errors."""


class BagWriteError(BagError):
    """A bag could not be written (bad path, unknown topic or type, writer closed, disk full)."""


class BagReadError(BagError):
    """A path is not a readable bag, or its content is damaged beyond the readable prefix."""


class BagTruncatedWarning(UserWarning):
    """A bag was not closed cleanly (e.g. its writer was killed); only a prefix was read."""
