"""The contract's files: IMU CSVs, initial-state JSON, solution/truth CSVs.

Every reading error is a :class:`DataFileError` whose message names the file,
the line and the column, so the command line can print one clear line.
Floats are written with round-trip precision (CONVENTIONS.md "Files").
"""

from __future__ import annotations

import csv
import io
import json
import math
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

INCREMENT_COLUMNS = ("t", "dtheta_x", "dtheta_y", "dtheta_z", "dv_x", "dv_y", "dv_z")
RATE_COLUMNS = ("t", "gyro_x", "gyro_y", "gyro_z", "acc_x", "acc_y", "acc_z")
SOLUTION_COLUMNS = ("t", "lat", "lon", "h", "vn", "ve", "vd", "roll", "pitch", "yaw", "qw", "qx", "qy", "qz")
INIT_KEYS = ("t", "lat", "lon", "h", "vn", "ve", "vd", "roll", "pitch", "yaw")


class DataFileError(ValueError):
    """A data file that cannot be used, with a message naming where and why."""


@dataclass(frozen=True)
class InitialState:
    """Initial state of CONVENTIONS.md: time (s), lat/lon/angles (deg), h (m), NED velocity (m/s)."""

    t: float
    lat: float
    lon: float
    h: float
    vn: float
    ve: float
    vd: float
    roll: float
    pitch: float
    yaw: float

    def to_dict(self) -> dict[str, float]:
        return {k: getattr(self, k) for k in INIT_KEYS}


def _open_text(path: Path) -> io.TextIOBase:
    if path.suffix == ".gz":
        import gzip

        return io.TextIOWrapper(gzip.open(path, "rb"), encoding="utf-8")
    return open(path, encoding="utf-8", newline="")


def _file_line(path: Path, data_row: int) -> int:
    """File line number (1-based) of a data row, counting the blank lines numpy skips."""
    with _open_text(path) as fh:
        next(fh)
        seen = -1
        for lineno, line in enumerate(fh, start=2):
            if line.strip():
                seen += 1
                if seen == data_row:
                    return lineno
    return data_row + 2


def _locate_bad_cell(path: Path, header: list[str], wanted: tuple[str, ...]) -> str:
    """Slow second pass that finds the first cell which is not a number."""
    try:
        return _scan_cells(path, header, wanted)
    except UnicodeDecodeError:
        return _bad_text(path)


def _bad_text(path: Path) -> str:
    """Message naming the first line that is not UTF-8."""
    import gzip

    opener = gzip.open if path.suffix == ".gz" else open
    with opener(path, "rb") as fh:
        for lineno, raw in enumerate(fh, start=1):
            try:
                raw.decode("utf-8")
            except UnicodeDecodeError as exc:
                return f"{path}: line {lineno}: not UTF-8 text ({exc.reason} at column {exc.start + 1})"
    return f"{path}: not UTF-8 text"


def _scan_cells(path: Path, header: list[str], wanted: tuple[str, ...]) -> str:
    idx = {name: header.index(name) for name in wanted}
    with _open_text(path) as fh:
        reader = csv.reader(fh)
        next(reader)
        for lineno, row in enumerate(reader, start=2):
            if not row:
                continue
            for name, j in idx.items():
                if j >= len(row):
                    return f"{path}: line {lineno}: column '{name}' is missing (row has {len(row)} fields)"
                try:
                    float(row[j])
                except ValueError:
                    return f"{path}: line {lineno}, column '{name}': not a number: {row[j]!r}"
    return f"{path}: cannot parse as CSV numbers"


