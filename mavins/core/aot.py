"""Kernels built ahead of time, so that a first start loads compiled code instead of compiling it.

Numba compiles a kernel on its first call (about 20 s for what ``mavins demo`` calls, on two
cores) and keeps it in its disk cache. The kernels that Python calls on the live path, in
``mavins nav`` and in the simulator are also built once, at install time, into an extension module per package
(numba's ``numba.pycc``, from the very same source): ``mavins/core/_kernels_<digest>`` and
``sim/_kernels_<digest>``. Each package lists those entry points with their signatures in its
``exports.py``.

When a kernel is created (:func:`mavins.core.jit.kernel`), :func:`attach` hands the built entry
points of that kernel to it: a call from Python with exactly the exported argument types runs the
built code, any other call compiles as before. The digest in the module's name covers the source
of the package and of this core, so a module built from other source is never loaded: edited
kernels compile on first use until the next build (``python -m mavins.core.aot``).
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import os
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

CORE = Path(__file__).resolve().parent
PACKAGES = ("mavins.core", "sim")  # the packages whose exports.py lists built entry points


@dataclass(frozen=True)
class Export:
    """One entry point built ahead of time: kernel ``name`` of module ``module`` (within its
    package) for the numba signature ``signature`` (return type and argument types); ``frame``
    is the mechanisation frame for kernels that take it as their last, literal argument
    (:func:`mavins.core.jit.for_frame`), left out of ``signature``."""

    module: str
    name: str
    signature: str
    frame: int | None = None
    variant: str = ""  # names a second signature of the same kernel (and frame)

    @property
    def symbol(self) -> str:
        """The name of the built function in the extension module."""
        tail = ("" if self.frame is None else f"_frame{self.frame}") + (f"_{self.variant}" if self.variant else "")
        return f"{self.module}__{self.name}{tail}"


def source_digest(*folders: Path) -> str:
    """A digest (16 hex digits) of every ``*.py`` file in ``folders``: names and bytes."""
    digest = hashlib.sha256()
    for folder in folders:
        for src in sorted(folder.glob("*.py")):
            digest.update(src.name.encode())
            digest.update(src.read_bytes())
    return digest.hexdigest()[:16]


def module_name(package: str) -> str:
    """The name of ``package``'s built module for its current source (no package prefix)."""
    folder = Path(importlib.import_module(package).__path__[0])
    folders = (folder,) if folder == CORE else (folder, CORE)
    return f"_kernels_{source_digest(*folders)}"


def _package_of(module: str) -> str | None:
    return next((p for p in PACKAGES if module.startswith(p + ".")), None)


_loaded: dict[str, tuple[Any, dict[str, list[Export]]] | None] = {}
_frame_entries: dict[tuple[int, int, tuple], Callable] = {}
# numba keeps a type (and with it the code the dispatcher matches on) only while it is referenced:
# the argument types of every inserted entry are held here for the life of the process
_inserted: list[tuple[Any, tuple, Callable]] = []


def _built(package: str) -> tuple[Any, dict[str, list[Export]]] | None:
    """``package``'s built module and its exports by kernel, or None when there is none for the
    current source (not built, built from other source, or ``MAVINS_AOT=0``)."""
    if package not in _loaded:
        _loaded[package] = None
        if os.environ.get("MAVINS_AOT", "1") != "0":
            try:
                built = importlib.import_module(f"{package}.{module_name(package)}")
            except ImportError:
                built = None
            if built is not None:
                table: dict[str, list[Export]] = {}
                for e in importlib.import_module(f"{package}.exports").EXPORTS:
                    table.setdefault(f"{package}.{e.module}.{e.name}", []).append(e)
                _loaded[package] = (built, table)
    return _loaded[package]


def has_built(package: str) -> bool:
    """Whether ``package``'s module built from its current source is loaded."""
    return _built(package) is not None


def argument_types(export: Export) -> tuple:
    """The numba argument types of ``export`` (its frame left out)."""
    from numba.core import sigutils

    args, _ = sigutils.normalize_signature(export.signature)
    return tuple(args)


def attach(dispatcher: Any) -> None:
    """Give ``dispatcher`` (a numba kernel) the built entry points of its function, if any."""
    func = dispatcher.py_func
    package = _package_of(func.__module__)
    built = _built(package) if package else None
    if built is None:
        return
    module, table = built
    for export in table.get(f"{func.__module__}.{func.__name__}", ()):
        entry = getattr(module, export.symbol, None)
        if entry is None:
            continue
        args = argument_types(export)
        if export.frame is None:
            # the dispatcher's own C fast path then calls the built function for these argument
            # types, as it calls a compiled overload; a kernel calling this one still compiles it
            dispatcher._insert([a._code for a in args], entry, False)
            _inserted.append((dispatcher, args, entry))
        else:
            _frame_entries[(id(dispatcher), export.frame, args)] = entry


