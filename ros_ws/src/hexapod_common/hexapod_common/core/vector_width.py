"""512-bit vectors for the compiled loops on CPUs with AVX-512.

LLVM tunes Intel's AVX-512 CPUs to prefer 256-bit vectors (its ``prefer-256-bit``
feature), so a loop over cases of the batched engine (hexapod_sim.core.batch_physics)
steps 4 doubles an instruction instead of 8. :func:`prefer_512_bit` turns that preference
off in numba's code generator: it sets ``numba.config.CPU_FEATURES`` to the host's
features plus ``-prefer-256-bit`` before anything is compiled (this package's import runs
it). The numbers do not change: a vector lane does the same IEEE operations whatever the
vector's width, and numba keys its on-disk cache on the CPU features. A user's own
``NUMBA_CPU_NAME`` or ``NUMBA_CPU_FEATURES`` wins; so does ``HEXAPOD_VECTOR_WIDTH=256``.
docs/benchmarks.md (S2) has the figures.
"""
from __future__ import annotations

import os
import platform
from typing import Any


def prefer_512_bit() -> bool:
    """Make numba's code generator prefer 512-bit vectors where the host has AVX-512 and
    nobody chose its CPU features; True if it did. Call before numba compiles anything
    (later calls change nothing for code already generated)."""
    from numba.core import config as numba_config

    config: Any = numba_config  # its settings are read from the environment at import
    if (os.environ.get("HEXAPOD_VECTOR_WIDTH") == "256" or config.CPU_NAME is not None
            or config.CPU_FEATURES is not None
            or platform.machine() not in ("x86_64", "AMD64")):
        return False
    import llvmlite.binding as ll

    try:
        features = ll.get_host_cpu_features()
    except RuntimeError:  # LLVM cannot tell this CPU's features
        return False
    if not features.get("avx512f", False):
        return False
    config.CPU_FEATURES = features.flatten() + ",-prefer-256-bit"
    return True


__all__ = ["prefer_512_bit"]
