"""Run every benchmark in ``benchmarks/`` and print one table.

A benchmark is a module ``bench_*.py`` in this folder that defines
``main(argv=()) -> list[dict]``; each dict is one table row with keys of
:data:`COLUMNS` (missing keys print as ``-``; a column that is empty in every
row is left out). A module may also define ``NOTES`` (lines printed under the
table) and ``BASELINE`` (what its ratios compare with, listed under the table).
Run from the repository root::

    .venv/bin/python benchmarks/run_all.py                 # everything, full length
    .venv/bin/python benchmarks/run_all.py --quick         # short runs, for trying things out
    .venv/bin/python benchmarks/run_all.py --only bench_replay --args bench_replay="--workdir /tmp/tlogs"

Speed is reported here, as a table, never by timed assertions in the tests.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import importlib
import os
import platform
import shlex
import sys
import time
import traceback
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))


def _num(fmt: str) -> Callable[[Any], str]:
    return lambda v: format(float(v), fmt)


#: (key, header, formatter) of the printed columns, in order.
COLUMNS: tuple[tuple[str, str, Callable[[Any], str]], ...] = (
    ("case", "case", str),
    ("samples", "samples", lambda v: f"{int(v):,}"),
    ("seconds", "seconds", lambda v: f"{float(v):.3f}" if float(v) < 100 else f"{float(v):.1f}"),
    ("rate", "per s", _num(",.0f")),
    ("value", "value", str),
    ("ratio", "ratio", lambda v: f"{float(v):.2f}x"),
    ("baseline", "ratio against", str),
    ("goal", "goal", str),
    ("note", "note", str),
)
_RIGHT = {"samples", "seconds", "rate", "value", "ratio"}

#: What the ratios of modules that do not say so themselves compare with.
DEFAULT_BASELINES = {"bench_nav": "pyins compute (timed part), same record"}
#: Goals of rows of modules that do not state them: (module, case prefix) -> (minimum ratio, text).
DEFAULT_GOALS = {("bench_nav", "mavins compute (kernel, samples=2)"): (3.0, ">= 3x pyins")}
#: Arguments of ``--quick`` per module (modules not listed get ``--quick``).
QUICK_ARGS = {"bench_nav": ["--n", "200000", "--repeat", "1", "--no-subprocess"]}


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


def _dist_version(dist: str) -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(dist)
    except PackageNotFoundError:
        return "not installed"


def _pyins_version() -> str:
    return _dist_version("python-ins")


def _load() -> str:
    try:
        return " ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        return "unknown"


def machine_info() -> list[str]:
    """Lines describing the machine and the software the numbers come from."""
    cores = os.cpu_count() or 0
    try:
        usable = len(os.sched_getaffinity(0))
    except AttributeError:
        usable = cores
    mem = ""
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            kb = int(next(line for line in fh if line.startswith("MemTotal")).split()[1])
        mem = f", {kb / 1024 / 1024:.0f} GB RAM"
    except (OSError, StopIteration, ValueError):
        pass
    return [
        f"date:    {_dt.datetime.now().astimezone().strftime('%Y-%m-%d %H:%M %Z')}",
        f"cpu:     {_cpu_model()}, {cores} cores ({usable} usable){mem}",
        f"python:  {platform.python_version()} ({platform.python_implementation()}, {platform.system()} {platform.release()})",
        f"numpy:   {_version('numpy')}, numba: {_version('numba')}, pymavlink: {_dist_version('pymavlink')}, "
        f"rerun-sdk: {_dist_version('rerun-sdk')}, pyins: {_pyins_version()}, mavins: {_dist_version('mavins')}",
        f"load:    {_load()} (1/5/15 min load average at the start)",
    ]


def print_report(rows: list[dict], notes: list[str]) -> None:
    """What a benchmark script prints when run on its own: machine, table, notes."""
    print("\n".join(machine_info()))
    print()
    print(format_table(rows))
    for line in notes:
        print(line)


def format_table(rows: Iterable[dict]) -> str:
    """Plain-text table of the rows; absent or None cells print as ``-``; all-empty columns are left out."""
    rows = list(rows)
    cols = [c for c in COLUMNS if c[0] == "case" or any(r.get(c[0]) not in (None, "") for r in rows)]
    cells = [[h for _, h, _ in cols]]
    for r in rows:
        cells.append([("-" if r.get(k) in (None, "") else f(r[k])) for k, _, f in cols])
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
    """Names of the ``bench_*.py`` modules in this folder that define ``main()``."""
    names = []
    for path in sorted(HERE.glob("bench_*.py")):
        text = path.read_text(encoding="utf-8")
        if "\ndef main(" in text:
            names.append(path.stem)
    return names


def _adapt(name: str, rows: list[dict]) -> list[dict]:
    """Fill the baseline and goal cells of modules that predate those columns."""
    base = DEFAULT_BASELINES.get(name)
    for r in rows:
        if r.get("ratio") is not None and not r.get("baseline") and base:
            is_base = abs(float(r["ratio"]) - 1.0) < 1e-12 and base.split(",")[0] in str(r.get("case", ""))
            r["baseline"] = "(is the baseline)" if is_base else base.split(",")[0]
        for (mod, prefix), (minimum, text) in DEFAULT_GOALS.items():
            if mod == name and str(r.get("case", "")).startswith(prefix) and r.get("ratio") is not None:
                r.setdefault("goal", f"{text}: {'met' if float(r['ratio']) >= minimum else 'NOT met'}")
    return rows


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description="Run every benchmark and print one table.")
    p.add_argument("--only", action="append", default=[], metavar="NAME", help="run only this module (repeatable)")
    p.add_argument("--quick", action="store_true", help="short runs (development; not for docs/performance.md)")
    p.add_argument("--args", action="append", default=[], metavar="NAME=ARGS",
                   help="extra arguments for one module, e.g. bench_latency=\"--profile\" (repeatable)")
    args = p.parse_args(sys.argv[1:] if argv is None else list(argv))
    extra: dict[str, list[str]] = {}
    for item in args.args:
        name, _, text = item.partition("=")
        extra.setdefault(name, []).extend(shlex.split(text))

    header = machine_info()
    rows: list[dict] = []
    notes: list[str] = []
    baselines: list[str] = []
    for name in discover():
        if args.only and name not in args.only:
            continue
        margv = (QUICK_ARGS.get(name, ["--quick"]) if args.quick else []) + extra.get(name, [])
        print(f"running {name} {' '.join(margv)} ...", file=sys.stderr, flush=True)
        t0 = time.perf_counter()
        try:
            module = importlib.import_module(name)
            result = _adapt(name, list(module.main(margv)))
        except Exception as exc:  # noqa: BLE001 - one failing benchmark must not hide the others
            traceback.print_exc()
            rows.append({"case": f"{name} FAILED", "note": f"{type(exc).__name__}: {exc}".splitlines()[0]})
            continue
        print(f"{name} took {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
        rows.extend(result)
        notes.extend(f"[{name}] {n}" for n in getattr(module, "NOTES", []))
        b = getattr(module, "BASELINE", None) or DEFAULT_BASELINES.get(name)
        if b:
            baselines.append(f"  {name}: {b}")
    print("\n".join(header))
    print(f"load:    {_load()} at the end")
    if args.quick:
        print("mode:    --quick (short runs; not the figures of record)")
    print()
    print(format_table(rows))
    print()
    print("ratio = the row's figure / the baseline's figure, both measured in this run: for throughputs (per s) "
          "above 1 is faster; for latency and CPU below 1 is better.")
    if baselines:
        print("baselines:")
        print("\n".join(baselines))
    for note in notes:
        print(note)
    return 0


if __name__ == "__main__":
    sys.exit(main())
