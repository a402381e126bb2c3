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

import functools
import os
from pathlib import Path
from typing import Any, Callable, TypeVar

import numba

from . import aot

F = TypeVar("F", bound=Callable)


def _cache_dir() -> str:
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "mavins" / "numba"
    return str(base / f"{numba.__version__}-{aot.source_digest(aot.CORE)}")


if not os.environ.get("NUMBA_CACHE_DIR"):
    numba.config.CACHE_DIR = _cache_dir()


def cache_is_warm() -> bool:
    """Whether compiled kernels of this core version are already on disk: built at install
    (:mod:`mavins.core.aot`), or numba index files of strapdown.py, which every navigating
    command loads (the simulator's kernels share the folder and are compiled first by
    ``mavins demo``: they do not count). With numba's JIT disabled (NUMBA_DISABLE_JIT=1) nothing is
    compiled, so there is nothing to wait for."""
    if numba.config.DISABLE_JIT:
        return True
    return aot.has_built("mavins.core") or any(Path(numba.config.CACHE_DIR).rglob("strapdown.*.nbi"))


def kernel(func: F) -> F:
    """Compile ``func`` in nopython mode with the on-disk cache, taking its entry points built
    ahead of time when there are (:mod:`mavins.core.aot`)."""
    return _compiled_kernel(func, fastmath=False)


def sum_kernel(func: F) -> F:
    """:func:`kernel` whose floating-point sums may be reassociated (numba ``fastmath`` reassoc and
    contract), so that a long sum vectorises. Only for sums whose order of terms means nothing beyond
    rounding (a sum of many sinusoids); never for the navigation's recursions."""
    return _compiled_kernel(func, fastmath={"reassoc", "contract"})


def inline_kernel(func: F) -> F:
    """:func:`kernel` that numba inlines into each kernel calling it (``inline="always"``): for a helper
    that takes arrays, called in a hot loop. A call to a kernel that is not inlined keeps the reference
    counts of the caller's arrays (two atomic operations per array and call); inlined, numba prunes them.
    It takes a mechanisation frame as its caller's constant and never calls ``literally`` (the inliner
    cannot); what Python calls with a frame is a ``literally`` wrapper around it (strapdown.position)."""
    return _compiled_kernel(func, fastmath=False, inline="always")


def _compiled_kernel(func: F, fastmath: bool | set[str], inline: str = "never") -> F:
    dispatcher = numba.njit(cache=True, nogil=True, error_model="numpy", fastmath=fastmath, inline=inline)(func)
    if dispatcher is not func:  # not under NUMBA_DISABLE_JIT=1
        aot.attach(dispatcher)
    return dispatcher


class _FrameBound:
    """A kernel whose last argument is the mechanisation frame, called from Python with that
    argument a compile-time constant (see :func:`for_frame`)."""

    __slots__ = ("func", "frame", "_entries")

    def __init__(self, func: Callable, frame: int) -> None:
        self.func = func
        self.frame = frame
        self._entries: dict[tuple, Callable] = {}

    def __call__(self, *args: Any) -> Any:
        key = tuple(map(type, args))
        entry = self._entries.get(key)
        if entry is None:
            entry = self._entries[key] = _compiled(self.func, args, self.frame)
        return _call(entry, args, self.frame)


def _compiled(func: Callable, args: tuple, frame: int) -> tuple[Callable, bool]:
    """The entry point of ``func`` for the types of ``args`` and the literal ``frame``, and
    whether it was built ahead of time (then called without the frame). Else it comes from the
    disk cache when it is there, or is ``func`` itself when kernels run as plain Python."""
    if not hasattr(func, "compile"):
        return func, False
    types = tuple(numba.typeof(a) for a in args)
    built = aot.frame_entry(func, frame, types)
    if built is not None:
        return built, True
    return func.compile(types + (numba.types.literal(frame),)), False


def _call(entry: tuple[Callable, bool], args: tuple, frame: int) -> Any:
    """Call an entry of :func:`_compiled`: a built one without the frame, the others with it."""
    call, built = entry
    return call(*args) if built else call(*args, frame)


def call_for_frame(func: Callable, frame: int, *args: Any) -> Any:
    """``func(*args, frame)`` for a batch call, through :func:`_compiled` each time (the argument
    types are looked up per call, a few microseconds; arrays may differ in layout between calls)."""
    return _call(_compiled(func, args, frame), args, frame)


@functools.lru_cache(maxsize=None)
def for_frame(func: Callable, frame: int) -> Callable:
    """``func(*args, frame)`` as a Python callable with ``frame`` a compile-time constant.

    A kernel that takes the frame through numba's ``literally`` compiles only that frame's
    branches, but a call from Python with a plain int goes through numba's slow path each time
    (about 3 ms) before it finds the literal overload. This compiles (or loads) the overload
    per tuple of Python argument types and then calls it directly. Arrays are taken as the
    first call's (the state, config and filter vectors are C-contiguous float64 throughout).
    """
    return _FrameBound(func, frame)
