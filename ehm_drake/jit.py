"""Compiled kernels for the per-step laws (numba), each beside the NumPy law
it mirrors, which stays the reference and the fallback.

A law evaluated every time step on a handful of elements costs more in
NumPy's per-call overhead (about a microsecond per operation on arrays of
five) than in arithmetic; a numba kernel evaluates the same formulas in
the same order in one call.  `kernel(fn)` compiles `fn` (nopython, cached
on disk beside this package, so only the first run on a machine compiles)
or returns None when numba is not installed or ``EHM_DRAKE_NO_JIT=1``: the
callers then use the NumPy law, and the results are the same to rounding
(the tests compare every kernel with its law to 1e-12).  No fast-math:
IEEE operations in the law's order.
"""

from __future__ import annotations

import os

try:
    if os.environ.get("EHM_DRAKE_NO_JIT", "") not in ("", "0"):
        raise ImportError("EHM_DRAKE_NO_JIT is set")
    import numba
except ImportError:  # the NumPy laws serve
    numba = None


def kernel(fn):
    """`fn` compiled by numba (nopython, cache=True), or None without numba.
    A division by zero gives inf or NaN as in NumPy (numba's "numpy" error
    model), never an exception: a diverging state reaches the divergence
    guard as on the NumPy path."""
    if numba is None:
        return None
    return numba.njit(cache=True, nogil=True, error_model="numpy")(fn)


def available() -> bool:
    """True when the kernels are compiled (numba installed, not disabled)."""
    return numba is not None


def _maximum(a, b):
    """np.maximum of two floats (b when equal, NaN from a)."""
    return a if (a > b or a != a) else b


def _minimum(a, b):
    """np.minimum of two floats (b when equal, NaN from a)."""
    return a if (a < b or a != a) else b


#: NumPy's elementwise maximum and minimum of two floats, for the kernels
#: (compiled when the kernels are, so a kernel can call them).
maximum = kernel(_maximum) or _maximum
minimum = kernel(_minimum) or _minimum

__all__ = ["available", "kernel", "maximum", "minimum"]
