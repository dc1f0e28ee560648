"""Vector widths for the compiled loops: 512-bit on CPUs with AVX-512, 4 doubles forced on
AVX2-only CPUs.

LLVM tunes Intel's AVX-512 CPUs to prefer 256-bit vectors (its ``prefer-256-bit``
feature), so a loop over cases of the batched engine (hexapod_sim.core.batch_physics)
steps 4 doubles an instruction instead of 8. :func:`prefer_512_bit` turns that preference
off in numba's code generator: it sets ``numba.config.CPU_FEATURES`` to the host's
features plus ``-prefer-256-bit`` before anything is compiled (this package's import runs
it). The numbers do not change: a vector lane does the same IEEE operations whatever the
vector's width, and numba keys its on-disk cache on the CPU features. A user's own
``NUMBA_CPU_NAME`` or ``NUMBA_CPU_FEATURES`` wins; so does ``HEXAPOD_VECTOR_WIDTH=256``.

On AVX2 CPUs without AVX-512 (AMD's Zen, for one) LLVM's cost model judges the batched
engine's loop over the legs (block_prepare: sincos.py's polynomials, the leg's mass matrix
and its factor) not worth vectorising and leaves it scalar. :func:`force_avx2_width` makes
LLVM vectorise every loop it can at 4 doubles (``-force-vector-width=4``, a process-wide
LLVM option, so only where nobody chose numba's CPU). As above, the numbers do not
change. docs/benchmarks.md (S2) has the figures.
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
    if (os.environ.get("HEXAPOD_VECTOR_WIDTH") in ("256", "native") or config.CPU_NAME is not None
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


_FORCED: list[bool] = []


def force_avx2_width() -> bool:
    """Make LLVM vectorise loops at 4 doubles on hosts with AVX2 but no AVX-512 (where its
    cost model leaves the batched legs' loop scalar); True if it did. Once per process, before
    numba compiles anything; ``HEXAPOD_VECTOR_WIDTH=native`` (or a user's NUMBA_CPU_NAME or
    NUMBA_CPU_FEATURES) leaves LLVM's own choice."""
    from numba.core import config as numba_config

    config: Any = numba_config
    if _FORCED:
        return _FORCED[0]
    forced = False
    if (os.environ.get("HEXAPOD_VECTOR_WIDTH") != "native" and config.CPU_NAME is None
            and config.CPU_FEATURES is None and platform.machine() in ("x86_64", "AMD64")):
        import llvmlite.binding as ll

        try:
            features = ll.get_host_cpu_features()
        except RuntimeError:
            features = {}
        if features.get("avx2", False) and not features.get("avx512f", False):
            ll.set_option("hexapod", "-force-vector-width=4")
            forced = True
    _FORCED.append(forced)
    return forced


__all__ = ["force_avx2_width", "prefer_512_bit"]
