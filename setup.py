"""Install-time build of the kernels Python calls first (mavins/core/aot.py).

``pip install .`` and ``pip install -e .`` run ``build_ext``, which here builds each package's
listed kernels with numba into an extension module beside the package's source (editable) or
in the wheel. Without a C compiler, or with a numba that no longer ships ``numba.pycc``, the
install still succeeds and the kernels compile on first use, as before.
"""

from __future__ import annotations

import sys
from pathlib import Path

from setuptools import Distribution, setup
from setuptools.command.build_ext import build_ext

ROOT = Path(__file__).resolve().parent
sys.path.insert(0, str(ROOT))

from mavins.core import aot  # noqa: E402  (the source being installed)


class BuildKernels(build_ext):
    """Build the ahead-of-time kernel modules."""

    def finalize_options(self) -> None:
        super().finalize_options()
        self._outputs: list[str] = []

    def run(self) -> None:
        if not aot.can_build():
            print("mavins: no working C compiler (or no numba.pycc): the kernels are not built ahead of time "
                  "and compile on first use instead", file=sys.stderr)
            return
        in_place = self.inplace or getattr(self, "editable_mode", False)
        outputs = {p: None if in_place else Path(self.build_lib).joinpath(*p.split(".")) for p in aot.PACKAGES}
        for out in outputs.values():
            if out is not None:
                out.mkdir(parents=True, exist_ok=True)
        for package, (ok, line) in aot.build_each(outputs).items():
            if ok:
                self._outputs.append(line)
            else:
                print(f"mavins: kernels of {package} not built ahead of time; they compile on first use "
                      f"instead ({line})", file=sys.stderr)

    def get_outputs(self) -> list[str]:
        return list(self._outputs)


class WithKernels(Distribution):
    """A distribution with compiled code (the kernel modules), so ``build_ext`` runs and a wheel is
    tagged for its platform."""

    def has_ext_modules(self) -> bool:
        return True


setup(cmdclass={"build_ext": BuildKernels}, distclass=WithKernels)
