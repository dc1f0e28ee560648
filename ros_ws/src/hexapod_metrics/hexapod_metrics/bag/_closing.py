"""``with`` support shared by the reader's :class:`~.reader.Bag` and the writer."""

from __future__ import annotations

from types import TracebackType
from typing import Self


class Closing:
    """``with obj:`` returns ``obj`` on entry and calls ``close()`` on exit, also after an
    exception. Subclasses define ``close()``; ``__enter__`` may be overridden to open."""

    def close(self) -> None:
        """Release the files (subclasses)."""
        raise NotImplementedError

    def __enter__(self) -> Self:
        """Enter ``with``."""
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        """Close on leaving ``with``."""
        self.close()
