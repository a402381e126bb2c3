"""The one place that decides how navigation kernels are compiled.

Every kernel is compiled by numba with an on-disk cache (``cache=True``), so the
compile cost is paid once per machine, not once per process. Setting
``NUMBA_DISABLE_JIT=1`` runs the very same source as plain Python for debugging.
"""

from __future__ import annotations

from typing import Callable, TypeVar

import numba

F = TypeVar("F", bound=Callable)


def kernel(func: F) -> F:
    """Compile ``func`` in nopython mode with the on-disk cache."""
    return numba.njit(cache=True, nogil=True, error_model="numpy")(func)
