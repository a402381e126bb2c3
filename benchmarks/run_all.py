"""Run every benchmark in ``benchmarks/`` and print one table.

A benchmark is any module in this folder that defines ``main() -> list[dict]``;
each dict is one table row with the keys of :data:`COLUMNS` (missing keys
print as ``-``). Run from the repository root::

    .venv/bin/python benchmarks/run_all.py

Speed is reported here, as a table, never by timed assertions in the tests.
"""

from __future__ import annotations

import datetime as _dt
import importlib
import os
import platform
import sys
from pathlib import Path
from typing import Any, Callable, Iterable

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

#: (key, header, formatter) of the printed columns, in order.
COLUMNS: tuple[tuple[str, str, Callable[[Any], str]], ...] = (
    ("case", "case", str),
    ("samples", "samples", lambda v: f"{int(v):,}"),
    ("seconds", "seconds", lambda v: f"{float(v):.3f}"),
    ("rate", "samples/s", lambda v: f"{float(v):,.0f}"),
    ("ratio", "ratio vs pyins", lambda v: f"{float(v):.2f}x"),
    ("note", "note", str),
)
_RIGHT = {"samples", "seconds", "rate", "ratio"}


def _cpu_model() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"


def _version(module: str) -> str:
    try:
        return str(importlib.import_module(module).__version__)
    except Exception:  # noqa: BLE001 - a missing module is reported, not raised
        return "not installed"


def machine_info() -> list[str]:
    """Lines describing the machine and the software the numbers come from."""
    cores = os.cpu_count() or 0
    try:
        usable = len(os.sched_getaffinity(0))
    except AttributeError:
        usable = cores
    return [
        f"date:    {_dt.datetime.now().astimezone().strftime('%Y-%m-%d %H:%M %Z')}",
        f"cpu:     {_cpu_model()}, {cores} cores ({usable} usable)",
        f"python:  {platform.python_version()} ({platform.python_implementation()}, {platform.system()} {platform.release()})",
        f"numpy:   {_version('numpy')}, numba: {_version('numba')}, pyins: {_pyins_version()}",
    ]


def _pyins_version() -> str:
    try:
        from importlib.metadata import PackageNotFoundError, version

        return version("python-ins")
    except PackageNotFoundError:
        return "not installed"


def format_table(rows: Iterable[dict]) -> str:
    """Plain-text table of the rows; absent or None cells print as ``-``."""
    rows = list(rows)
    cols = [c for c in COLUMNS if c[0] != "note" or any(r.get("note") for r in rows)]
    cells = [[h for _, h, _ in cols]]
    for r in rows:
        cells.append([("-" if r.get(k) is None else f(r[k])) for k, _, f in cols])
    widths = [max(len(row[i]) for row in cells) for i in range(len(cols))]

    def line(row: list[str]) -> str:
        parts = []
        for (key, _, _), w, text in zip(cols, widths, row):
            parts.append(text.rjust(w) if key in _RIGHT else text.ljust(w))
        return "  ".join(parts).rstrip()

    out = [line(cells[0]), "  ".join("-" * w for w in widths)]
    out += [line(r) for r in cells[1:]]
    return "\n".join(out)


def discover() -> list[str]:
    """Module names in this folder that define ``main()``."""
    names = []
    for path in sorted(HERE.glob("*.py")):
        if path.stem in ("run_all", "__init__"):
            continue
        text = path.read_text(encoding="utf-8")
        if "\ndef main(" in text:
            names.append(path.stem)
    return names


def main() -> int:
    rows: list[dict] = []
    notes: list[str] = []
    for name in discover():
        print(f"running {name} ...", file=sys.stderr, flush=True)
        module = importlib.import_module(name)
        result = module.main()
        rows.extend(result)
        notes.extend(getattr(module, "NOTES", []))
    print("\n".join(machine_info()))
    print()
    print(format_table(rows))
    for note in notes:
        print(note)
    return 0


if __name__ == "__main__":
    sys.exit(main())