def read_table(path: str | Path, columns: tuple[str, ...], *, strictly_increasing: bool = True) -> np.ndarray:
    """Read the named columns of a CSV (extra columns ignored) into an (n, k) array.

    Raises DataFileError for a missing file or column, a non-numeric cell, a
    NaN/Inf value, an empty table, or a time column that does not increase.
    """
    path = Path(path)
    if not path.is_file():
        raise DataFileError(f"{path}: no such file")
    try:
        with _open_text(path) as fh:
            header_line = fh.readline()
    except (OSError, UnicodeDecodeError) as exc:
        raise DataFileError(f"{path}: cannot read: {exc}") from None
    header = [h.strip() for h in header_line.strip().split(",")]
    missing = [c for c in columns if c not in header]
    if missing:
        raise DataFileError(
            f"{path}: line 1: missing column(s) {', '.join(missing)} (header has: {', '.join(header)})"
        )
    usecols = [header.index(c) for c in columns]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # "input contained no data": reported below
            data = np.loadtxt(path, delimiter=",", skiprows=1, usecols=usecols, ndmin=2, dtype=np.float64)
    except (ValueError, IndexError):
        raise DataFileError(_locate_bad_cell(path, header, columns)) from None
    except UnicodeDecodeError:
        raise DataFileError(_bad_text(path)) from None
    if data.shape[0] == 0:
        raise DataFileError(f"{path}: no data rows")
    bad = ~np.isfinite(data)
    if bad.any():
        i, j = np.argwhere(bad)[0]
        raise DataFileError(
            f"{path}: line {_file_line(path, i)}, column '{columns[j]}': value {float(data[i, j])!r} is not finite"
        )
    if strictly_increasing and data.shape[0] > 1:
        steps = np.diff(data[:, 0])
        nonpos = np.flatnonzero(~(steps > 0))
        if nonpos.size:
            i = nonpos[0] + 1
            raise DataFileError(
                f"{path}: line {_file_line(path, i)}, column 't': time {float(data[i, 0])!r} does not increase "
                f"(previous row has {float(data[i - 1, 0])!r})"
            )
    return data


def read_init(path: str | Path) -> InitialState:
    """Read and check the initial-state JSON (CONVENTIONS.md "Initial state")."""
    path = Path(path)
    if not path.is_file():
        raise DataFileError(f"{path}: no such file")
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except UnicodeDecodeError:
        raise DataFileError(_bad_text(path)) from None
    except json.JSONDecodeError as exc:
        raise DataFileError(f"{path}: line {exc.lineno}, column {exc.colno}: invalid JSON: {exc.msg}") from None
    if not isinstance(doc, dict):
        raise DataFileError(f"{path}: expected a JSON object with keys {', '.join(INIT_KEYS)}")
    values = {}
    for key in INIT_KEYS:
        if key not in doc:
            raise DataFileError(f"{path}: key '{key}' is missing")
        v = doc[key]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise DataFileError(f"{path}: key '{key}': {v!r} is not a finite number")
        values[key] = float(v)
    if not -90.0 <= values["lat"] <= 90.0:
        raise DataFileError(f"{path}: key 'lat': {values['lat']} is outside [-90, 90] deg")
    return InitialState(**values)


def write_init(path: str | Path, init: InitialState) -> None:
    """Write the initial-state JSON with round-trip floats."""
    Path(path).write_text(json.dumps(init.to_dict(), indent=2) + "\n", encoding="utf-8")


def format_rows(data: np.ndarray) -> str:
    """CSV body with shortest round-trip float text (Python's float repr)."""
    if data.shape[0] == 0:
        return ""
    return "\n".join(",".join(map(repr, row)) for row in data.tolist()) + "\n"


def write_table(path: str | Path, columns: tuple[str, ...], data: np.ndarray) -> None:
    """Write a CSV with a header line and round-trip floats."""
    with open(path, "w", encoding="utf-8", newline="") as fh:
        fh.write(",".join(columns) + "\n")
        chunk = 65536
        for start in range(0, data.shape[0], chunk):
            fh.write(format_rows(data[start : start + chunk]))


def read_solution(path: str | Path) -> np.ndarray:
    """Read a solution or truth CSV (degrees as in the file)."""
    return read_table(path, SOLUTION_COLUMNS)


class SolutionWriter:
    """Write solution rows (kernel radians) to a solution CSV as they come."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._fh = open(self.path, "w", encoding="utf-8", newline="")
        self._fh.write(",".join(SOLUTION_COLUMNS) + "\n")
        self.rows = 0

    def write(self, row_rad: np.ndarray) -> None:
        r = row_rad.copy()
        r[[1, 2, 7, 8, 9]] = np.degrees(r[[1, 2, 7, 8, 9]])
        self._fh.write(",".join(map(repr, r.tolist())) + "\n")
        self.rows += 1

    def close(self) -> None:
        self._fh.close()
