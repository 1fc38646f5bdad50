"""Run the diagnosis with a single BLAS thread.

The diagnosis does thousands of products and solves of small matrices (tens of columns). With
OpenBLAS's thread pool these are slower than on one thread, and on a busy 2-core machine
dramatically so (measured: 2.8 s instead of 0.4 s for a two-leg session). numpy has no API for
the thread count, so the OpenBLAS libraries bundled with numpy/scipy are asked directly through
their exported setter; when that is not possible nothing changes.
"""

from __future__ import annotations

import ctypes
import glob
import os
from contextlib import contextmanager

_SETTERS = ("scipy_openblas_set_num_threads64_", "scipy_openblas_set_num_threads", "openblas_set_num_threads64_",
            "openblas_set_num_threads")
_GETTERS = ("scipy_openblas_get_num_threads64_", "scipy_openblas_get_num_threads", "openblas_get_num_threads64_",
            "openblas_get_num_threads")
_libs: list | None = None


def _openblas() -> list:
    """(getter, setter) pairs of the OpenBLAS libraries shipped with numpy and scipy."""
    global _libs
    if _libs is not None:
        return _libs
    _libs = []
    try:
        import numpy
        import scipy

        paths = []
        for pkg in (numpy, scipy):
            root = os.path.dirname(os.path.dirname(pkg.__file__))
            paths += glob.glob(os.path.join(root, f"{pkg.__name__}.libs", "*openblas*"))
        for path in paths:
            lib = ctypes.CDLL(path)
            get = next((getattr(lib, n) for n in _GETTERS if hasattr(lib, n)), None)
            put = next((getattr(lib, n) for n in _SETTERS if hasattr(lib, n)), None)
            if get is not None and put is not None:
                get.restype = ctypes.c_int
                _libs.append((get, put))
    except Exception:  # no bundled OpenBLAS (system BLAS, another platform): leave threads alone
        _libs = []
    return _libs


@contextmanager
def single_threaded_blas():
    saved = []
    for get, put in _openblas():
        try:
            saved.append((put, int(get())))
            put(1)
        except Exception:
            pass
    try:
        yield
    finally:
        for put, n in saved:
            try:
                put(n)
            except Exception:
                pass
