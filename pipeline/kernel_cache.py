"""The trial engine's numba kernels, loaded from numba's on-disk cache when this module is imported.

numba loads a cached kernel on its first call, about 0.35 s for the engine's 25 in every new
process. The trial workers' fork server imports this module (:data:`pipeline.pool.PRELOAD`), so
the workers it forks start with them loaded. Only overloads cached for this very code and
machine are loaded (numba's own index key); a kernel with none, or whose cache this numba
cannot read, is left to compile or load on first use, as always, so the fork server never fails
on it. Importing it elsewhere only moves that cost to the import.
"""

import importlib
import sys

#: whose kernels are loaded (and the modules they import)
MODULES = ("pipeline.trial.engine",)


def load_cached(modules=MODULES):
    """Load every cached overload of the numba kernels in ``modules`` and the ``pipeline``
    modules they import; returns how many were loaded."""
    from numba.core.dispatcher import Dispatcher

    for name in modules:
        importlib.import_module(name)
    loaded = 0
    for name, module in list(sys.modules.items()):
        if not name.startswith("pipeline."):
            continue
        for kernel in list(vars(module).values()):
            cache = getattr(kernel, "_cache", None) if isinstance(kernel, Dispatcher) else None
            index = getattr(cache, "_cache_file", None)
            if index is None:  # not cached (no ``cache=True``)
                continue
            try:
                codegen = kernel.targetctx.codegen()
                for key in index._load_index():
                    if cache._index_key(key[0], codegen) == key and key[0] not in kernel.overloads:
                        kernel.compile(key[0])
                        loaded += 1
            except Exception:  # noqa: BLE001 (numba's internals: a kernel left to load on its first call, as without)
                continue
    return loaded


LOADED = load_cached()
