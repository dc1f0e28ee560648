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
import re
import sys
import tempfile
import threading
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
#: HEXAPOD_VECTOR_WIDTH's values: unset or empty (this module's choice), 256 (LLVM's width on
#: AVX-512 hosts), native (LLVM's own choice everywhere).
WIDTH_CHOICES = ("", "256", "native")
#: What LLVM prints for each loop it cannot vectorise once a width is forced (its remarks
#: are then always printed, to the C stderr).
_REMARK = re.compile(rb"^remark: .*(vectoriz|interleav)")


def _quiet_loop_remarks() -> None:
    """While numba compiles (its compiler lock), the process's stderr goes to a temporary
    file; afterwards everything but LLVM's loop-vectorisation remarks is written back."""
    from numba.core import event

    lock = threading.Lock()
    state: dict[str, Any] = {"depth": 0}

    class Quiet(event.Listener):
        def on_start(self, ev: Any) -> None:
            with lock:
                state["depth"] += 1
                if state["depth"] == 1:
                    sys.stderr.flush()
                    state["saved"] = os.dup(2)
                    state["file"] = tempfile.TemporaryFile()
                    os.dup2(state["file"].fileno(), 2)

        def on_end(self, ev: Any) -> None:
            with lock:
                state["depth"] -= 1
                if state["depth"] == 0:
                    sys.stderr.flush()
                    os.dup2(state["saved"], 2)
                    os.close(state["saved"])
                    f = state.pop("file")
                    f.seek(0)
                    kept = [line for line in f.read().splitlines(keepends=True)
                            if not _REMARK.match(line)]
                    f.close()
                    if kept:
                        os.write(2, b"".join(kept))

    event.register("numba:compiler_lock", Quiet())  # type: ignore[no-untyped-call]


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
    chosen = os.environ.get("HEXAPOD_VECTOR_WIDTH", "")
    if chosen not in WIDTH_CHOICES:
        print(f"warning: HEXAPOD_VECTOR_WIDTH={chosen!r} is none of "
              f"{', '.join(repr(c) for c in WIDTH_CHOICES)}: ignored", file=sys.stderr)
    if (os.environ.get("HEXAPOD_VECTOR_WIDTH") != "native" and config.CPU_NAME is None
            and config.CPU_FEATURES is None and platform.machine() in ("x86_64", "AMD64")):
        import llvmlite.binding as ll

        try:
            features = ll.get_host_cpu_features()
        except RuntimeError:
            features = {}
        if features.get("avx2", False) and not features.get("avx512f", False):
            ll.set_option("hexapod", "-force-vector-width=4")
            # the same features under another name: numba's on-disk cache is keyed on them,
            # so code compiled before at LLVM's own width is not loaded for this
            config.CPU_FEATURES = features.flatten() + ",+avx2"
            _quiet_loop_remarks()
            forced = True
    _FORCED.append(forced)
    return forced


__all__ = ["WIDTH_CHOICES", "force_avx2_width", "prefer_512_bit"]