def frame_entry(dispatcher: Any, frame: int, args: tuple) -> Callable | None:
    """The built entry point of ``dispatcher`` for ``frame`` and numba argument types ``args``
    (frame left out), called without the frame; None when there is none."""
    return _frame_entries.get((id(dispatcher), frame, args))


def _frame_wrapper(kernel: Any, arity: int, frame: int) -> Callable:
    """A function of ``arity`` arguments calling ``kernel`` with those and the literal ``frame``
    (numba types the constant as a literal, so only that frame's branches are built)."""
    names = ", ".join(f"a{i}" for i in range(arity))
    scope: dict[str, Any] = {"kernel": kernel}
    exec(f"def entry({names}):\n    return kernel({names}, {int(frame)})", scope)  # noqa: S102
    return scope["entry"]


def build(package: str, output_dir: Path | None = None) -> Path:
    """Build ``package``'s exports into its extension module; return the module's path.

    Kernels the exports call are compiled on the way; they go to a throw-away numba cache so
    that the user's cache stays as it was.
    """
    with tempfile.TemporaryDirectory(prefix="mavins-aot-") as scratch:
        os.environ["NUMBA_CACHE_DIR"] = scratch
        os.environ["MAVINS_AOT"] = "0"  # build from source, never from an older build
        import warnings

        import numba
        from numba.pycc import CC

        numba.config.CACHE_DIR = scratch
        warnings.filterwarnings("ignore", category=numba.NumbaPendingDeprecationWarning)
        name = module_name(package)
        folder = Path(importlib.import_module(package).__path__[0])
        cc = CC(name)
        cc.output_dir = str(output_dir or folder)
        cc.target_cpu = "host"  # built where it runs, like the JIT
        for export in importlib.import_module(f"{package}.exports").EXPORTS:
            kernel = getattr(importlib.import_module(f"{package}.{export.module}"), export.name)
            func = kernel.py_func if export.frame is None else _frame_wrapper(
                kernel, len(argument_types(export)), export.frame)
            cc.export(export.symbol, export.signature)(func)
        cc.compile()
    built = Path(cc.output_dir) / cc.output_file
    for old in built.parent.glob("_kernels_*"):  # modules of earlier source, never loaded again
        if old != built:
            old.unlink()
    return built


def can_build() -> bool:
    """Whether this machine can build the modules: numba still ships ``numba.pycc`` and a C
    compiler works (numba's own check: it compiles an empty C program)."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            from numba.pycc.platform import external_compiler_works
        except ImportError:
            return False
    return bool(external_compiler_works())


def is_built(package: str) -> bool:
    """Whether ``package``'s module for its current source exists (loaded or not)."""
    return importlib.util.find_spec(f"{package}.{module_name(package)}") is not None


def build_each(outputs: dict[str, Path | None]) -> dict[str, tuple[bool, str]]:
    """Build each package of ``outputs`` into its folder there (None: beside its source), each in
    a fresh interpreter and side by side (up to a minute of one core each). Returns, per package,
    whether it was built and the built module's path or the last line of the error that stopped it."""
    root = CORE.parents[1]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, (str(root), os.environ.get("PYTHONPATH"))))}
    procs = {}
    for package, out in outputs.items():
        code = f"from pathlib import Path; from mavins.core import aot; print(aot.build({package!r}, " \
               f"{None if out is None else f'Path({str(out)!r})'}))"
        procs[package] = subprocess.Popen([sys.executable, "-c", code], env=env, text=True,
                                          stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    result = {}
    for package, proc in procs.items():
        out, err = proc.communicate()
        lines = (out if proc.returncode == 0 else err).strip().splitlines() or ["(no output)"]
        result[package] = (proc.returncode == 0, lines[-1])
    return result


def main(argv: list[str] | None = None) -> int:
    """``python -m mavins.core.aot [--if-missing] [PACKAGE ...]``: build the packages' modules
    beside their source (all of :data:`PACKAGES` by default); with ``--if-missing`` only those
    not built from the current source. Exit status 1 when a build failed."""
    args = list(argv or ())
    packages = [a for a in args if a != "--if-missing"] or list(PACKAGES)
    if "--if-missing" in args:
        packages = [p for p in packages if not is_built(p)]
    if not packages:
        return 0
    if not can_build():
        print("mavins: no working C compiler (or no numba.pycc): the kernels compile on first use instead",
              file=sys.stderr)
        return 0 if "--if-missing" in args else 1
    print(f"mavins: building the kernels of {', '.join(packages)} ahead of time (about a minute)",
          file=sys.stderr, flush=True)
    failed = 0
    for package, (ok, line) in build_each(dict.fromkeys(packages)).items():
        failed += not ok
        print(f"mavins: {package}: {'built ' if ok else 'not built, compiles on first use: '}{line}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
