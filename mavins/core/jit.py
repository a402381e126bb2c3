"""The one place that decides how navigation kernels are compiled.

Every kernel is compiled by numba with an on-disk cache (``cache=True``), so the
compile cost is paid once per machine, not once per process. Setting
``NUMBA_DISABLE_JIT=1`` runs the very same source as plain Python for debugging.

Numba invalidates a cached kernel only when its *own* source file changes, not
when a kernel it calls in another module does; a stale cache then links old
code. The cache therefore lives in a folder named after a digest of every
source file in this package (``~/.cache/mavins/numba/<digest>``, or
``$XDG_CACHE_HOME``), so any change to the core recompiles everything that
depends on it. ``NUMBA_CACHE_DIR``, when set, is respected as is.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path
from typing import Callable, TypeVar

import numba

F = TypeVar("F", bound=Callable)


def _cache_dir() -> str:
    digest = hashlib.sha256()
    for src in sorted(Path(__file__).parent.glob("*.py")):
        digest.update(src.name.encode())
        digest.update(src.read_bytes())
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "mavins" / "numba"
    return str(base / f"{numba.__version__}-{digest.hexdigest()[:16]}")


if not os.environ.get("NUMBA_CACHE_DIR"):
    numba.config.CACHE_DIR = _cache_dir()


def cache_is_warm() -> bool:
    """Whether compiled kernels of this core version are already on disk (numba index files)."""
    return any(Path(numba.config.CACHE_DIR).rglob("*.nbi"))


def kernel(func: F) -> F:
    """Compile ``func`` in nopython mode with the on-disk cache."""
    return numba.njit(cache=True, nogil=True, error_model="numpy")(func)
