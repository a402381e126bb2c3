"""Kernels built ahead of time (mavins/core/aot.py): loaded, complete, and the JIT's very code.

The install builds every kernel the live path, ``mavins nav`` and the simulator call from Python
into an extension module per package. These tests hold it to four things: the modules of the
current source are there and loaded; each export's signature is the one numba infers for those
argument types; the demo's computation and ``mavins nav``'s files are the same bytes with and
without them; and the demo's whole path and ``mavins nav`` with aiding files, started on an
empty numba cache, compile nothing.
"""

from __future__ import annotations

import importlib
import json
import subprocess
import sys
from pathlib import Path

import numba
import pytest
from numba.core import sigutils

from support import ENV, mavins
from mavins.core import aot

HERE = Path(__file__).resolve().parents[1]  # tests/, where aot_probe.py is
pytestmark = pytest.mark.skipif(not aot.can_build(), reason="no working C compiler here (or a numba without "
                                "numba.pycc): the install could not build the kernels; tests/faces/test_cold_start.py "
                                "covers the path every kernel then takes (the JIT)")


def _exports() -> list[tuple[str, aot.Export]]:
    return [(p, e) for p in aot.PACKAGES for e in importlib.import_module(f"{p}.exports").EXPORTS]


def test_the_modules_of_the_current_source_are_built_and_loaded() -> None:
    for package in aot.PACKAGES:
        assert aot.is_built(package), f"{package}: run `python -m mavins.core.aot` (or reinstall)"
        assert aot.has_built(package)


@pytest.mark.parametrize(("package", "export"), _exports(), ids=lambda v: getattr(v, "symbol", v))
def test_each_export_has_the_signature_numba_infers(package: str, export: aot.Export) -> None:
    kernel = getattr(importlib.import_module(f"{package}.{export.module}"), export.name)
    args, ret = sigutils.normalize_signature(export.signature)
    full = tuple(args) + (() if export.frame is None else (numba.types.literal(export.frame),))
    kernel.compile(full)
    assert kernel.overloads[full].signature.return_type == ret


def test_the_demos_computation_is_the_same_bytes_without_them(tmp_path: Path) -> None:
    """The same flight and filter through the built kernels (empty numba cache: nothing may
    compile) and through numba's JIT (``MAVINS_AOT=0``)."""
    def probe(**env: str) -> dict:
        res = subprocess.run([sys.executable, str(HERE / "aot_probe.py")], env={**ENV, **env}, cwd=tmp_path,
                             capture_output=True, text=True, timeout=900)
        assert res.returncode == 0, res.stderr
        return json.loads(res.stdout)

    cache = tmp_path / "numba-cache"
    built = probe(NUMBA_CACHE_DIR=str(cache), MAVINS_AOT="1")
    assert built["built"] == {p: True for p in aot.PACKAGES}
    assert not list(cache.rglob("*.nbi")), "a kernel the demo calls from Python is not built ahead of time"
    jit = probe(MAVINS_AOT="0")
    assert jit["built"] == {p: False for p in aot.PACKAGES}
    assert built["solutions"] > 300
    assert (built["simulated"], built["published"], built["solutions"]) == \
        (jit["simulated"], jit["published"], jit["solutions"])


def test_the_demo_on_an_empty_cache_compiles_nothing(tmp_path: Path) -> None:
    cache = tmp_path / "numba-cache"
    cache.mkdir()
    res = mavins("demo", "--duration", "12", "--no-rerun", cwd=tmp_path,
                 env={**ENV, "NUMBA_CACHE_DIR": str(cache), "MAVINS_AOT": "1"})
    text = res.stdout + res.stderr
    assert res.returncode == 0, text
    assert "NAVIGATING" in text and "compiling" not in text, text
    assert not list(cache.rglob("*.nbi")), sorted(p.name for p in cache.rglob("*.nbi"))


def test_the_module_name_follows_every_byte_of_the_source(tmp_path: Path) -> None:
    """A module built from other source is never loaded: its name holds a digest of the source."""
    a, b = tmp_path / "a", tmp_path / "b"
    for folder in (a, b):
        folder.mkdir()
        (folder / "k.py").write_text("x = 1\n")
        (folder / "l.py").write_text("y = 2\n")
    assert aot.source_digest(a) == aot.source_digest(b)
    (b / "l.py").write_text("y = 3\n")
    assert aot.source_digest(a) != aot.source_digest(b)
    (b / "l.py").write_text("y = 2\n")
    (b / "m.py").write_text("")
    assert aot.source_digest(a) != aot.source_digest(b)
    assert aot.module_name("mavins.core") == "_kernels_" + aot.source_digest(aot.CORE)
    assert aot.module_name("sim") == "_kernels_" + aot.source_digest(aot.CORE.parents[1] / "sim", aot.CORE)


def test_mavins_nav_on_an_empty_cache_compiles_nothing_and_writes_the_jits_bytes(tmp_path: Path) -> None:
    """The batch strapdown run and the batch filter (``--gnss``, ``--baro``; smoothed: the forward pass is the
    same kernel with an epoch store, and the backward pass and the rows are built too), ahead of time."""
    res = mavins("sim", "flight", "-o", "d", "--duration", "30", "--grade", "consumer", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    cache = tmp_path / "numba-cache"
    for aiding in ((), ("--gnss", "d/gnss.csv", "--baro", "d/baro.csv", "--smooth")):
        outputs = {}
        for flag, env in (("1", {"NUMBA_CACHE_DIR": str(cache)}), ("0", {})):
            out = tmp_path / f"nav{flag}.csv"
            res = mavins("nav", "d/imu.csv", "--init", "d/init.json", "-o", str(out), *aiding, cwd=tmp_path,
                         env={**ENV, **env, "MAVINS_AOT": flag})
            assert res.returncode == 0, res.stderr
            outputs[flag] = out.read_bytes()
        assert not list(cache.rglob("*.nbi")), sorted(p.name for p in cache.rglob("*.nbi"))
        assert outputs["1"] == outputs["0"] and outputs["1"].count(b"\n") > 1000


def test_each_export_has_its_own_symbol() -> None:
    """Two signatures of one kernel (aot.Export.variant) build to two functions: no symbol is used twice."""
    symbols = [e.symbol for _, e in _exports()]
    assert len(symbols) == len(set(symbols))
    assert any(e.variant for _, e in _exports())
