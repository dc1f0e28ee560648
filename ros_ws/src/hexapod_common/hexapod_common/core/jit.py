"""numba's compiler as the project's compiled code uses it: ``njit`` and ``prange``, with
512-bit vectors on AVX-512 hosts and 4-double ones forced on AVX2 hosts (vector_width.py),
set up before anything compiles.

Every module with compiled code imports them from here, so the vector width is chosen by
the first such import; modules without compiled code (the parameter table, the topic
names, the command line's) import no numba (1-2 s at a command's start)."""
from __future__ import annotations

from .vector_width import force_avx2_width, prefer_512_bit

prefer_512_bit()
force_avx2_width()

from numba import njit, prange  # noqa: E402  (after the vector width is set)

__all__ = ["njit", "prange"]
