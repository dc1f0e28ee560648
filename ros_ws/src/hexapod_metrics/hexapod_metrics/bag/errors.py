"""Errors of the bag subpackage (writer, reader).

Every message is one line that says what was expected, what was found and, where it helps,
what the user can do about it. Low-level failures (``OSError``, ``struct.error``, decompressor
errors, ...) are translated at the module boundary with ``raise BagReadError(msg) from err``.
"""

from __future__ import annotations

__all__ = ['BagError', 'BagReadError', 'BagStorageError', 'BagWriteError']


class BagError(Exception):
    """Base class of all bag errors."""


class BagWriteError(BagError):
    """A bag could not be written (bad path, unknown topic or type, writer closed, disk full)."""


class BagStorageError(BagWriteError):
    """The file system refused a write (disk full, quota, I/O error).

    The writer has already closed the bag at its last complete chunk (readable by every
    reader); ``reason`` is the system's message, e.g. ``No space left on device``.
    """

    def __init__(self, message: str, reason: str) -> None:
        """``message`` says what happened to the bag; ``reason`` is the OS error text."""
        super().__init__(message)
        self.reason = reason


class BagReadError(BagError):
    """A path is not a readable bag, or its content is damaged beyond the readable prefix."""

