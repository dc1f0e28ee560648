"""Imported last by the node fork server (node_fork.py): every compiled numba kernel of the
project's modules imported so far is loaded from numba's on-disk cache once, in the server,
so that the nodes it forks start with them in memory (~0.4 CPU s for all of them, paid once
instead of each node loading its own on its first tick).

numba has no public call for "load every cached overload": this reads each dispatcher's
cache index (signatures only) and compiles those signatures, which numba serves from the
cache. Anything unexpected (another numba version, no cache yet) skips the warm-up: the
nodes then load their kernels themselves, as a freshly started interpreter does.
"""
from __future__ import annotations

import sys


def load_cached_kernels(prefix: str = "hexapod") -> int:
    """Load the cached overloads of every numba dispatcher in the modules named
    ``prefix*``; how many were loaded."""
    try:
        from numba.core.registry import CPUDispatcher
    except ImportError:
        return 0
    seen: set[int] = set()
    loaded = 0
    for name, module in list(sys.modules.items()):
        if not name.startswith(prefix) or module is None:
            continue
        for value in list(vars(module).values()):
            if not isinstance(value, CPUDispatcher) or id(value) in seen:
                continue
            seen.add(id(value))
            try:
                index = value._cache._cache_file._load_index()  # {(signature, ...): file}
                for key in index:
                    value.compile(key[0])
                    loaded += 1
            except Exception:  # noqa: BLE001 - a warm-up only: the node loads it itself
                continue
    return loaded


LOADED = load_cached_kernels()
