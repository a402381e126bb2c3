"""The package map of DEVELOPERS.md, checked on the source: which room may import which, and no module
name used twice.

Every ``import`` and ``from ... import`` of mavins/ and sim/ is read with ``ast`` (relative imports
resolved against the module's package), also those inside functions, and each edge is held to the
rooms' rule. A new import against the flow (the core importing the link, the link the recorder, the
live shell a command face, the simulator the service) fails here with the module and the import.
"""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# the rooms are folders of mavins/ (DEVELOPERS.md "Layout"); the command faces sit at its top
ROOMS = {"mavins.core": "core", "mavins.link": "link", "mavins.record": "record", "mavins.common": "utilities",
         "mavins.live": "live", "mavins.cli": "cli"}
FACES = {"mavins.service", "mavins.replay", "mavins.demo", "mavins.nav", "mavins.navfdi",
         "mavins.analysis", "mavins.__main__"}
SAME_NAME_BY_DESIGN = {"__init__.py", "__main__.py", "exports.py"}  # exports.py: one per built package (core/aot.py)


def room(module: str) -> str:
    """The room of a module (DEVELOPERS.md "Layout"): its folder, or the faces at the top."""
    if module == "mavins":  # the package's __init__ holds its version only
        return "core"
    for prefix, name in ROOMS.items():
        if module == prefix or module.startswith(prefix + "."):
            return name
    if module in FACES:
        return "faces"
    if module == "sim" or module.startswith("sim."):
        return "sim"
    return "other"


# room -> the rooms it may import (its own included); third-party imports are checked separately
MAY_IMPORT = {
    "core": {"core"},
    "link": {"core", "link"},
    "record": {"core", "record", "utilities"},
    "utilities": {"core", "utilities"},
    "live": {"core", "link", "record", "utilities", "live"},
    "faces": {"core", "link", "record", "utilities", "live", "faces", "sim"},
    "sim": {"core", "link", "utilities", "sim"},
    "cli": {"core", "link", "record", "utilities", "live", "faces", "sim", "cli"},  # parses, then calls in
}
THIRD_PARTY_ONLY_IN = {"pymavlink": {"link", "sim", "faces"}, "rerun": {"record"}}


def _modules() -> dict[str, Path]:
    out = {}
    for top in ("mavins", "sim"):
        for p in sorted((ROOT / top).rglob("*.py")):
            if "_kernels_" in p.name:
                continue
            parts = list(p.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = p
    return out


def _imports(module: str, path: Path) -> set[str]:
    pkg = module if path.name == "__init__.py" else module.rsplit(".", 1)[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = pkg.split(".")[: len(pkg.split(".")) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
                if node.module is None:  # from . import x: x may be a module
                    found.update(f"{target}.{a.name}" for a in node.names)
                else:
                    found.add(target)
            else:
                found.add(node.module or "")
                found.update(f"{node.module}.{a.name}" for a in node.names)  # from pkg import module
    return found


def _resolve(name: str, modules: dict[str, Path]) -> str | None:
    """The project module an import names (the longest known prefix), or None for a third-party one."""
    parts = name.split(".")
    for k in range(len(parts), 0, -1):
        if ".".join(parts[:k]) in modules:
            return ".".join(parts[:k])
    return None


def test_every_module_sits_in_a_room() -> None:
    unplaced = [m for m in _modules() if room(m) == "other"]
    assert not unplaced, f"modules in no room of DEVELOPERS.md (add them to the map): {unplaced}"


def test_no_import_runs_against_the_flow() -> None:
    modules = _modules()
    bad = []
    for m, path in modules.items():
        here = room(m)
        for name in _imports(m, path):
            target = _resolve(name, modules)
            if target is not None:
                if room(target) not in MAY_IMPORT[here]:
                    bad.append(f"{m} ({here}) imports {target} ({room(target)})")
            else:
                top = name.split(".")[0]
                if top in THIRD_PARTY_ONLY_IN and here not in THIRD_PARTY_ONLY_IN[top]:
                    bad.append(f"{m} ({here}) imports {name}")
    assert not bad, "imports against the flow (DEVELOPERS.md):\n" + "\n".join(bad)


def test_no_module_name_is_used_twice() -> None:
    by_name = defaultdict(list)
    for m, path in _modules().items():
        if path.name not in SAME_NAME_BY_DESIGN:
            by_name[path.name].append(m)
    twice = {n: ms for n, ms in by_name.items() if len(ms) > 1}
    assert not twice, f"module names used twice: {twice}"


def test_the_rules_catch_a_core_module_importing_the_link(tmp_path: Path) -> None:
    """The checker itself: an import of mavins.link from a core module is against the flow, one of the
    core from the link is not, and rerun outside the recorder is caught."""
    modules = {"mavins.core.x": tmp_path / "x.py", "mavins.link.ingest": tmp_path / "i.py",
               "mavins.core.records": tmp_path / "r.py"}
    assert room(_resolve("mavins.link.ingest", modules)) not in MAY_IMPORT["core"]
    assert room(_resolve("mavins.core.records", modules)) in MAY_IMPORT["link"]
    assert "faces" not in MAY_IMPORT["live"] and "live" not in MAY_IMPORT["sim"]
    assert "core" not in THIRD_PARTY_ONLY_IN["rerun"]


def _kernel_linear_algebra(path: Path) -> list[str]:
    """``@`` products and np.dot / np.linalg calls inside the @kernel / @sum_kernel functions of a file."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if not isinstance(node, ast.FunctionDef):
            continue
        if not any(isinstance(d, ast.Name) and d.id in ("kernel", "sum_kernel") for d in node.decorator_list):
            continue
        for sub in ast.walk(node):
            if isinstance(sub, ast.BinOp) and isinstance(sub.op, ast.MatMult):
                found.append(f"{path.name}:{sub.lineno} {node.name}: @")
            elif isinstance(sub, ast.Attribute) and sub.attr in ("dot", "linalg") and \
                    isinstance(sub.value, ast.Name) and sub.value.id == "np":
                found.append(f"{path.name}:{sub.lineno} {node.name}: np.{sub.attr}")
    return found


def test_no_kernel_uses_numbas_linear_algebra(tmp_path: Path) -> None:
    """numba's np.dot, ``@`` and np.linalg need SciPy, which an install does not have: a kernel using
    them fails the build of the kernels on a fresh machine (DEVELOPERS.md). The checker sees one."""
    bad = [hit for p in _modules().values() for hit in _kernel_linear_algebra(p)]
    assert not bad, f"kernels using numba's linear algebra (write the loop): {bad}"
    probe = tmp_path / "probe.py"
    probe.write_text("@kernel\ndef f(a, b):\n    return a @ b + np.dot(a, b)\n\ndef g(a, b):\n    return a @ b\n")
    assert [h.split(" ", 1)[1] for h in _kernel_linear_algebra(probe)] == ["f: @", "f: np.dot"]
